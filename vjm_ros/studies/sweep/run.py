"""One run of a sweep, as a worker executes it: the case's scene, settings and measures.

The physics and the measures are those of ``vjm bench``
(:func:`vjm_ros.studies.bench.runs.run_vjm`): the same simulator as ``vjm run`` and the node,
closure errors and energy drift from the trajectory, and the deviation of every chain tip and
link end from an exact reference (:func:`vjm_ros.studies.bench.runs.compute_reference`),
computed once per scene and parameter set and shared by its runs.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from collections.abc import Callable
from pathlib import Path

import yaml

from vjm_ros.core.errors import ConfigurationError, VjmError
from vjm_ros.scene import Scene, load_scene, parse_scene
from vjm_ros.scene.loader import builtin_scenes
from vjm_ros.scene.safe_yaml import SceneLoader
from vjm_ros.sim.settings import SimulationSettings, resolve_settings
from vjm_ros.studies.bench.grid import FAILED, RowConfig
from vjm_ros.studies.bench.runs import Reference, compute_reference, run_vjm
from vjm_ros.studies.sweep.spec import Case

MEASURES = (
    "status", "message", "diverged_at", "max_closure_error", "rms_closure_error", "energy_drift",
    "energy_balance_residual", "position_deviation", "tip_deviation", "wall_time", "finite",
)
"""Result columns of every row, after the run's identity columns."""


def _named_parts(doc: dict):
    """(link name, link dict, joint name, joint dict) of every link, with the builder's defaults."""
    for c, chain in enumerate(doc.get("chains") or []):
        cname = chain.get("name", f"chain{c + 1}")
        for i, link in enumerate(chain.get("links") or []):
            joint = link.get("joint") or {}
            yield (link.get("name", f"{cname}_link{i + 2}"), link,
                   joint.get("name", f"{cname}_joint{i + 1}"), joint)


def apply_parameters(base: Scene, parameters: dict,
                     where: Callable[[str], str] = lambda key: f"grid.{key}") -> Scene:
    """The scene with a case's parameters applied.

    ``mass|length|inertia.<link>`` set the link's value; ``initial.<joint>`` the joint's initial
    value (``angle`` in the file's unit for a revolute joint, ``slide`` in m for a prismatic
    one; joints the scene assembles are solved again); ``effort.<joint>`` the actuator's
    constant effort. The modified document is validated and assembled like any scene file.
    ``where(key)`` names the spec key of a parameter in messages.

    Raises
    ------
    ConfigurationError
        A parameter names a link, joint or actuator the scene does not have.
    SceneError
        The modified scene is not valid (a mass that is not positive, a pose that cannot close).
    """
    if not parameters:
        return base
    doc = json.loads(json.dumps(yaml.load(base.text, Loader=SceneLoader)))  # noqa: S506
    parts = list(_named_parts(doc))
    for key, value in parameters.items():
        kind, _, name = key.partition(".")
        if kind in ("mass", "length", "inertia"):
            what, named = "a link", [(lname, link) for lname, link, _, _ in parts]
        elif kind == "initial":
            what, named = "a joint", [(jname, joint) for _, _, jname, joint in parts]
        elif kind == "effort":
            what, named = "an actuated joint", [(a.get("joint", "?"), a)
                                                for a in doc.get("actuators") or []]
        else:
            continue
        found = [part for n, part in named if n == name]
        if not found:
            raise ConfigurationError(
                f"{where(key)}: expected {what} of {base.name} "
                f"({', '.join(n for n, _ in named)}), found {name!r}")
        if kind == "initial":
            kind = "slide" if found[0].get("type") == "prismatic" else "angle"
        found[0][kind] = value
    source = f"{base.name} with {json.dumps(parameters, sort_keys=True)}"
    return parse_scene(yaml.safe_dump(doc, sort_keys=False), source=source)


@functools.lru_cache(maxsize=8)
def _base_scene(text: str, source: str) -> Scene:
    return parse_scene(text, source)


@functools.lru_cache(maxsize=64)
def case_scene(text: str, source: str, parameters: str) -> Scene:
    """The scene of YAML ``text`` (named ``source``) with a case's parameters applied
    (``parameters``: JSON of the case's dict), see :func:`apply_parameters`.

    The text, never a path, travels to the workers: a worker on another machine or in another
    directory runs the same scene as the client.
    """
    return apply_parameters(_base_scene(text, source), json.loads(parameters))


def scene_source(scene: str) -> tuple[str, str]:
    """``(text, source)`` of a built-in scene name or a scene file path, read here."""
    loaded = load_scene(scene)
    return loaded.text, scene if scene in builtin_scenes() else str(Path(scene).resolve())


def case_duration(case: Case, scene: Scene) -> float:
    """Simulated seconds of a case: its ``duration`` setting, else the scene's default."""
    return float(case.settings.get("duration") or scene.defaults.get("duration", 10.0))


def case_settings(case: Case, scene: Scene) -> SimulationSettings:
    """The case's settings resolved against the scene's defaults (as ``vjm run`` resolves)."""
    given = {k: v for k, v in case.settings.items() if k != "duration"}
    return resolve_settings(scene.defaults, scene.gains, **given)


def reference_for(text: str, source: str, parameters: str, horizon: float,
                  rate: float) -> Reference:
    """The exact reference of a scene and parameter set (shared by all its runs)."""
    return compute_reference(case_scene(text, source, parameters), horizon, rate, check=False)


def run_case(case: Case, scene_text: tuple[str, str],
             reference: Reference | None = None) -> dict:
    """Run one case; a row of the results table (its identity, then :data:`MEASURES`).

    ``scene_text`` is ``(text, source)`` of the case's scene (:func:`scene_source`). Never
    raises for a case that cannot run: the row says why (``status`` ``error``,
    ``refused (stiffness)`` or ``diverged``, and ``message``).
    """
    row = dict(case.as_row())
    try:
        scene = case_scene(*scene_text, json.dumps(case.parameters, sort_keys=True))
        settings = case_settings(case, scene)
        duration = case_duration(case, scene)
    except (VjmError, ValueError, TypeError) as exc:
        return {**row, **dict.fromkeys(MEASURES), "status": FAILED, "message": str(exc)}
    rest = {
        f.name: getattr(settings, f.name)
        for f in dataclasses.fields(settings)
        if f.name not in ("integrator", "rate", "substeps", "divergence_limit")
    }
    cfg = RowConfig("vjm", settings.integrator, settings.rate, settings.substeps, settings.closure,
                    rest)
    res = run_vjm(scene, cfg, duration, reference)
    wall = res.wall_samples[0] * duration if res.wall_samples else None
    values = {m: getattr(res, m, None) for m in MEASURES}
    values["wall_time"] = wall
    for k, v in values.items():
        if isinstance(v, float) and not math.isfinite(v):
            values[k] = None if k != "energy_drift" else v
    return {**row, **values}
