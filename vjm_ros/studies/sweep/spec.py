"""Sweep specifications: which scenes, which grid of settings and scene parameters, what to measure.

A spec is a YAML file::

    name: five_bar_gains
    scenes: [five_bar, four_bar]      # built-in names or scene file paths
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

Every error names the file, the key and what was expected, before any run starts.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from vjm_ros.core.errors import ConfigurationError

SETTINGS = (
    "integrator", "closure", "rate", "substeps", "kp", "kv", "omega_n", "zeta", "alpha", "beta",
    "projection", "rtol", "atol", "kernel", "duration",
)
"""Settings a spec may fix or sweep: those of ``vjm run`` (``duration`` in simulated s)."""
SCENE_PARAMETERS = ("mass", "length", "inertia", "initial", "effort")
"""Scene parameters a spec may sweep, as ``<kind>.<link or joint name>``."""
TOP_KEYS = {"name", "scenes", "duration", "settings", "grid", "reference"}


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
        Built-in name or scene file path.
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
    """A validated sweep spec (see the module documentation)."""

    name: str
    scenes: list[str]
    settings: dict
    axes: dict[str, list]
    duration: float | None = None
    reference: bool = True
    source: str = "<spec>"

    def cases(self) -> list[Case]:
        """Every run, scene by scene, in grid order."""
        names = list(self.axes)
        out = []
        for scene in self.scenes:
            for values in itertools.product(*(self.axes[n] for n in names)):
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
        if self.duration is not None:
            keys.setdefault("duration")
        return list(keys)


def _check_value(source: str, key: str, value: object) -> object:
    """A grid or setting value: a finite number, a string, a boolean or null."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise SpecError(source, key, "a finite number", value)
        return value
    raise SpecError(source, key, "a number, a string or a boolean", value)


def parse_spec(text: str, source: str = "<spec>") -> SweepSpec:
    """Validate a sweep spec's YAML text.

    Raises
    ------
    SpecError
        Naming the key: unknown keys and settings, empty or malformed axes, bad values.
    """
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise SpecError(source, "(file)", "valid YAML", str(exc).split("\n")[0]) from None
    if not isinstance(doc, dict):
        raise SpecError(source, "(top level)", "a mapping", doc)
    unknown = sorted(set(doc) - TOP_KEYS)
    if unknown:
        raise SpecError(source, unknown[0], f"one of the keys {sorted(TOP_KEYS)}", unknown[0])
    scenes = doc.get("scenes")
    if not isinstance(scenes, list) or not scenes or not all(isinstance(s, str) for s in scenes):
        raise SpecError(source, "scenes", "a non-empty list of scene names or paths", scenes)
    settings = doc.get("settings") or {}
    if not isinstance(settings, dict):
        raise SpecError(source, "settings", "a mapping of vjm run settings", settings)
    for key, value in settings.items():
        if key not in SETTINGS:
            raise SpecError(source, f"settings.{key}", f"one of {list(SETTINGS)}", key)
        _check_value(source, f"settings.{key}", value)
    grid = doc.get("grid") or {}
    if not isinstance(grid, dict):
        raise SpecError(source, "grid", "a mapping of axis name to a list of values", grid)
    axes: dict[str, list] = {}
    for key, values in grid.items():
        kind, _, name = str(key).partition(".")
        if key not in SETTINGS and not (kind in SCENE_PARAMETERS and name):
            raise SpecError(
                source, f"grid.{key}",
                f"a vjm run setting ({', '.join(SETTINGS)}) or a scene parameter "
                f"<{'|'.join(SCENE_PARAMETERS)}>.<name>", key,
            )
        if key in settings:
            raise SpecError(source, f"grid.{key}", "a setting that is not also fixed", key)
        if not isinstance(values, list) or not values:
            raise SpecError(source, f"grid.{key}", "a non-empty list of values", values)
        axes[key] = [_check_value(source, f"grid.{key}[{i}]", v) for i, v in enumerate(values)]
    duration = doc.get("duration")
    if duration is not None and (
        isinstance(duration, bool) or not isinstance(duration, (int, float)) or not duration > 0
        or not math.isfinite(duration)
    ):
        raise SpecError(source, "duration", "a positive number of simulated seconds", duration)
    reference = doc.get("reference", True)
    if not isinstance(reference, bool):
        raise SpecError(source, "reference", "true or false", reference)
    name = doc.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise SpecError(source, "name", "a non-empty string", name)
    return SweepSpec(name, list(scenes), dict(settings), axes,
                     None if duration is None else float(duration), reference, source)


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep spec file."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(str(path), "(file)", "a readable UTF-8 YAML file",
                        getattr(exc, "strerror", None) or str(exc)) from None
    return parse_spec(text, str(path))
