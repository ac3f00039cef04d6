"""A sweep's runs, every one checked before any worker starts.

:func:`plan_sweep` reads each scene of a spec once (its text is what travels to the workers, so a
worker elsewhere needs no copy of the files), applies each row's scene parameters and resolves
each row's settings against the scene's defaults with :func:`vjm_ros.sim.settings.
resolve_settings`, as ``vjm run`` does, then :meth:`SimulationSettings.validated`. What fails
would fail in the run: it is refused here, naming the spec file, the row and the key.

Runs that are the same computation under another name (a setting the closure method ignores)
are found here too: each such row names the row it repeats (:func:`same_run`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

from vjm_ros.core.errors import ConfigurationError, SceneError
from vjm_ros.scene import Scene
from vjm_ros.sim.settings import USER_SETTINGS, SimulationSettings, resolve_settings
from vjm_ros.studies.sweep.run import _base_scene, apply_parameters, scene_source
from vjm_ros.studies.sweep.spec import Case, SweepSpec

PENALTY_ONLY = ("kp", "kv", "omega_n", "zeta")
"""Settings the exact closure does not read (the penalty gains)."""
EXACT_ONLY = ("alpha", "beta", "projection")
"""Settings the penalty closure does not read (Baumgarte gains and projection)."""


@dataclass
class SweepPlan:
    """A spec's runs, checked.

    Attributes
    ----------
    spec : SweepSpec
    cases : list of Case
        Every row, in table order.
    scenes : dict
        Scene name or path (as the spec gives it) to ``(text, source)``.
    same_as : dict
        Key of a row that repeats another row's computation to ``(that row's key, why)``.
    """

    spec: SweepSpec
    cases: list[Case]
    scenes: dict[str, tuple[str, str]]
    same_as: dict[str, tuple[str, str]] = field(default_factory=dict)


def describe(spec: SweepSpec, case: Case) -> str:
    """A row as a reader finds it: its scene and the values its axes take."""
    values = {**case.settings, **case.parameters}
    shown = ", ".join(f"{k}={values[k]!r}" for k in spec.axes_of(case.scene))
    return f"{case.scene}{': ' + shown if shown else ''}"


def same_run(settings: SimulationSettings) -> tuple[tuple, str]:
    """The computation a run's resolved settings make, and what in them makes no difference.

    Two runs of one scene and parameter set with equal first elements compute the same thing:
    the exact closure ignores the penalty gains, and without penalty forces ``implicit_euler``
    steps as ``semi_implicit_euler``; the penalty closure ignores the Baumgarte gains and
    projection. (Whether that holds is checked by running both, in the tests.)
    """
    fields = {k: getattr(settings, k) for k in (*USER_SETTINGS, "kernel", "check_stiffness")}
    ignored = EXACT_ONLY if settings.closure == "penalty" else PENALTY_ONLY
    why = f"the {settings.closure} closure does not read {', '.join(ignored)}"
    for k in ignored:
        fields[k] = None
    if settings.closure == "exact" and settings.integrator == "implicit_euler":
        # implicit_euler is semi_implicit_euler with the penalty forces at the step's end; the
        # exact closure has no penalty forces
        fields["integrator"] = "semi_implicit_euler"
        why += "; without penalty forces implicit_euler is semi_implicit_euler"
    return tuple(sorted(fields.items())), why


def plan_sweep(spec: SweepSpec) -> SweepPlan:
    """Every row of ``spec``, checked before any run.

    Raises
    ------
    ConfigurationError
        Naming the spec file, the row (number, scene and axis values) and the key: a scene that
        does not load, a parameter the scene does not have or cannot take, settings that cannot
        be combined (``kp`` with ``omega_n``) or that ``vjm run`` would refuse.
    """
    scenes: dict[str, tuple[str, str]] = {}
    for i, name in enumerate(spec.scenes):
        try:
            scenes[name] = scene_source(name)
        except SceneError as exc:
            raise ConfigurationError(f"{spec.source}: scenes[{i}]: {exc}") from None
    cases = spec.cases()
    loaded: dict[tuple, Scene] = {}
    seen: dict[tuple, str] = {}
    same_as: dict[str, tuple[str, str]] = {}
    for row, case in enumerate(cases, 1):
        params = json.dumps(case.parameters, sort_keys=True)
        at = f"{spec.source}: row {row} of {len(cases)} ({describe(spec, case)})"
        if (case.scene, params) not in loaded:
            try:
                base = _base_scene(*scenes[case.scene])
                loaded[case.scene, params] = apply_parameters(
                    base, case.parameters, where=lambda k, s=case.scene: spec.where(k, s))
            except (SceneError, ConfigurationError) as exc:
                raise ConfigurationError(f"{at}: {exc}") from None
        scene = loaded[case.scene, params]
        given = {k: v for k, v in case.settings.items() if k not in ("duration", "kernel")}
        try:
            settings = resolve_settings(
                scene.defaults, scene.gains, kernel=case.settings.get("kernel", "auto"),
                flag=lambda k, s=case.scene: spec.where(k, s), **given).validated()
        except ConfigurationError as exc:
            raise ConfigurationError(f"{at}: {exc}") from None
        ident, why = same_run(settings)
        sig = (case.scene, params, case.settings.get("duration"), ident)
        if sig in seen:
            same_as[case.key] = (seen[sig], why)
        else:
            seen[sig] = case.key
    return SweepPlan(spec, cases, scenes, same_as)
