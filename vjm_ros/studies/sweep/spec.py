"""Sweep specifications: which scenes, which grid of settings and scene parameters, what to measure.

A spec is a YAML file::

    name: five_bar_gains
    scenes:                           # built-in names or scene file paths
      - five_bar
      - scene: four_bar               # a scene with axes of its own (scene parameters
        grid:                         #   of one scene of several, say)
          length.crank: [0.9, 1.0]
    duration: 0.5                     # simulated s per run (default: each scene's own)
    settings:                         # fixed for every run (any `vjm run` setting)
      closure: penalty
    grid:                             # axes: every combination runs once per scene
      integrator: [rk4, semi_implicit_euler]
      rate: [500, 1000]
      omega_n: [50, 100, 200]
      zeta: [0.7, 1.0]
      mass.crank: [1.0, 1.5]          # scene parameters: mass|length|inertia.<link>,
      initial.crank_joint: [0.0, 0.5] #   initial.<joint> (the file's angle unit), effort.<joint>
    reference: true                   # deviation from an exact reference (once per scene)

Every error names the file, the key and what was expected, before any run starts: the spec's
shape and each value's type and range here, each row's settings resolved as ``vjm run`` resolves
them in :mod:`vjm_ros.studies.sweep.plan`.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from vjm_ros.core.compiled import KERNELS
from vjm_ros.core.errors import ConfigurationError, SceneError
from vjm_ros.core.integrators import INTEGRATORS
from vjm_ros.scene.safe_yaml import parse_yaml
from vjm_ros.sim.settings import USER_SETTINGS, SimulationSettings

SETTINGS = (*USER_SETTINGS, "kernel", "duration")
"""Settings a spec may fix or sweep: those of ``vjm run`` (``duration`` in simulated s)."""
SCENE_PARAMETERS = ("mass", "length", "inertia", "initial", "effort")
"""Scene parameters a spec may sweep, as ``<kind>.<link or joint name>``."""
TOP_KEYS = {"name", "scenes", "duration", "settings", "grid", "reference"}
SCENE_KEYS = {"scene", "grid"}
NUMBER_SETTINGS = ("rate", "kp", "kv", "omega_n", "zeta", "alpha", "beta", "rtol", "atol",
                   "duration")
"""Settings that take a number (``vjm run`` reads them as floats)."""


class SpecError(ConfigurationError):
    """A sweep spec that cannot run; names the file and the key."""

    def __init__(self, source: str, key: str, expected: str, found: object):
        self.source, self.key, self.expected, self.found = source, key, expected, found
        super().__init__(f"{source}: {key}: expected {expected}, found {found!r}")


@dataclass(frozen=True)
class Case:
    """One run of a sweep.

    Attributes
    ----------
    scene : str
        Built-in name or scene file path, as the spec gives it.
    settings : dict
        ``vjm run`` settings of this run (fixed ones and grid values).
    parameters : dict
        Scene parameters of this run, ``<kind>.<name>`` to value.
    """

    scene: str
    settings: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)

    @property
    def key(self) -> str:
        """Identity of the run: a hash of its scene, settings and parameters."""
        text = json.dumps([self.scene, self.settings, self.parameters], sort_keys=True)
        return hashlib.sha1(text.encode()).hexdigest()[:16]

    def as_row(self) -> dict:
        """The run's identity as table columns."""
        return {"key": self.key, "scene": self.scene, **self.settings, **self.parameters}


@dataclass
class SweepSpec:
    """A validated sweep spec (see the module documentation).

    ``axes`` run for every scene; ``scene_axes[scene]`` only for that scene, after ``axes``.
    """

    name: str
    scenes: list[str]
    settings: dict
    axes: dict[str, list]
    duration: float | None = None
    reference: bool = True
    source: str = "<spec>"
    scene_axes: dict[str, dict[str, list]] = field(default_factory=dict)

    def axes_of(self, scene: str) -> dict[str, list]:
        """The axes a scene's runs vary: the common ones, then the scene's own."""
        return {**self.axes, **self.scene_axes.get(scene, {})}

    def where(self, key: str, scene: str) -> str:
        """The spec key that gives setting or parameter ``key`` to ``scene``'s runs."""
        if key in self.scene_axes.get(scene, {}):
            return f"scenes[{self.scenes.index(scene)}].grid.{key}"
        if key in self.axes:
            return f"grid.{key}"
        if key in self.settings:
            return f"settings.{key}"
        return "duration" if key == "duration" else key

    def cases(self) -> list[Case]:
        """Every run, scene by scene, in grid order."""
        out = []
        for scene in self.scenes:
            axes = self.axes_of(scene)
            names = list(axes)
            for values in itertools.product(*(axes[n] for n in names)):
                chosen = dict(zip(names, values, strict=True))
                settings = {**self.settings, **{k: v for k, v in chosen.items() if k in SETTINGS}}
                if self.duration is not None:
                    settings.setdefault("duration", self.duration)
                params = {k: v for k, v in chosen.items() if k not in SETTINGS}
                out.append(Case(scene, settings, params))
        return out

    @property
    def columns(self) -> list[str]:
        """Identity columns of the results table (measures follow)."""
        keys = dict.fromkeys(["key", "scene", *self.settings, *self.axes])
        for scene in self.scenes:
            keys.update(dict.fromkeys(self.scene_axes.get(scene, {})))
        if self.duration is not None:
            keys.setdefault("duration")
        return list(keys)


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check_value(source: str, where: str, key: str, value: object) -> object:
    """A setting's or a scene parameter's value, of the type and range ``vjm run`` accepts.

    ``where`` is the spec key that holds it (``grid.rate[1]``). The ranges are
    :meth:`SimulationSettings.validated`'s, so the messages are those of ``vjm run``.

    Raises
    ------
    SpecError
        A value of the wrong type.
    ConfigurationError
        A value out of range, with the message of ``vjm run`` after the file and the key.
    """
    if key in ("integrator", "closure", "kernel"):
        known = {"integrator": list(INTEGRATORS), "closure": ["penalty", "exact"],
                 "kernel": list(KERNELS)}[key]
        if value not in known:
            raise SpecError(source, where, f"one of {known}", value)
    elif key == "substeps":
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise SpecError(source, where, "a whole number of steps per tick >= 1", value)
    elif key == "projection":
        if not isinstance(value, bool):
            raise SpecError(source, where, "true or false", value)
    elif key in NUMBER_SETTINGS or key not in SETTINGS:
        if not _is_number(value) or not math.isfinite(value):
            raise SpecError(source, where, "a finite number", value)
        if key == "duration" and not value > 0:
            raise SpecError(source, where, "a positive number of simulated seconds", value)
    if key in SETTINGS and key != "duration":
        try:  # the ranges of vjm run, with its messages
            SimulationSettings(**{key: value}).validated()
        except ConfigurationError as exc:
            text = str(exc)
            text = text[len(key) + 2:] if text.startswith(f"{key}: ") else text
            raise ConfigurationError(f"{source}: {where}: {text}") from None
    return value


def _axes(source: str, prefix: str, grid: object, settings: dict) -> dict[str, list]:
    if not isinstance(grid, dict):
        raise SpecError(source, prefix, "a mapping of axis name to a list of values", grid)
    axes: dict[str, list] = {}
    for key, values in grid.items():
        kind, _, name = str(key).partition(".")
        if key not in SETTINGS and not (kind in SCENE_PARAMETERS and name):
            raise SpecError(
                source, f"{prefix}.{key}",
                f"a vjm run setting ({', '.join(SETTINGS)}) or a scene parameter "
                f"<{'|'.join(SCENE_PARAMETERS)}>.<name>", key,
            )
        if key in settings:
            raise SpecError(source, f"{prefix}.{key}", "a setting that is not also fixed", key)
        if not isinstance(values, list) or not values:
            raise SpecError(source, f"{prefix}.{key}", "a non-empty list of values", values)
        axes[key] = [check_value(source, f"{prefix}.{key}[{i}]", key, v)
                     for i, v in enumerate(values)]
    return axes


def parse_spec(text: str, source: str = "<spec>") -> SweepSpec:
    """Validate a sweep spec's YAML text.

    Raises
    ------
    SpecError
        Naming the key (a YAML syntax error: its line and column): unknown keys and settings,
        empty or malformed axes, values of the wrong type or out of range.
    """
    try:
        doc = parse_yaml(text, source)
    except SceneError as exc:
        raise SpecError(source, exc.key, exc.expected, exc.found) from None
    if not isinstance(doc, dict):
        raise SpecError(source, "(top level)", "a mapping", doc)
    unknown = sorted(set(doc) - TOP_KEYS, key=str)
    if unknown:
        raise SpecError(source, unknown[0], f"one of the keys {sorted(TOP_KEYS)}", unknown[0])
    settings = doc.get("settings") or {}
    if not isinstance(settings, dict):
        raise SpecError(source, "settings", "a mapping of vjm run settings", settings)
    for key, value in settings.items():
        if key not in SETTINGS:
            raise SpecError(source, f"settings.{key}", f"one of {list(SETTINGS)}", key)
        check_value(source, f"settings.{key}", key, value)
    axes = _axes(source, "grid", doc.get("grid") or {}, settings)
    entries = doc.get("scenes")
    if not isinstance(entries, list) or not entries:
        raise SpecError(source, "scenes", "a non-empty list of scene names or paths", entries)
    scenes: list[str] = []
    scene_axes: dict[str, dict[str, list]] = {}
    for i, entry in enumerate(entries):
        if isinstance(entry, dict):
            unknown = sorted(set(entry) - SCENE_KEYS, key=str)
            if unknown or not isinstance(entry.get("scene"), str):
                raise SpecError(source, f"scenes[{i}]",
                                "a scene name or path, or a mapping {scene: NAME, grid: {...}}",
                                entry)
            own = _axes(source, f"scenes[{i}].grid", entry.get("grid") or {}, settings)
            for key in own:
                if key in axes:
                    raise SpecError(source, f"scenes[{i}].grid.{key}",
                                    "an axis that is not also in the common grid", key)
            scene = entry["scene"]
            if own:
                scene_axes[scene] = own
        elif isinstance(entry, str) and entry:
            scene = entry
        else:
            raise SpecError(source, f"scenes[{i}]", "a scene name or path", entry)
        if scene in scenes:
            raise SpecError(source, f"scenes[{i}]", "each scene once", scene)
        scenes.append(scene)
    duration = doc.get("duration")
    if duration is not None:
        check_value(source, "duration", "duration", duration)
    reference = doc.get("reference", True)
    if not isinstance(reference, bool):
        raise SpecError(source, "reference", "true or false", reference)
    name = doc.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise SpecError(source, "name", "a non-empty string", name)
    return SweepSpec(name, scenes, dict(settings), axes,
                     None if duration is None else float(duration), reference, source, scene_axes)


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep spec file."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(str(path), "(file)", "a readable UTF-8 YAML file",
                        getattr(exc, "strerror", None) or str(exc)) from None
    return parse_spec(text, str(path))
