"""The study's grid: scenes, horizons, closure variants, MuJoCo variants, and the rows they make."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vjm_ros.core.integrators import INTEGRATORS

HORIZONS: dict[str, float] = {
    "four_bar": 5.0,
    "six_bar": 3.0,
    "double_slider": 3.0,
    "slider_crank": 3.0,
    "pendulum": 5.0,
    "rrr_platform": 1.0,
    "five_bar": 1.0,
    "three_chain": 1.0,
}
"""Simulated seconds compared per scene (full grid).

The non-chaotic scenes could be compared for longer; these horizons keep the full grid (about
150 rows per scene, each timed three times) within about ten minutes of one core with the
compiled kernels.
"""
QUICK_HORIZON = 0.5
"""Largest horizon of ``--quick``, s."""

HORIZON_NOTES: dict[str, str] = {
    "five_bar": (
        "the symmetric motion from the thesis's stretched start is physically unstable "
        "(perturbations grow about 100x per second): two tight-tolerance references drift apart "
        "beyond 1e-9 m after about 3 s, so the comparison stops at 1 s or earlier"
    ),
    "three_chain": (
        "three chains meeting at one pin amplify round-off about 10x per second: the comparison "
        "stops at 1 s or earlier"
    ),
    "rrr_platform": (
        "references at rtol 1e-10 and 1e-12 separate beyond 1e-7 m after 3 s: the comparison "
        "stops at 1 s or earlier"
    ),
}
"""Why a scene's horizon is short."""

DEFAULT_HORIZON = 1.0
"""Horizon of scenes not in :data:`HORIZONS` (YAML files), s."""

FULL_SCENES = ("four_bar", "six_bar", "double_slider", "five_bar", "three_chain")
"""Scenes of the default (full) bench: the thesis mechanisms of chapter 4."""
QUICK_SCENES = ("four_bar", "five_bar")
"""Scenes of ``--quick``: the two with a MuJoCo counterpart."""
MUJOCO_SCENES = ("four_bar", "five_bar")
"""Scenes also run in MuJoCo (any scene can be: these two keep the study short)."""

REFERENCE_SETTINGS = {"integrator": "dop853", "rtol": 1e-12, "atol": 1e-14}
"""The reference: exact closure, ``dop853`` at these tolerances."""
CHECK_SETTINGS = {"integrator": "dop853", "rtol": 1e-10, "atol": 1e-12}
"""A looser solve compared with the reference to show how far it can be trusted."""
REFERENCE_RATE = 1000.0
"""Tick rate of the reference, Hz; every grid rate divides it."""

LIVE_RATE = 1000.0
"""Rate of the live tier, Hz."""
LIVE_HEADROOM = 2.0
"""The live tier needs a realtime factor of at least this (physics within half the tick)."""
TIERS: tuple[tuple[str, float | None], ...] = (
    ("live 1 kHz", None),
    ("1e-3 m", 1e-3),
    ("1e-6 m", 1e-6),
    ("1e-9 m", 1e-9),
)
"""Accuracy tiers: the live tier, then largest position error allowed offline."""
MATCH_LEVELS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7)
"""Position errors at which vjm and MuJoCo are compared (cheapest row of each reaching it)."""

REFUSED = "refused (stiffness)"
DIVERGED = "diverged"
OK = "ok"
FAILED = "error"


# ---------------------------------------------------------------------------------------- the grid
@dataclass(frozen=True)
class ClosureVariant:
    """One way to close the loops.

    Attributes
    ----------
    label : str
        Short name used in tables.
    closure : str
        ``"penalty"`` or ``"exact"``.
    kp, kv, omega_n, zeta : float or None
        Penalty gains (raw or modal).
    projection : bool
        Exact closure: project ``q``, ``qd`` after each tick.
    """

    label: str
    closure: str
    kp: float | None = None
    kv: float | None = None
    omega_n: float | None = None
    zeta: float | None = None
    projection: bool = False

    def settings(self) -> dict:
        """Keyword arguments of :class:`SimulationSettings`."""
        out: dict = {"closure": self.closure, "projection": self.projection}
        for k in ("kp", "kv", "omega_n", "zeta"):
            v = getattr(self, k)
            if v is not None:
                out[k] = v
        return out


THESIS = ClosureVariant("penalty Kp=1e5 Kv=1e2 (thesis)", "penalty", kp=1e5, kv=100.0)
PENALTY_1E7 = ClosureVariant("penalty Kp=1e7 Kv=1e3", "penalty", kp=1e7, kv=1e3)
MODAL_100 = ClosureVariant("penalty wn=100 z=1", "penalty", omega_n=100.0, zeta=1.0)
MODAL_1000 = ClosureVariant("penalty wn=1000 z=1", "penalty", omega_n=1000.0, zeta=1.0)
EXACT = ClosureVariant("exact", "exact")
EXACT_PROJ = ClosureVariant("exact + projection", "exact", projection=True)


@dataclass(frozen=True)
class MujocoVariant:
    """A MuJoCo equality softness.

    Attributes
    ----------
    label : str
    solref, solimp : tuple of float
    """

    label: str
    solref: tuple[float, ...]
    solimp: tuple[float, ...] = (0.9, 0.95, 0.001, 0.5, 2.0)


MJ_DEFAULT = MujocoVariant("solref 0.02/1 (default)", (0.02, 1.0))
MJ_STIFF = MujocoVariant("solref 0.002/1", (0.002, 1.0))
MJ_THESIS = MujocoVariant("solref -1e5/-100 (thesis gains)", (-1e5, -100.0))
MJ_HARD = MujocoVariant(
    "solref -1e7/-2e3 solimp 0.9999", (-1e7, -2e3), (0.9999, 0.9999, 0.001, 0.5, 2.0)
)


@dataclass(frozen=True)
class Grid:
    """What the bench runs per scene.

    Attributes
    ----------
    fixed : tuple of str
        Fixed-step integrators.
    steps : tuple of (rate, substeps)
        Tick rates (Hz) and substeps of the fixed-step rows.
    closures : tuple of ClosureVariant
        Closure variants of the fixed-step rows.
    adaptive : tuple of (integrator, ClosureVariant, rtol)
        Adaptive rows (ticks at 1 kHz, ``atol = rtol * 1e-3``).
    mujoco : tuple of (integrator, rate, substeps, MujocoVariant)
        MuJoCo rows.
    scaling_links : tuple of int
        Chain lengths of the cost-per-tick study.
    scaling_chains : tuple of int
        Chain counts of the cost-per-tick study.
    scaling_ticks : int
        Ticks timed per repeat in the scaling study, at least.
    scaling_seconds : float
        Wall time of each timed repeat of the scaling study, at least, s: where
        ``scaling_ticks`` take less, more ticks are timed (at most :data:`MAX_SCALING_TICKS`), so
        that a stall of the machine or a timer interrupt does not decide a small size's figure.
    """

    fixed: tuple[str, ...]
    steps: tuple[tuple[float, int], ...]
    closures: tuple[ClosureVariant, ...]
    adaptive: tuple[tuple[str, ClosureVariant, float], ...]
    mujoco: tuple[tuple[str, float, int, MujocoVariant], ...]
    scaling_links: tuple[int, ...] = (1, 2, 4, 8, 16, 32)
    scaling_chains: tuple[int, ...] = (1, 2, 4, 8, 16)
    scaling_ticks: int = 40
    scaling_seconds: float = 0.02


MAX_SCALING_TICKS = 20000
"""Most ticks timed per repeat of the scaling study (20 simulated seconds at 1 kHz)."""


FIXED = ("explicit_euler", "semi_implicit_euler", "rk4", "implicit_euler")
MJ_INTEGRATORS = ("Euler", "implicitfast", "RK4")


def full_grid() -> Grid:
    """The default grid."""
    steps = ((1000.0, 1), (1000.0, 4), (250.0, 1), (100.0, 1))
    closures = (THESIS, PENALTY_1E7, MODAL_100, MODAL_1000, EXACT, EXACT_PROJ)
    adaptive = tuple(
        (name, EXACT, rtol)
        for name in ("dop853", "rk45", "rk23", "radau", "bdf", "lsoda")
        for rtol in (1e-6, 1e-9)
    ) + tuple((name, THESIS, 1e-6) for name in ("dop853", "radau", "bdf", "lsoda"))
    mj_steps = ((1000.0, 1), (1000.0, 4), (1000.0, 16), (250.0, 1), (100.0, 1))
    mujoco = tuple(
        (name, rate, sub, var)
        for name in MJ_INTEGRATORS
        for rate, sub in mj_steps
        for var in (MJ_DEFAULT, MJ_STIFF, MJ_THESIS, MJ_HARD)
    )
    return Grid(FIXED, steps, closures, adaptive, mujoco)


def quick_grid() -> Grid:
    """The ``--quick`` grid (a subset of :func:`full_grid`)."""
    steps = ((1000.0, 1), (1000.0, 2), (250.0, 1))
    closures = (THESIS, MODAL_1000, EXACT, EXACT_PROJ)
    adaptive = (("dop853", EXACT, 1e-6), ("dop853", EXACT, 1e-9), ("radau", THESIS, 1e-6))
    mujoco = tuple(
        (name, 1000.0, sub, var)
        for name in MJ_INTEGRATORS
        for sub in (1, 4)
        for var in (MJ_DEFAULT, MJ_STIFF, MJ_THESIS)
    )
    return Grid(FIXED, steps, closures, adaptive, mujoco, (1, 4, 16, 32), (1, 4, 16), 20)


@dataclass
class RowConfig:
    """One row of the grid.

    Attributes
    ----------
    engine : str
        ``"vjm"`` or ``"mujoco"``.
    integrator : str
    rate : float
    substeps : int
    closure : str
        Closure label (vjm) or equality softness label (MuJoCo).
    settings : dict
        vjm: keyword arguments of :class:`SimulationSettings`; MuJoCo: ``solref``, ``solimp``.
    """

    engine: str
    integrator: str
    rate: float
    substeps: int
    closure: str
    settings: dict = field(default_factory=dict)

    @property
    def adaptive(self) -> bool:
        """True for error-controlled (scipy) integrators."""
        return self.engine == "vjm" and not INTEGRATORS[self.integrator].fixed_step

    @property
    def step(self) -> float | None:
        """Fixed step ``h``, s (None for adaptive rows)."""
        return None if self.adaptive else 1.0 / (self.rate * self.substeps)

    def label(self) -> str:
        """Human-readable setting, e.g. ``rk4 1000 Hz x4, exact``."""
        if self.adaptive:
            return f"{self.integrator} rtol={self.settings['rtol']:.0e}, {self.closure}"
        eng = "MuJoCo " if self.engine == "mujoco" else ""
        return f"{eng}{self.integrator} {self.rate:g} Hz x{self.substeps}, {self.closure}"

    def key(self) -> str:
        """Identity of the setting across scenes."""
        return f"{self.engine}|{self.label()}"


def grid_rows(grid: Grid, mujoco: bool, extra: dict | None = None) -> list[RowConfig]:
    """Expand a grid into rows.

    Parameters
    ----------
    grid : Grid
    mujoco : bool
        Include the MuJoCo rows.
    extra : dict, optional
        More :class:`SimulationSettings` fields for every vjm row (e.g. a kernel selector).

    Returns
    -------
    list of RowConfig
    """
    extra = dict(extra or {})
    rows = []
    for integ in grid.fixed:
        for rate, sub in grid.steps:
            for var in grid.closures:
                rows.append(RowConfig("vjm", integ, rate, sub, var.label, {**var.settings(), **extra}))
    for integ, var, rtol in grid.adaptive:
        s = {**var.settings(), "rtol": rtol, "atol": rtol * 1e-3, **extra}
        rows.append(RowConfig("vjm", integ, REFERENCE_RATE, 1, var.label, s))
    if mujoco:
        for integ, rate, sub, var in grid.mujoco:
            rows.append(RowConfig("mujoco", integ, rate, sub, var.label,
                                  {"solref": var.solref, "solimp": var.solimp}))
    return rows


def jsonable(x: object) -> object:
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if isinstance(x, Path):
        return str(x)
    return x


@dataclass
class BenchOptions:
    """What one ``vjm bench`` invocation does (see :func:`main` for the flags)."""

    scenes: list[str]
    quick: bool = False
    out: Path = Path("bench_out")
    repeats: int = 3
    horizon: float | None = None
    mujoco: bool = True
    scaling: bool = True
    docs: Path | None = None
    extra: dict = field(default_factory=dict)
    grid: Grid | None = None
    progress: bool = True
    command: str = "vjm bench"
    workers: int = 1
    cluster: str | None = None
    cluster_timeout: float = 10.0
