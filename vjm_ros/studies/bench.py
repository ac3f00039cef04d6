"""Speed/accuracy study: ``vjm bench [SCENE ...] [--quick] [--out DIR] [--docs FILE]``.

For every scene the bench runs a grid of settings through :class:`~vjm_ros.sim.simulator.Simulator`
(so any faster kernel selected there is measured as it is) and, when MuJoCo is installed, the same
mechanism in MuJoCo (:mod:`vjm_ros.studies.compare_mujoco`). Each row reports (docs/design.md section 6):

* cost: wall time per simulated second of the physics calls (``Simulator.advance`` or
  ``mj_step``), median of ``--repeats`` runs over the scene's horizon, single-threaded; sampling
  the results is not timed. Rows are compared as ratios within one run;
* closure error: the largest ``|C|`` over the run, m;
* energy drift ``max |(T+V)(t) - (T+V)(0)| / max T`` and the energy-balance residual (J);
* accuracy: the largest distance, over all tick times, between the positions of the run and of a
  reference solved by vjm with ``dop853`` at ``rtol = 1e-12`` and exact closure. "tip" is the chain
  tips (the named points); "position" adds the end of every link (the joints), which is the
  measure used for the Pareto fronts and the tiers (for ``four_bar`` the only tip is the pinned
  rocker end, which says little about the motion).

Horizons are chosen where the mechanism is not chaotic: the five-bar's symmetric motion is
physically unstable and the three-chain amplifies round-off about tenfold per second, so both are
compared over 1 s (see :data:`HORIZONS`). A configuration refused by the stiffness check is a row
``refused (stiffness)``, one that diverged a row ``diverged`` with the time and the error; no row is
dropped.

Outputs in ``--out`` (default ``bench_out/``): ``report.md``, ``results.json``, one Pareto plot
per scene (``<scene>_pareto.png``) and ``scaling.png`` (cost per tick against chain length and
chain count). ``--docs FILE`` also writes the user-facing summary (``docs/accuracy.md``) and
copies the figures next to it under ``figures/``. ``--long-run S --out DIR`` instead runs only
the long four-bar run and writes ``DIR/long_run_<setting>.json``; reports later written to
``DIR`` include every ``long_run*.json`` found there.
"""

from __future__ import annotations

import argparse
import ctypes
import datetime as _dt
import json
import math
import os
import platform
import shutil
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np

from vjm_ros.core.errors import (
    ConfigurationError,
    DivergenceError,
    SceneError,
    StiffnessError,
    VjmError,
)
from vjm_ros.core.integrators import INTEGRATORS
from vjm_ros.core.kinematics import forward_kinematics, link_segments, point_positions
from vjm_ros.scene.loader import Scene, builtin_scenes, load_scene, parse_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator
from vjm_ros.sim.trajectory import Trajectory

# ---------------------------------------------------------------------------------------- constants
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
compiled kernel (about an hour with the numpy one).
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
"""Scenes also run in MuJoCo (hinge closures only)."""

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
        Ticks timed per repeat in the scaling study.
    """

    fixed: tuple[str, ...]
    steps: tuple[tuple[float, int], ...]
    closures: tuple[ClosureVariant, ...]
    adaptive: tuple[tuple[str, ClosureVariant, float], ...]
    mujoco: tuple[tuple[str, float, int, MujocoVariant], ...]
    scaling_links: tuple[int, ...] = (1, 2, 4, 8, 16, 32)
    scaling_chains: tuple[int, ...] = (1, 2, 4, 8, 16)
    scaling_ticks: int = 40


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


# ---------------------------------------------------------------------------------------- threads
def limit_threads() -> dict:
    """Keep BLAS and OpenMP on one thread, also when numpy is already loaded.

    Sets ``OMP_NUM_THREADS`` and friends for anything started later, and calls the loaded
    OpenBLAS's ``set_num_threads(1)`` (through threadpoolctl when it is installed).

    Returns
    -------
    dict
        What was done (for the report).
    """
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS"):
        os.environ[var] = "1"
    info = {"env": "OMP/OPENBLAS/MKL_NUM_THREADS=1", "blas": "not found"}
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
        info["blas"] = "threadpoolctl limit 1"
        return info
    except ImportError:
        pass
    try:
        with open("/proc/self/maps", encoding="utf-8") as fh:
            libs = sorted({ln.split()[-1] for ln in fh if "openblas" in ln.lower() and "/" in ln})
    except OSError:
        libs = []
    done = []
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for sym in ("openblas_set_num_threads", "scipy_openblas_set_num_threads64_",
                    "openblas_set_num_threads64_", "scipy_openblas_set_num_threads"):
            fn = getattr(lib, sym, None)
            if fn is not None:
                fn(ctypes.c_int(1))
                done.append(f"{Path(path).name}:{sym}(1)")
                break
    if done:
        info["blas"] = ", ".join(done)
    return info


# ---------------------------------------------------------------------------------------- progress
class BenchProgress:
    """A progress bar on stderr: redrawn in place on a terminal, a line per ~10 % otherwise.

    Parameters
    ----------
    total : float
        Total estimated work (arbitrary units).
    stream : file, optional
        Default ``sys.stderr``.
    enabled : bool
    """

    def __init__(self, total: float, stream=None, enabled: bool = True):
        self.total = max(total, 1e-9)
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.done = 0.0
        self.start = time.perf_counter()
        self.last_draw = 0.0
        self.last_line_frac = -1.0
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def advance(self, work: float, label: str = "") -> None:
        """Count ``work`` as done and redraw."""
        self.done += work
        self.draw(label)

    def draw(self, label: str = "") -> None:
        """Redraw the bar with the current label."""
        if not self.enabled:
            return
        now = time.perf_counter()
        frac = min(self.done / self.total, 1.0)
        elapsed = now - self.start
        eta = elapsed * (1 - frac) / frac if frac > 0.01 else float("nan")
        eta_s = f"{eta / 60:4.1f} min" if math.isfinite(eta) else "   ?"
        width = 28
        filled = int(frac * width)
        bar = "#" * filled + "-" * (width - filled)
        text = f"[{bar}] {100 * frac:5.1f}%  {elapsed / 60:4.1f} min, eta {eta_s}  {label}"
        if self.tty:
            if now - self.last_draw < 0.1 and frac < 1.0:
                return
            self.last_draw = now
            cols = shutil.get_terminal_size((120, 20)).columns
            self.stream.write("\r" + text[: cols - 1].ljust(cols - 1))
        else:
            if frac - self.last_line_frac < 0.1 and frac < 1.0:
                return
            self.last_line_frac = frac
            self.stream.write(text + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line."""
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def _work(cfg: RowConfig, horizon: float, model_n: int) -> float:
    """Rough cost of one run, in model evaluations (for the progress estimate)."""
    if cfg.engine == "mujoco":
        return 0.02 * horizon * cfg.rate * cfg.substeps
    if cfg.adaptive:
        per_s = {"radau": 20000.0, "bdf": 8000.0, "lsoda": 6000.0}.get(cfg.integrator, 4000.0)
        return per_s * horizon
    stages = {"rk4": 4.0, "implicit_euler": 1.4}.get(cfg.integrator, 1.0)
    return stages * horizon * cfg.rate * cfg.substeps


# ---------------------------------------------------------------------------------------- runs
@dataclass
class Reference:
    """Positions of the reference solution at the tick times of ``rate``.

    Attributes
    ----------
    rate : float
    points : ndarray, shape (ticks + 1, n_points, 2)
        Named points (chain tips first), m.
    ends : ndarray, shape (ticks + 1, n, 2)
        Link end points, m.
    info : dict
        Settings, wall time and the check against a looser solve.
    """

    rate: float
    points: np.ndarray
    ends: np.ndarray
    info: dict


def _positions(model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    kin = forward_kinematics(model, q)
    if model.points:
        links = np.array([p.ref.link for p in model.points], dtype=int)
        local = np.array([p.ref.local for p in model.points], dtype=float)
        pts = point_positions(kin, links, local)
    else:
        pts = np.zeros((0, 2))
    return pts, link_segments(model, kin)[:, 1]


def _efforts(scene: Scene) -> np.ndarray:
    return np.array([a.effort for a in scene.model.actuators], dtype=float)


def _exact_run(scene: Scene, horizon: float, rate: float, opts: dict) -> tuple[np.ndarray, np.ndarray, float]:
    settings = SimulationSettings(closure="exact", rate=rate, **opts)
    sim = Simulator(scene.model, settings, scene.gains)
    if scene.model.actuators:
        sim.set_efforts(_efforts(scene))
    ticks = int(round(horizon * rate))
    p0, e0 = _positions(scene.model, sim.q)
    pts = np.zeros((ticks + 1,) + p0.shape)
    ends = np.zeros((ticks + 1,) + e0.shape)
    pts[0], ends[0] = p0, e0
    t0 = time.perf_counter()
    for i in range(ticks):
        sim.advance()
        pts[i + 1], ends[i + 1] = _positions(scene.model, sim.q)
    return pts, ends, time.perf_counter() - t0


def compute_reference(scene: Scene, horizon: float, rate: float = REFERENCE_RATE,
                      check: bool = True) -> Reference:
    """Solve the scene with exact closure at tight tolerance.

    Parameters
    ----------
    scene : Scene
    horizon : float
        Simulated seconds.
    rate : float
        Tick rate at which positions are kept, Hz.
    check : bool
        Also solve at :data:`CHECK_SETTINGS` and report the largest difference.

    Returns
    -------
    Reference
    """
    pts, ends, wall = _exact_run(scene, horizon, rate, REFERENCE_SETTINGS)
    info = {"closure": "exact", **REFERENCE_SETTINGS, "rate": rate, "horizon": horizon,
            "wall_time": wall}
    if check:
        cp, ce, cwall = _exact_run(scene, horizon, rate, CHECK_SETTINGS)
        dev = max(_max_distance(cp, pts), _max_distance(ce, ends))
        info["check"] = {**CHECK_SETTINGS, "max_position_difference": dev, "wall_time": cwall}
    return Reference(rate, pts, ends, info)


def _max_distance(a: np.ndarray, b: np.ndarray) -> float:
    if a.size == 0:
        return 0.0
    return float(np.max(np.linalg.norm(a - b, axis=-1)))


def _ref_index(ref: Reference, rate: float, ticks: int) -> np.ndarray | None:
    ratio = ref.rate / rate
    k = int(round(ratio))
    if abs(ratio - k) > 1e-9 or k < 1 or ticks * k >= len(ref.ends):
        return None
    return np.arange(ticks + 1) * k


@dataclass
class RowResult:
    """Measures of one row (see the module docstring). None where not measured."""

    scene: str
    engine: str
    integrator: str
    rate: float
    substeps: int
    step: float | None
    closure: str
    label: str
    key: str
    settings: dict
    status: str = OK
    message: str = ""
    diverged_at: float | None = None
    wall_per_sim_s: float | None = None
    wall_samples: list = field(default_factory=list)
    cpu_per_sim_s: float | None = None
    cpu_samples: list = field(default_factory=list)
    realtime_factor: float | None = None
    steps_per_s: float | None = None
    evaluations_per_sim_s: float | None = None
    max_closure_error: float | None = None
    rms_closure_error: float | None = None
    energy_drift: float | None = None
    energy_balance_residual: float | None = None
    tip_deviation: float | None = None
    position_deviation: float | None = None
    finite: bool | None = None

    @property
    def ok(self) -> bool:
        """True when the row ran to the horizon."""
        return self.status == OK


def _new_result(scene: str, cfg: RowConfig) -> RowResult:
    return RowResult(scene, cfg.engine, cfg.integrator, cfg.rate, cfg.substeps, cfg.step,
                     cfg.closure, cfg.label(), cfg.key(), _jsonable(cfg.settings))


def _make_vjm(scene: Scene, cfg: RowConfig) -> Simulator:
    settings = SimulationSettings(integrator=cfg.integrator, rate=cfg.rate,
                                  substeps=cfg.substeps, **cfg.settings)
    sim = Simulator(scene.model, settings, scene.gains)
    if scene.model.actuators:
        sim.set_efforts(_efforts(scene))
    return sim


def _run_vjm(scene: Scene, cfg: RowConfig, horizon: float, ref: Reference | None) -> RowResult:
    res = _new_result(scene.name, cfg)
    try:
        warm = _make_vjm(scene, cfg)  # a compiled kernel compiles here, not in the timed loop
        try:
            warm.advance()
        except (VjmError, np.linalg.LinAlgError, FloatingPointError):
            pass
        sim = _make_vjm(scene, cfg)
    except StiffnessError as exc:
        res.status, res.message = REFUSED, str(exc)
        return res
    except (ConfigurationError, ValueError) as exc:
        res.status, res.message = FAILED, str(exc)
        return res
    ticks = int(round(horizon * cfg.rate))
    traj = Trajectory(scene.model, capacity=ticks + 2)
    traj.append(sim.sample())
    p0, e0 = _positions(scene.model, sim.q)
    pts = np.zeros((ticks + 1,) + p0.shape)
    ends = np.zeros((ticks + 1,) + e0.shape)
    pts[0], ends[0] = p0, e0
    wall = cpu = 0.0
    evals0 = sim.mechanism.evaluations
    try:
        for i in range(ticks):
            w0, c0 = time.perf_counter(), time.process_time()
            sim.advance()
            wall += time.perf_counter() - w0
            cpu += time.process_time() - c0
            traj.append(sim.sample())
            pts[i + 1], ends[i + 1] = _positions(scene.model, sim.q)
    except DivergenceError as exc:
        res.status, res.message, res.diverged_at = DIVERGED, str(exc), exc.time
        res.finite = False
        return res
    except (VjmError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
        res.status, res.message = FAILED, f"{type(exc).__name__}: {exc}"
        return res
    evals = sim.mechanism.evaluations - evals0 - ticks  # sample() evaluates once per tick
    summary = traj.summary()
    res.wall_samples = [wall / horizon]
    res.cpu_samples = [cpu / horizon]
    res.cpu_per_sim_s = cpu / horizon
    res.evaluations_per_sim_s = evals / horizon
    res.steps_per_s = (ticks * (cfg.substeps if not cfg.adaptive else 1)) / wall if wall > 0 else None
    for k in ("max_closure_error", "rms_closure_error", "energy_drift", "energy_balance_residual",
              "finite"):
        setattr(res, k, summary[k])
    _deviation(res, ref, cfg.rate, ticks, pts, ends)
    return res


def _deviation(res: RowResult, ref: Reference | None, rate: float, ticks: int,
               pts: np.ndarray, ends: np.ndarray) -> None:
    if ref is None:
        return
    idx = _ref_index(ref, rate, ticks)
    if idx is None:
        return
    res.tip_deviation = _max_distance(pts, ref.points[idx])
    res.position_deviation = max(res.tip_deviation, _max_distance(ends, ref.ends[idx]))


def _time_vjm(scene: Scene, cfg: RowConfig, horizon: float) -> tuple[float, float]:
    sim = _make_vjm(scene, cfg)
    ticks = int(round(horizon * cfg.rate))
    advance = sim.advance
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(ticks):
        advance()
    return (time.perf_counter() - t0) / horizon, (time.process_time() - c0) / horizon


def _make_mujoco(scene: Scene, cfg: RowConfig):
    from vjm_ros.studies.compare_mujoco import MujocoSettings, MujocoSimulator

    ms = MujocoSettings(integrator=cfg.integrator, rate=cfg.rate, substeps=cfg.substeps,
                        solref=tuple(cfg.settings["solref"]), solimp=tuple(cfg.settings["solimp"]))
    sim = MujocoSimulator(scene.model, ms)
    if scene.model.actuators:
        sim.set_efforts(_efforts(scene))
    return sim


def _run_mujoco(scene: Scene, cfg: RowConfig, horizon: float, ref: Reference | None) -> RowResult:
    res = _new_result(scene.name, cfg)
    try:
        sim = _make_mujoco(scene, cfg)
    except (NotImplementedError, ValueError) as exc:
        res.status, res.message = FAILED, str(exc)
        return res
    ticks = int(round(horizon * cfg.rate))
    n_pts = len(scene.model.points)
    pts = np.zeros((ticks + 1, n_pts, 2))
    ends = np.zeros((ticks + 1, scene.model.n, 2))
    closure = np.zeros(ticks + 1)
    energy = np.zeros((ticks + 1, 2))
    power = np.zeros(ticks + 1)

    def sample(i: int) -> None:
        sim.refresh()
        pts[i], ends[i] = sim.points(), sim.link_ends()
        err = sim.closure_errors()
        closure[i] = float(err.max()) if err.size else 0.0
        energy[i] = sim.energy()
        power[i] = sim.power_in()

    wall = cpu = 0.0
    with sim:
        sample(0)
        try:
            for i in range(ticks):
                w0, c0 = time.perf_counter(), time.process_time()
                sim.step_tick()
                wall += time.perf_counter() - w0
                cpu += time.process_time() - c0
                sim.ticks += 1
                sim.t = sim.ticks * sim.dt
                sim.check()
                sample(i + 1)
        except DivergenceError as exc:
            res.status, res.message, res.diverged_at = DIVERGED, str(exc), exc.time
            res.finite = False
            return res
    tv = energy.sum(axis=1)
    kin_max = float(energy[:, 0].max())
    work = np.concatenate(([0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) / cfg.rate)))
    res.wall_samples = [wall / horizon]
    res.cpu_samples = [cpu / horizon]
    res.cpu_per_sim_s = cpu / horizon
    res.steps_per_s = ticks * cfg.substeps / wall if wall > 0 else None
    res.max_closure_error = float(closure.max())
    res.rms_closure_error = float(np.sqrt(np.mean(closure**2)))
    res.energy_drift = float(np.max(np.abs(tv - tv[0])) / kin_max) if kin_max > 0 else 0.0
    res.energy_balance_residual = float(np.max(np.abs(tv - tv[0] - work)))
    res.finite = bool(np.all(np.isfinite(ends)))
    _deviation(res, ref, cfg.rate, ticks, pts, ends)
    return res


def _time_mujoco(scene: Scene, cfg: RowConfig, horizon: float) -> tuple[float, float]:
    sim = _make_mujoco(scene, cfg)
    ticks = int(round(horizon * cfg.rate))
    with sim:
        step = sim.step_tick
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(ticks):
            step()
        return (time.perf_counter() - t0) / horizon, (time.process_time() - c0) / horizon


def _finish_timing(res: RowResult) -> None:
    if res.wall_samples:
        res.wall_per_sim_s = float(statistics.median(res.wall_samples))
        res.realtime_factor = 1.0 / res.wall_per_sim_s if res.wall_per_sim_s > 0 else None
    if res.cpu_samples:
        res.cpu_per_sim_s = float(statistics.median(res.cpu_samples))
        if res.steps_per_s is not None:
            steps_per_sim_s = res.rate * (res.substeps if res.step is not None else 1)
            res.steps_per_s = steps_per_sim_s / res.wall_per_sim_s


# ---------------------------------------------------------------------------------------- analysis
def pareto_front(rows: Sequence[RowResult]) -> list[RowResult]:
    """Rows not beaten in both cost and position error, cheapest first.

    Parameters
    ----------
    rows : sequence of RowResult
        Only rows that ran (``ok``) with a cost and a position error are considered.

    Returns
    -------
    list of RowResult
    """
    cand = [r for r in rows if r.ok and r.wall_per_sim_s is not None
            and r.position_deviation is not None]
    cand.sort(key=lambda r: (r.wall_per_sim_s, r.position_deviation))
    front, best = [], math.inf
    for r in cand:
        if r.position_deviation < best:
            front.append(r)
            best = r.position_deviation
    return front


def _live_ok(r: RowResult) -> bool:
    """Fixed step at 1 kHz, and at least :data:`LIVE_HEADROOM` times faster than real time.

    Speed here is CPU time per simulated second (wall time where none was measured): on a shared
    machine the wall time penalizes every row alike, the CPU time is what a core of its own
    would take.
    """
    cost = r.cpu_per_sim_s if r.cpu_per_sim_s else r.wall_per_sim_s
    return (r.ok and r.step is not None and abs(r.rate - LIVE_RATE) < 1e-9
            and cost is not None and cost > 0 and 1.0 / cost >= LIVE_HEADROOM
            and r.position_deviation is not None)


def recommend(rows: Sequence[RowResult], engine: str = "vjm") -> dict:
    """The recommended row per tier for one scene.

    ``live 1 kHz``: among fixed-step rows at 1 kHz at least :data:`LIVE_HEADROOM` times faster
    than real time (CPU time, see :func:`_live_ok`), the smallest position error (ties: the
    cheapest). Accuracy tiers: the
    cheapest row whose position error is within the tier.

    Returns
    -------
    dict
        Tier name to the row's key, label, cost and errors (None when no row qualifies).
    """
    mine = [r for r in rows if r.engine == engine and r.ok and r.position_deviation is not None
            and r.wall_per_sim_s is not None]
    out = {}
    for tier, tol in TIERS:
        if tol is None:
            cand = sorted((r for r in mine if _live_ok(r)),
                          key=lambda r: (r.position_deviation, r.wall_per_sim_s))
        else:
            cand = sorted((r for r in mine if r.position_deviation <= tol),
                          key=lambda r: (r.wall_per_sim_s, r.position_deviation))
        out[tier] = _brief(cand[0]) if cand else None
    return out


def _brief(r: RowResult) -> dict:
    return {
        "key": r.key, "label": r.label, "wall_per_sim_s": r.wall_per_sim_s,
        "realtime_factor": r.realtime_factor, "cpu_per_sim_s": r.cpu_per_sim_s,
        "position_deviation": r.position_deviation,
        "tip_deviation": r.tip_deviation, "max_closure_error": r.max_closure_error,
        "energy_drift": r.energy_drift,
    }


def recommend_overall(scenes: dict) -> dict:
    """One setting per tier that qualifies on every benched scene.

    Live tier: the setting with the smallest worst-case position error among those that are live
    (1 kHz, CPU time at most 1 / :data:`LIVE_HEADROOM` of real time) on every scene. Accuracy tiers: the setting
    within the tier on every scene with the smallest total cost.

    Parameters
    ----------
    scenes : dict
        Scene name to its list of :class:`RowResult`.

    Returns
    -------
    dict
        Tier to a summary (None when no single setting qualifies everywhere).
    """
    by_key: dict[str, dict[str, RowResult]] = {}
    for name, rows in scenes.items():
        for r in rows:
            if r.engine == "vjm":
                by_key.setdefault(r.key, {})[name] = r
    names = list(scenes)
    out = {}
    for tier, tol in TIERS:
        best, best_score = None, None
        for key, per in by_key.items():
            if len(per) != len(names):
                continue
            rs = list(per.values())
            if tol is None:
                if not all(_live_ok(r) for r in rs):
                    continue
                score = (max(r.position_deviation for r in rs), sum(r.wall_per_sim_s for r in rs))
            else:
                if not all(r.ok and r.position_deviation is not None and r.position_deviation <= tol
                           and r.wall_per_sim_s is not None for r in rs):
                    continue
                score = (sum(r.wall_per_sim_s for r in rs), max(r.position_deviation for r in rs))
            if best_score is None or score < best_score:
                best, best_score = key, score
        if best is None:
            out[tier] = None
            continue
        rs = by_key[best]
        out[tier] = {
            "key": best,
            "label": next(iter(rs.values())).label,
            "worst_position_deviation": max(r.position_deviation for r in rs.values()),
            "worst_max_closure_error": max(r.max_closure_error for r in rs.values()),
            "worst_wall_per_sim_s": max(r.wall_per_sim_s for r in rs.values()),
            "worst_cpu_per_sim_s": max((r.cpu_per_sim_s or r.wall_per_sim_s) for r in rs.values()),
            "per_scene": {n: _brief(r) for n, r in rs.items()},
        }
    return out


def matched_accuracy(rows: Sequence[RowResult]) -> list[dict]:
    """vjm against MuJoCo: the cheapest row of each reaching a position error, per level.

    Returns
    -------
    list of dict
        ``level``, the two rows' labels and costs, and ``ratio`` (vjm cost / MuJoCo cost).
    """
    out = []
    for level in MATCH_LEVELS:
        best = {}
        for engine in ("vjm", "mujoco"):
            cand = [r for r in rows if r.engine == engine and r.ok and r.wall_per_sim_s is not None
                    and r.position_deviation is not None and r.position_deviation <= level]
            best[engine] = min(cand, key=lambda r: r.wall_per_sim_s) if cand else None
        v, m = best["vjm"], best["mujoco"]
        out.append({
            "level": level,
            "vjm": _brief(v) if v else None,
            "mujoco": _brief(m) if m else None,
            "ratio": (v.wall_per_sim_s / m.wall_per_sim_s) if (v and m and m.wall_per_sim_s) else None,
        })
    return out


def live_comparison(rows: Sequence[RowResult]) -> dict:
    """Best live (1 kHz) row of vjm and of MuJoCo, by position error."""
    out = {}
    for engine in ("vjm", "mujoco"):
        cand = [r for r in rows if r.engine == engine and _live_ok(r)]
        cand.sort(key=lambda r: (r.position_deviation, r.wall_per_sim_s))
        out[engine] = _brief(cand[0]) if cand else None
    return out


# ---------------------------------------------------------------------------------------- scaling scenes
def chain_scene(n_links: int, gains: str = "closure_method: {method: penalty, omega_n: 100.0, zeta: 1.0}") -> Scene:
    """One chain of ``n_links`` revolute links (1 m, 1 kg in all) whose tip runs on a horizontal line.

    The links hang in a zigzag (absolute angles alternating -60 and -120 degrees); the line passes
    through the initial tip, so the scene closes exactly at t = 0 (one slider row).

    Parameters
    ----------
    n_links : int
        1 or more.
    gains : str
        The scene's ``closure_method`` line.

    Returns
    -------
    Scene
    """
    if n_links < 1:
        raise ValueError("n_links: expected 1 or more")
    length, mass = 1.0 / n_links, 1.0 / n_links
    inertia = mass * length**2 / 12.0
    links, x, y = [], 0.0, 0.0
    for k in range(n_links):
        ang = -math.pi / 3 if k % 2 == 0 else -2 * math.pi / 3
        x += length * math.cos(ang)
        y += length * math.sin(ang)
        links.append(
            f"      - {{name: l{k}, length: {length!r}, mass: {mass!r}, inertia: {inertia!r}, "
            f"com: [{length / 2!r}, 0.0], joint: {{name: j{k}, type: revolute, angle: {ang!r}}}}}"
        )
    text = "\n".join([
        f"name: chain_{n_links}",
        "description: generated chain for the cost-per-tick study",
        "chains:",
        "  - name: chain",
        "    links:",
        *links,
        "closures:",
        f"  - {{name: tip_line, type: slider, point: {{link: l{n_links - 1}, at: tip}}, "
        f"line: {{ground: [{x!r}, {y!r}], direction: [1.0, 0.0]}}}}",
        gains,
    ])
    return parse_scene(text, source=f"<chain_scene {n_links}>")


def star_scene(n_chains: int, gains: str = "closure_method: {method: penalty, omega_n: 100.0, zeta: 1.0}") -> Scene:
    """``n_chains`` two-link chains from a unit circle whose tips meet at its centre.

    The first chain's tip is pinned to every other chain's tip (``n_chains - 1`` hinges, two rows
    each); the mechanism keeps two degrees of freedom. Links 0.6 m, 0.5 kg, ``I = m a^2 / 12``.

    Parameters
    ----------
    n_chains : int
        1 or more.
    gains : str
        The scene's ``closure_method`` line.

    Returns
    -------
    Scene
    """
    if n_chains < 1:
        raise ValueError("n_chains: expected 1 or more")
    a, m = 0.6, 0.5
    inertia = m * a * a / 12.0
    h = math.sqrt(a * a - 0.25)
    chains = []
    for c in range(n_chains):
        alpha = 2 * math.pi * c / n_chains + 0.1
        bx, by = math.cos(alpha), math.sin(alpha)
        ex, ey = 0.5 * bx - h * by, 0.5 * by + h * bx  # elbow: midpoint plus h along n(alpha)
        th2 = math.atan2(ey - by, ex - bx)
        th3 = math.atan2(-ey, -ex)
        chains += [
            f"  - name: c{c}",
            f"    origin: [{bx!r}, {by!r}]",
            "    links:",
            f"      - {{name: c{c}_p, length: {a!r}, mass: {m!r}, inertia: {inertia!r}, "
            f"com: [{a / 2!r}, 0.0], joint: {{name: c{c}_base, type: revolute, angle: {th2!r}}}}}",
            f"      - {{name: c{c}_d, length: {a!r}, mass: {m!r}, inertia: {inertia!r}, "
            f"com: [{a / 2!r}, 0.0], joint: {{name: c{c}_elbow, type: revolute, angle: {th3!r}}}}}",
        ]
    closures = [
        f"  - {{name: pin{c}, type: hinge, point: {{link: c0_d, at: tip}}, target: {{link: c{c}_d, at: tip}}}}"
        for c in range(1, n_chains)
    ]
    text = "\n".join([
        f"name: star_{n_chains}",
        "description: generated chains meeting at one pin, for the cost-per-tick study",
        "chains:",
        *chains,
        "closures:" + ("" if closures else " []"),
        *closures,
        gains,
        "assemble: {fixed: [c0_base]}",
    ])
    return parse_scene(text, source=f"<star_scene {n_chains}>")


SCALING_METHODS = (
    ("semi_implicit_euler", {"closure": "penalty", "omega_n": 100.0, "zeta": 1.0}),
    ("implicit_euler", {"closure": "penalty", "kp": 1e5, "kv": 100.0}),
    ("rk4", {"closure": "exact"}),
)
"""Settings timed in the cost-per-tick study (1 kHz, one step per tick)."""


def tick_cost(scene: Scene, integrator: str, settings: dict, ticks: int, repeats: int) -> float:
    """Median wall time of one 1 kHz tick, s.

    Parameters
    ----------
    scene : Scene
    integrator : str
    settings : dict
        More :class:`SimulationSettings` fields.
    ticks : int
        Ticks per timed repeat.
    repeats : int

    Returns
    -------
    float
    """
    samples = []
    for _ in range(max(repeats, 1)):
        sim = Simulator(scene.model, SimulationSettings(integrator=integrator, rate=1000.0,
                                                        **settings), scene.gains)
        sim.advance()  # warm-up
        t0 = time.perf_counter()
        for _ in range(ticks):
            sim.advance()
        samples.append((time.perf_counter() - t0) / ticks)
    return float(statistics.median(samples))


def _slope(ns: Sequence[float], costs: Sequence[float]) -> float | None:
    pairs = [(math.log(n), math.log(c)) for n, c in zip(ns, costs, strict=True) if n >= 4 and c and c > 0]
    if len(pairs) < 2:
        return None
    x = np.array([p[0] for p in pairs])
    y = np.array([p[1] for p in pairs])
    return float(np.polyfit(x, y, 1)[0])


def _scaling_methods(extra: dict) -> list[tuple[str, str, dict]]:
    """(key, integrator, settings) of the scaling study; the numpy kernel too, when selectable."""
    out = []
    kernels = [None]
    if "kernel" in {f.name for f in fields(SimulationSettings)} and "kernel" not in extra:
        kernels.append("numpy")
    for kernel in kernels:
        for integ, settings in SCALING_METHODS:
            key = f"{integ} {settings['closure']}" + (f" [{kernel} kernel]" if kernel else "")
            st = {**settings, **extra, **({"kernel": kernel} if kernel else {})}
            out.append((key, integ, st))
    return out


def run_scaling(grid: Grid, repeats: int, progress: BenchProgress | None = None,
                extra: dict | None = None) -> dict:
    """Cost per tick against chain length and number of chains.

    Each method of :data:`SCALING_METHODS` is timed with the default physics kernel and, when
    :class:`SimulationSettings` has a ``kernel`` field, also with the numpy reference kernel.

    Returns
    -------
    dict
        ``methods`` (column keys), ``links`` and ``chains`` tables (size, closure rows, seconds
        per tick per method) and the fitted growth exponent of each method for sizes >= 4.
    """
    methods = _scaling_methods(dict(extra or {}))
    out: dict = {"methods": [m[0] for m in methods]}
    for family, sizes, build in (("links", grid.scaling_links, chain_scene),
                                 ("chains", grid.scaling_chains, star_scene)):
        table = []
        for size in sizes:
            scene = build(size)
            row = {"size": size, "n": scene.model.n, "rows": scene.model.n_rows}
            for key, integ, settings in methods:
                try:
                    row[key] = tick_cost(scene, integ, settings, grid.scaling_ticks, repeats)
                except (VjmError, np.linalg.LinAlgError) as exc:
                    row[key] = None
                    row.setdefault("errors", {})[key] = str(exc)
                if progress:
                    progress.advance(_scaling_work(scene, integ, grid, repeats) / len(methods) * 3,
                                     f"scaling {family} {size}")
            table.append(row)
        growth = {key: _slope([r["n"] for r in table], [r.get(key) for r in table])
                  for key, _, _ in methods}
        out[family] = {"table": table, "growth_exponent": growth}
    return out


def _scaling_keys(scaling: dict) -> list[str]:
    return scaling.get("methods") or [f"{i} {s['closure']}" for i, s in SCALING_METHODS]


def _scaling_work(scene: Scene, integ: str, grid: Grid, repeats: int) -> float:
    stages = 4.0 if integ == "rk4" else 1.0
    return stages * (grid.scaling_ticks + 1) * max(repeats, 1) * (1 + scene.model.n / 8)


# ---------------------------------------------------------------------------------------- long run
def long_run(scene_name: str = "four_bar", seconds: float = 3600.0,
             settings: SimulationSettings | None = None, sample_every: int = 10,
             progress: Callable[[float], None] | None = None) -> dict:
    """Simulate one scene for a long time and report its energy drift and closure error.

    Parameters
    ----------
    scene_name : str
    seconds : float
        Simulated seconds.
    settings : SimulationSettings, optional
        Default: the scene's defaults (``rk4`` at 1 kHz with its closure gains).
    sample_every : int
        Ticks between samples of energy and closure error.
    progress : callable, optional
        Called with the simulated time now and then.

    Returns
    -------
    dict
        Settings, ``sim_time``, ``wall_time``, ``max_closure_error``, ``final_closure_error``,
        ``energy_drift`` (as docs/design.md defines it), ``max_energy_change`` and ``max_energy_gain``
        (largest ``|T+V - (T+V)(0)|`` and largest rise above it, J), ``energy_initial``/
        ``energy_final`` (T + V),
        ``finite`` and, on failure, ``error``.
    """
    scene = load_scene(scene_name)
    if settings is None:
        d, g = scene.defaults, scene.gains
        settings = SimulationSettings(integrator=d.get("integrator", "rk4"),
                                      rate=d.get("rate", 1000.0), substeps=d.get("substeps", 1),
                                      closure=g.get("method", "penalty"))
    sim = Simulator(scene.model, settings, scene.gains)
    if scene.model.actuators:
        sim.set_efforts(_efforts(scene))
    ticks = int(round(seconds * settings.rate))
    s0 = sim.sample()
    tv0 = float(s0.energy[0] + s0.energy[1])
    max_t = float(s0.energy[0])
    max_dev = max_gain = 0.0
    max_err = s0.max_closure_error
    last = s0
    error = None
    t0 = time.perf_counter()
    try:
        for i in range(1, ticks + 1):
            sim.advance()
            if i % sample_every == 0 or i == ticks:
                last = sim.sample()
                tv = float(last.energy[0] + last.energy[1])
                max_t = max(max_t, float(last.energy[0]))
                max_dev = max(max_dev, abs(tv - tv0))
                max_gain = max(max_gain, tv - tv0)
                max_err = max(max_err, last.max_closure_error)
                if progress and i % (100 * sample_every) == 0:
                    progress(sim.t)
    except DivergenceError as exc:
        error = str(exc)
    wall = time.perf_counter() - t0
    return {
        "scene": scene_name,
        "settings": _jsonable(asdict(settings)),
        "sim_time": sim.t,
        "wall_time": wall,
        "sample_every_ticks": sample_every,
        "max_closure_error": max_err,
        "final_closure_error": last.max_closure_error,
        "energy_drift": (max_dev / max_t) if max_t > 0 else 0.0,
        "max_energy_change": max_dev,
        "max_energy_gain": max_gain,
        "energy_initial": tv0,
        "energy_final": float(last.energy[0] + last.energy[1]),
        "finite": bool(np.all(np.isfinite(sim.q)) and np.all(np.isfinite(sim.qd))) and error is None,
        "error": error,
    }


# ---------------------------------------------------------------------------------------- driver
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


def horizon_for(name: str, quick: bool, override: float | None = None) -> float:
    """Simulated seconds compared for a scene."""
    if override is not None:
        return float(override)
    h = HORIZONS.get(name, DEFAULT_HORIZON)
    return min(h, QUICK_HORIZON) if quick else h


def run_bench(opts: BenchOptions) -> dict:
    """Run the study and write the outputs.

    Parameters
    ----------
    opts : BenchOptions

    Returns
    -------
    dict
        Everything written to ``results.json``.
    """
    threads = limit_threads()
    grid = opts.grid or (quick_grid() if opts.quick else full_grid())
    from vjm_ros.studies.compare_mujoco import mujoco_version, version_note

    mj_version = mujoco_version() if opts.mujoco else None
    mj_note = version_note(mj_version)
    scenes = [load_scene(s) for s in opts.scenes]
    plan = []
    total = 0.0
    for sc in scenes:
        horizon = horizon_for(sc.name, opts.quick, opts.horizon)
        use_mj = bool(mj_version) and sc.name in MUJOCO_SCENES
        rows = grid_rows(grid, use_mj, opts.extra)
        plan.append((sc, horizon, rows))
        total += 2 * 6000.0 * horizon  # reference and its check
        for cfg in rows:
            total += _work(cfg, horizon, sc.model.n) * (1 + max(opts.repeats - 1, 0))
    if opts.scaling:
        for family, sizes in (("links", grid.scaling_links), ("chains", grid.scaling_chains)):
            for size in sizes:
                n = size if family == "links" else 2 * size
                for integ, _ in SCALING_METHODS:
                    stages = 4.0 if integ == "rk4" else 1.0
                    total += stages * (grid.scaling_ticks + 1) * max(opts.repeats, 1) * (1 + n / 8)
    kernel = None
    if scenes:
        try:
            probe = Simulator(scenes[0].model, SimulationSettings(
                integrator="rk4", closure="exact", **opts.extra), scenes[0].gains)
            kernel = probe.describe().get("kernel", "numpy")
        except (VjmError, TypeError):
            kernel = None
    progress = BenchProgress(total, enabled=opts.progress)
    started = time.perf_counter()
    results: dict = {
        "meta": {**_meta(opts, threads, mj_version, mj_note, grid), "kernel": kernel},
        "scenes": {},
    }
    all_rows: dict[str, list[RowResult]] = {}
    try:
        for sc, horizon, rows in plan:
            progress.draw(f"{sc.name}: reference")
            try:
                ref = compute_reference(sc, horizon)
                ref_info = ref.info
            except (VjmError, np.linalg.LinAlgError) as exc:
                ref, ref_info = None, {"error": str(exc)}
            progress.advance(2 * 6000.0 * horizon, f"{sc.name}: reference done")
            out_rows = []
            for cfg in rows:
                runner = _run_mujoco if cfg.engine == "mujoco" else _run_vjm
                res = runner(sc, cfg, horizon, ref)
                out_rows.append(res)
                progress.advance(_work(cfg, horizon, sc.model.n), f"{sc.name}: {cfg.label()}")
            for _ in range(max(opts.repeats - 1, 0)):
                for cfg, res in zip(rows, out_rows, strict=True):
                    if res.ok:
                        timer = _time_mujoco if cfg.engine == "mujoco" else _time_vjm
                        try:
                            wall_s, cpu_s = timer(sc, cfg, horizon)
                            res.wall_samples.append(wall_s)
                            res.cpu_samples.append(cpu_s)
                        except (VjmError, np.linalg.LinAlgError, FloatingPointError) as exc:
                            res.message = f"a timing repeat failed: {exc}"
                    progress.advance(_work(cfg, horizon, sc.model.n),
                                     f"{sc.name}: timing {cfg.label()}")
            for res in out_rows:
                _finish_timing(res)
            all_rows[sc.name] = out_rows
            results["scenes"][sc.name] = _scene_summary(sc, horizon, ref_info, out_rows)
        if opts.scaling:
            results["scaling"] = run_scaling(grid, opts.repeats, progress, opts.extra)
    finally:
        progress.close()
    results["recommended"] = recommend_overall(all_rows) if all_rows else {}
    cpu = sum(sum(r.cpu_samples) for rs in all_rows.values() for r in rs
              if r.ok and len(r.cpu_samples) == len(r.wall_samples))
    wall = sum(sum(r.wall_samples) for rs in all_rows.values() for r in rs
               if r.ok and len(r.cpu_samples) == len(r.wall_samples))
    results["meta"]["cpu_share"] = cpu / wall if wall > 0 else None
    results["meta"]["bench_wall_time"] = time.perf_counter() - started
    long_runs = _long_runs(opts.out)
    if long_runs:
        results["long_runs"] = long_runs
    write_outputs(results, all_rows, opts)
    return results


def _long_runs(out: Path) -> list[dict]:
    found = []
    for path in sorted(out.glob("long_run*.json")) if out.is_dir() else []:
        try:
            found.append({**json.loads(path.read_text()), "source": path.name})
        except (OSError, ValueError):
            continue
    return found


def rows_from_results(results: dict) -> dict[str, list[RowResult]]:
    """The rows of a ``results.json`` as :class:`RowResult` objects, per scene."""
    names = {f.name for f in fields(RowResult)}

    def value(v):
        return float(v) if v in ("inf", "-inf") else v

    return {
        scene: [RowResult(**{k: value(v) for k, v in r.items() if k in names}) for r in sm["rows"]]
        for scene, sm in results["scenes"].items()
    }


def rerender(results_path: Path, opts: BenchOptions) -> dict:
    """Write the outputs again from a ``results.json`` (and the long runs found in ``opts.out``).

    Parameters
    ----------
    results_path : Path
    opts : BenchOptions
        ``out`` and ``docs`` are used.

    Returns
    -------
    dict
        The results as written.
    """
    try:
        results = json.loads(Path(results_path).read_text())
    except (OSError, ValueError) as exc:
        raise ConfigurationError(f"--from-results {results_path}: expected a results.json "
                                 f"written by vjm bench ({exc})") from None
    rows = rows_from_results(results)
    for name, rs in rows.items():
        results["scenes"][name].update(_analysis(rs))
    results["recommended"] = recommend_overall(rows) if rows else {}
    long_runs = _long_runs(opts.out)
    if long_runs:
        results["long_runs"] = long_runs
    write_outputs(results, rows, opts)
    return results


def _scene_summary(sc: Scene, horizon: float, ref_info: dict, rows: list[RowResult]) -> dict:
    return {
        "horizon": horizon,
        "horizon_note": HORIZON_NOTES.get(sc.name, ""),
        "n": sc.model.n,
        "closure_rows": sc.model.n_rows,
        "reference": ref_info,
        "rows": [_jsonable(asdict(r)) for r in rows],
        **_analysis(rows),
    }


def _analysis(rows: list[RowResult]) -> dict:
    """Counts, Pareto fronts, tiers and the MuJoCo comparison of one scene's rows."""
    counts: dict[str, int] = {}
    for r in rows:
        counts[r.status] = counts.get(r.status, 0) + 1
    return {
        "counts": counts,
        "pareto": {
            "vjm": [r.key for r in pareto_front([r for r in rows if r.engine == "vjm"])],
            "mujoco": [r.key for r in pareto_front([r for r in rows if r.engine == "mujoco"])],
        },
        "recommended": recommend(rows),
        "matched_accuracy": matched_accuracy(rows) if any(r.engine == "mujoco" for r in rows) else [],
        "live": live_comparison(rows) if any(r.engine == "mujoco" for r in rows) else {},
    }


def _meta(opts: BenchOptions, threads: dict, mj_version, mj_note, grid: Grid) -> dict:
    import scipy

    return {
        "command": opts.command,
        "date": _dt.datetime.now().astimezone().isoformat(timespec="seconds"),
        "quick": opts.quick,
        "repeats": opts.repeats,
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "scipy": scipy.__version__,
        },
        "threads": threads,
        "mujoco": {"version": mj_version, "note": mj_note,
                   "skipped": None if mj_version else "MuJoCo is not installed (pip install '.[compare]')"},
        "reference": {**REFERENCE_SETTINGS, "closure": "exact", "rate": REFERENCE_RATE,
                      "check": CHECK_SETTINGS},
        "live": {"rate": LIVE_RATE, "min_realtime_factor": LIVE_HEADROOM},
        "extra_settings": _jsonable(opts.extra),
        "grid": _jsonable(asdict(grid)),
    }


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if isinstance(x, Path):
        return str(x)
    return x


# ---------------------------------------------------------------------------------------- outputs
def write_outputs(results: dict, rows: dict[str, list[RowResult]], opts: BenchOptions) -> None:
    """Write ``results.json``, ``report.md``, the figures and (with ``--docs``) the docs page."""
    out = opts.out
    out.mkdir(parents=True, exist_ok=True)
    figures = {}
    for name, rs in rows.items():
        path = out / f"{name}_pareto.png"
        plot_pareto(name, rs, results["scenes"][name], path)
        figures[name] = path.name
    if "scaling" in results:
        plot_scaling(results["scaling"], out / "scaling.png")
        figures["scaling"] = "scaling.png"
    results["figures"] = figures
    (out / "results.json").write_text(json.dumps(_jsonable(results), indent=1) + "\n")
    (out / "report.md").write_text(render_report(results, rows))
    if opts.docs is not None:
        docs = Path(opts.docs)
        fig_dir = docs.parent / "figures"
        fig_dir.mkdir(parents=True, exist_ok=True)
        for fname in figures.values():
            shutil.copyfile(out / fname, fig_dir / fname)
        docs.write_text(render_docs(results, rows))


_COLORS = {
    "explicit_euler": "#d62728", "semi_implicit_euler": "#ff7f0e", "rk4": "#2ca02c",
    "implicit_euler": "#1f77b4", "dop853": "#9467bd", "rk45": "#8c564b", "rk23": "#e377c2",
    "radau": "#17becf", "bdf": "#bcbd22", "lsoda": "#7f7f7f",
    "Euler": "#555555", "implicitfast": "#999999", "RK4": "#000000",
}


def _marker(r: RowResult) -> str:
    if r.engine == "mujoco":
        return "^"
    if r.closure.startswith("exact + projection"):
        return "D"
    if r.closure.startswith("exact"):
        return "s"
    return "o"


def plot_pareto(name: str, rows: Sequence[RowResult], summary: dict, path: Path) -> None:
    """Position error against cost, every row that ran, with the Pareto fronts.

    Parameters
    ----------
    name : str
        Scene name.
    rows : sequence of RowResult
    summary : dict
        The scene's summary (horizon, counts).
    path : Path
        PNG file written.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    fig = Figure(figsize=(9.5, 6.0), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    pts = [r for r in rows if r.ok and r.wall_per_sim_s and r.position_deviation is not None]
    floor = 1e-14
    for r in pts:
        ax.scatter(r.wall_per_sim_s, max(r.position_deviation, floor), marker=_marker(r),
                   s=34 if r.engine == "vjm" else 40, color=_COLORS.get(r.integrator, "#333333"),
                   alpha=0.8, edgecolors="none" if _marker(r) != "^" else "black", linewidths=0.5)
    for engine, style, label in (("vjm", "-", "vjm Pareto front"),
                                 ("mujoco", "--", "MuJoCo Pareto front")):
        front = pareto_front([r for r in rows if r.engine == engine])
        if front:
            xs = [r.wall_per_sim_s for r in front]
            ys = [max(r.position_deviation, floor) for r in front]
            ax.step(xs, ys, where="post", linestyle=style, color="black", linewidth=1.0,
                    label=label)
    ax.axvline(1.0, color="gray", linestyle=":", linewidth=1)
    ax.axvline(1.0 / LIVE_HEADROOM, color="gray", linestyle="-.", linewidth=0.8)
    ax.text(1.0, 0.02, " realtime", transform=ax.get_xaxis_transform(), fontsize=7,
            color="gray")
    ax.text(1.0 / LIVE_HEADROOM, 0.06, f" live budget (RTF {LIVE_HEADROOM:g}) ",
            transform=ax.get_xaxis_transform(), fontsize=7, color="gray", ha="right")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("cost: wall seconds per simulated second (median, single core)")
    ax.set_ylabel("position error vs exact reference (m, max over ticks)")
    counts = summary.get("counts", {})
    ax.set_title(
        f"{name}: horizon {summary['horizon']:g} s; {counts.get(OK, 0)} rows ran, "
        f"{counts.get(REFUSED, 0)} refused (stiffness), {counts.get(DIVERGED, 0)} diverged",
        fontsize=10,
    )
    ax.grid(True, which="major", alpha=0.3)
    handles = [Line2D([], [], linestyle="", marker="^" if k in MJ_INTEGRATORS else "o", color=c,
                      label=f"MuJoCo {k}" if k in MJ_INTEGRATORS else k)
               for k, c in _COLORS.items() if any(r.integrator == k for r in pts)]
    handles += [
        Line2D([], [], linestyle="", marker="o", color="gray", label="penalty closure"),
        Line2D([], [], linestyle="", marker="s", color="gray", label="exact closure"),
        Line2D([], [], linestyle="", marker="D", color="gray", label="exact + projection"),
    ]
    handles += ax.get_legend_handles_labels()[0]
    ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    fig.savefig(path)


def plot_scaling(scaling: dict, path: Path) -> None:
    """Seconds per 1 kHz tick against the number of coordinates, per family and method."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4.2), dpi=110)
    FigureCanvasAgg(fig)
    for k, (family, title) in enumerate((("links", "one chain of N links (1 slider row)"),
                                         ("chains", "N two-link chains meeting at one pin"))):
        ax = fig.add_subplot(1, 2, k + 1)
        table = scaling[family]["table"]
        for key in _scaling_keys(scaling):
            integ = key.split()[0]
            xs = [r["n"] for r in table if r.get(key)]
            ys = [r[key] * 1e6 for r in table if r.get(key)]
            g = scaling[family]["growth_exponent"].get(key)
            lab = f"{key} (~n^{g:.2f})" if g is not None else key
            ax.plot(xs, ys, marker="o", label=lab, color=_COLORS.get(integ, "black"),
                    linestyle="--" if "kernel]" in key else "-", markersize=4)
        ax.axhline(1000.0, color="gray", linestyle=":", linewidth=1)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("coordinates n")
        ax.set_ylabel("microseconds per 1 kHz tick")
        ax.set_title(title, fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6, loc="best", framealpha=0.7)
    fig.tight_layout()
    fig.savefig(path)


def _e(x, digits: int = 2) -> str:
    if x is None:
        return "–"
    if isinstance(x, str):
        return x
    if x == 0:
        return "0"
    return f"{x:.{digits}e}" if (abs(x) < 1e-2 or abs(x) >= 1e4) else f"{x:.{digits + 1}g}"


def _ms(x) -> str:
    return "–" if x is None else f"{1e3 * x:.3g}"


def _status(r: RowResult) -> str:
    if r.status == DIVERGED:
        return f"diverged at t = {r.diverged_at:.3g} s" if r.diverged_at is not None else DIVERGED
    return r.status


def _row_table(rows: Sequence[RowResult]) -> list[str]:
    lines = [
        "| engine | integrator | rate Hz | substeps | h ms | closure | status | ms per sim s | RTF "
        "| max closure err m | energy drift | ledger residual J | tip err m | position err m |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        h = "adaptive" if r.step is None else f"{1e3 * r.step:.3g}"
        integ = r.integrator if r.step is not None else f"{r.integrator} rtol {r.settings.get('rtol'):.0e}"
        lines.append(
            f"| {r.engine} | {integ} | {r.rate:g} | {r.substeps} | {h} | {r.closure} | {_status(r)} "
            f"| {_ms(r.wall_per_sim_s)} | {_e(r.realtime_factor)} | {_e(r.max_closure_error)} "
            f"| {_e(r.energy_drift)} | {_e(r.energy_balance_residual)} | {_e(r.tip_deviation)} "
            f"| {_e(r.position_deviation)} |"
        )
    return lines


def _front_table(front: Sequence[RowResult]) -> list[str]:
    lines = ["| setting | ms per sim s | RTF | position err m | max closure err m | energy drift |",
             "|---|---|---|---|---|---|"]
    for r in front:
        lines.append(f"| {r.label} | {_ms(r.wall_per_sim_s)} | {_e(r.realtime_factor)} "
                     f"| {_e(r.position_deviation)} | {_e(r.max_closure_error)} | {_e(r.energy_drift)} |")
    return lines


def _tier_table(rec: dict) -> list[str]:
    lines = ["| tier | setting | ms per sim s | CPU ms per sim s | position err m "
             "| max closure err m |", "|---|---|---|---|---|---|"]
    for tier, _ in TIERS:
        b = rec.get(tier)
        if b is None:
            lines.append(f"| {tier} | no row qualifies | | | | |")
        else:
            lines.append(f"| {tier} | {b['label']} | {_ms(b['wall_per_sim_s'])} | "
                         f"{_ms(b.get('cpu_per_sim_s'))} | {_e(b['position_deviation'])} | "
                         f"{_e(b['max_closure_error'])} |")
    return lines


def _overall_table(rec: dict, n_scenes: int) -> list[str]:
    lines = [f"| tier | setting (qualifies on all {n_scenes} scenes) | worst ms per sim s "
             "| worst position err m | worst max closure err m |",
             "|---|---|---|---|---|"]
    for tier, _ in TIERS:
        b = rec.get(tier)
        if b is None:
            lines.append(f"| {tier} | no single setting qualifies on every scene | | | |")
        else:
            lines.append(f"| {tier} | {b['label']} | {_ms(b['worst_wall_per_sim_s'])} "
                         f"| {_e(b['worst_position_deviation'])} | {_e(b['worst_max_closure_error'])} |")
    return lines


def _match_table(match: list[dict]) -> list[str]:
    lines = ["| position err within | vjm: cheapest setting | ms per sim s | MuJoCo: cheapest setting "
             "| ms per sim s | vjm / MuJoCo cost |", "|---|---|---|---|---|---|"]
    for m in match:
        v, j = m["vjm"], m["mujoco"]
        lines.append(
            f"| {m['level']:.0e} m | {v['label'] if v else 'none'} | {_ms(v['wall_per_sim_s']) if v else '–'} "
            f"| {j['label'] if j else 'none'} | {_ms(j['wall_per_sim_s']) if j else '–'} "
            f"| {_e(m['ratio'])} |"
        )
    return lines


def _ref_line(info: dict) -> str:
    if "error" in info:
        return f"Reference failed: {info['error']}"
    chk = info.get("check", {})
    s = (f"Reference: vjm `{info['integrator']}` at rtol {info['rtol']:.0e}, atol {info['atol']:.0e}, "
         f"exact closure, ticks at {info['rate']:g} Hz ({info['wall_time']:.1f} s wall).")
    if chk:
        s += (f" A solve at rtol {chk['rtol']:.0e} differs from it by at most "
              f"{chk['max_position_difference']:.1e} m, so position errors below about that "
              "size are not resolved by the check but the reference is tighter still.")
    return s


def render_report(results: dict, rows: dict[str, list[RowResult]]) -> str:
    """The full markdown report (every row of every scene)."""
    meta = results["meta"]
    m = meta["machine"]
    lines = [
        "# vjm bench report",
        "",
        f"`{meta['command']}` on {meta['date']}: {m['platform']}, {m['cpu_count']} cores "
        f"({m['processor']}), Python {m['python']}, numpy {m['numpy']}, scipy {m['scipy']}, "
        f"MuJoCo {meta['mujoco']['version'] or 'not installed'}; vjm physics kernel "
        f"`{meta.get('kernel') or 'numpy'}`. Single-threaded "
        f"({meta['threads']['blas']}); costs are medians of {meta['repeats']} runs, wall time of the "
        f"physics calls only; total bench time {meta.get('bench_wall_time', 0) / 60:.1f} min.",
        "",
        *_share_text(meta),
    ]
    lines += _mujoco_text(meta)
    lines += _measures_text() + [""]
    if results.get("recommended"):
        lines += ["## Recommended settings", "",
                  *_overall_table(results["recommended"], len(rows)), ""]
    for name, rs in rows.items():
        sm = results["scenes"][name]
        lines += [f"## {name}", "",
                  f"Horizon {sm['horizon']:g} s"
                  + (f" ({sm['horizon_note']})." if sm["horizon_note"] else "."),
                  _ref_line(sm["reference"]), "",
                  f"![{name} Pareto plot]({results['figures'].get(name, '')})", "",
                  "Recommended per tier:", "", *_tier_table(sm["recommended"]), "",
                  "Pareto front (vjm):", "",
                  *_front_table(pareto_front([r for r in rs if r.engine == "vjm"])), ""]
        if sm["matched_accuracy"]:
            lines += ["Pareto front (MuJoCo):", "",
                      *_front_table(pareto_front([r for r in rs if r.engine == "mujoco"])), "",
                      "vjm against MuJoCo at matched accuracy:", "",
                      *_match_table(sm["matched_accuracy"]), ""]
        lines += ["All rows:", "", *_row_table(rs), ""]
        bad = [r for r in rs if r.status in (DIVERGED, FAILED)]
        if bad:
            lines += ["Divergence and error messages:", ""]
            lines += [f"- {r.label}: {r.message}" for r in bad]
            lines.append("")
    if "scaling" in results:
        lines += _scaling_text(results["scaling"]) + [""]
    lines += _long_runs_text(results.get("long_runs", []))
    return "\n".join(lines)


def _mujoco_text(meta: dict) -> list[str]:
    mj = meta["mujoco"]
    if mj.get("skipped"):
        return [f"MuJoCo rows skipped: {mj['skipped']}.", ""]
    out = [f"MuJoCo {mj['version']} rows use the model of `vjm_ros.studies.compare_mujoco` (same geometry, "
           "masses, inertias plus 1e-12 kg m², gravity; closures as equality `connect` "
           "constraints) and are timed the same way (`mj_step` calls only).", ""]
    if mj.get("note"):
        out += [f"**MuJoCo version warning**: {mj['note']}.", ""]
    return out


def _share_text(meta: dict) -> list[str]:
    share = meta.get("cpu_share")
    if share is None:
        return []
    s = (f"The timed physics calls got {100 * share:.0f} % of a core on average (CPU time over wall "
         "time)")
    if share < 0.9:
        s += ("; the machine was shared, so absolute costs are inflated by up to "
              f"{1 / share:.1f}x, while ratios measured in this run are much less affected.")
    else:
        s += "."
    return [s, ""]


def _measures_text() -> list[str]:
    return [
        "Measures: *ms per sim s* is wall milliseconds per simulated second (RTF its inverse); "
        "*max closure err* the largest closure residual (m); *energy drift* "
        "max|(T+V)(t) − (T+V)(0)| / max T; *ledger residual* the largest deviation from the "
        "energy balance (penalty: E = T + V + ½Kp|C|², dE/dt = τ·q̇ − Kv|Ċ|²; MuJoCo rows: "
        "T + V against the actuator work, so the soft constraint's own work counts as residual); "
        "*tip err* and *position err* the largest distance from the exact reference of the chain "
        "tips, and of the tips plus every link end, over all ticks. Rows refused by the stiffness "
        "check (ω_n·h beyond the integrator's bound) or stopped by the divergence guard are kept "
        "and marked.",
    ]


def _scaling_text(scaling: dict) -> list[str]:
    lines = ["## Cost per tick against size", "",
             "Microseconds per 1 kHz tick (one step per tick), median of repeats. `links`: one "
             "chain of N links whose tip runs on a line; `chains`: N two-link chains whose tips "
             "meet at one pin (2(N−1) closure rows).", "", "![scaling](scaling.png)", ""]
    for family in ("links", "chains"):
        table = scaling[family]["table"]
        keys = _scaling_keys(scaling)
        lines += [f"| {family} | n | closure rows | " + " | ".join(keys) + " |",
                  "|---|---|---|" + "---|" * len(keys)]
        for r in table:
            vals = " | ".join("–" if r.get(k) is None else f"{1e6 * r[k]:.0f}" for k in keys)
            lines.append(f"| {r['size']} | {r['n']} | {r['rows']} | {vals} |")
        g = scaling[family]["growth_exponent"]
        lines += ["", "Growth exponent (cost ∝ n^p, sizes ≥ 4): "
                  + ", ".join(f"{k}: {'–' if v is None else f'{v:.2f}'}" for k, v in g.items()), ""]
    return lines


def _long_run_line(lr: dict) -> str:
    s = lr.get("settings", {})
    gains = (f"Kp {s.get('kp')}, Kv {s.get('kv')}" if s.get("kp") is not None
             else "scene gains" if s.get("closure") == "penalty" else
             ("projection" if s.get("projection") else "no projection"))
    e0, e1 = lr["energy_initial"], lr["energy_final"]
    change = f"{100 * (e1 - e0) / e0:+.2g} %" if e0 else "n/a"
    source = " (the `pytest -m slow` test)" if lr.get("source") == "long_run_slow_test.json" else ""
    return (
        f"`{lr['scene']}` for {lr['sim_time']:.0f} simulated seconds with {s.get('integrator')} at "
        f"{s.get('rate', 0):g} Hz x{s.get('substeps')}, {s.get('closure')} closure ({gains})"
        f"{source}, {lr['wall_time'] / 60:.1f} min wall: max closure error "
        f"{_e(lr['max_closure_error'])} m (final {_e(lr['final_closure_error'])} m); energy drift "
        f"{_e(lr['energy_drift'])}, T+V from {e0:.6g} J to {e1:.6g} J ({change}; largest "
        f"|Δ(T+V)| {_e(lr['max_energy_change'])} J"
        + (f", largest rise {_e(lr['max_energy_gain'])} J" if "max_energy_gain" in lr else "")
        + f"); finite: {lr['finite']}" + (f", stopped: {lr['error']}" if lr.get("error") else "")
        + "."
    )


def _long_runs_text(runs: list[dict]) -> list[str]:
    if not runs:
        return []
    lines = ["## Long runs", "", "Energy and closure over long simulated times (samples every "
             f"{runs[0].get('sample_every_ticks', 10)} ticks):", ""]
    lines += [f"- {_long_run_line(lr)}" for lr in runs]
    return lines + [""]


# ---------------------------------------------------------------------------------------- docs
def _closure_stats(rows: dict[str, list[RowResult]], label: str, fixed_only: bool = True):
    vals = [r.max_closure_error for rs in rows.values() for r in rs
            if r.engine == "vjm" and r.closure == label and r.ok and r.max_closure_error is not None
            and (r.step is not None or not fixed_only)]
    pos = [r.position_deviation for rs in rows.values() for r in rs
           if r.engine == "vjm" and r.closure == label and r.ok and r.position_deviation is not None
           and (r.step is not None or not fixed_only)]
    return (min(vals), max(vals), min(pos), max(pos)) if vals and pos else None


def render_docs(results: dict, rows: dict[str, list[RowResult]]) -> str:
    """``docs/accuracy.md``: findings, figures and recommended settings."""
    meta = results["meta"]
    m = meta["machine"]
    n_rows = sum(len(rs) for rs in rows.values())
    n_ref = sum(1 for rs in rows.values() for r in rs if r.status == REFUSED)
    n_div = sum(1 for rs in rows.values() for r in rs if r.status == DIVERGED)
    lines = [
        "# Accuracy and speed",
        "",
        f"This page is written by `{_docs_command(meta, list(rows))}` ({meta['date']}; "
        f"{m['cpu_count']}-core "
        f"{m['processor']} machine, Python {m['python']}, numpy {m['numpy']}, scipy {m['scipy']}, "
        f"MuJoCo {meta['mujoco']['version'] or 'not installed'}; vjm physics kernel "
        f"`{meta.get('kernel') or 'numpy'}`). Run it again to refresh the "
        "numbers; `bench_out/report.md` then lists every row and `bench_out/results.json` holds "
        "them all.",
        "",
        "## What is measured",
        "",
        f"For each scene, {'a reduced' if meta['quick'] else 'the full'} grid of integrator × tick "
        "rate/substeps × closure method (penalty at several gains, raw and as natural frequency "
        "and damping ratio, including the thesis's Kp = 1e5 N/m, Kv = 100 N·s/m; exact closure "
        "with and without projection) runs through the same `Simulator` as `vjm run` and the ROS "
        "node, from the scene's initial state with its default efforts. Accuracy is the largest "
        "distance between the run and a reference solved by vjm with `dop853` at rtol 1e-12 "
        "with exact closure, at the same tick times, over every chain tip and link end "
        "(*position error*). Speed is the wall time of the physics calls per simulated second, "
        f"single core, median of {meta['repeats']} runs; only ratios within one run are "
        "meaningful, the machine is shared.",
        "",
        *_measures_text(),
        "",
        *_mujoco_text(meta),
        *_share_text(meta),
        f"{n_rows} rows in {meta.get('bench_wall_time', 0) / 60:.0f} min; "
        f"{_plural(n_ref, 'row')} refused by the stiffness check and {_plural(n_div, 'row')} "
        "stopped by the divergence guard (all kept in the report).",
        "",
        "Horizons: " + "; ".join(
            f"`{n}` {results['scenes'][n]['horizon']:g} s" for n in rows) + ". "
        + " ".join(f"`{n}`: {results['scenes'][n]['horizon_note']}." for n in rows
                   if results["scenes"][n]["horizon_note"]),
        "",
        "## Recommended settings",
        "",
    ]
    rec = results.get("recommended", {})
    lines += _overall_table(rec, len(rows)) + [""]
    live = rec.get("live 1 kHz")
    if live:
        lines += [
            f"**Live control at 1 kHz**: {live['label']} — the most accurate setting with one "
            f"tick per millisecond whose physics takes at most 1/{LIVE_HEADROOM:g} of real time "
            "(CPU time of one core) on every benched scene: worst position error "
            f"{_e(live['worst_position_deviation'])} m, worst closure error "
            f"{_e(live['worst_max_closure_error'])} m, at most {_ms(live['worst_cpu_per_sim_s'])} ms "
            f"of CPU ({_ms(live['worst_wall_per_sim_s'])} ms of wall time on this shared machine) "
            "per simulated second.", ""]
    else:
        lines += ["**Live control at 1 kHz**: no single setting is both fast enough and valid on "
                  "every scene; see the per-scene tiers below.", ""]
    for tier, _tol in TIERS[1:]:
        b = rec.get(tier)
        if b:
            lines += [f"**Offline, position error within {tier}**: {b['label']} (worst "
                      f"{_e(b['worst_position_deviation'])} m, at most "
                      f"{_ms(b['worst_wall_per_sim_s'])} ms per simulated second).", ""]
        else:
            lines += [f"**Offline, position error within {tier}**: no single setting of the grid "
                      "reaches it on every scene; see the per-scene tables below.", ""]
    lines += ["## Findings", ""]
    lines += _findings(results, rows)
    lines += ["### Settings at 1 kHz, one step per tick", "",
              "What a live node can use, worst case over the benched scenes:", "",
              *live_table(rows), ""]
    for name, rs in rows.items():
        sm = results["scenes"][name]
        fig = results["figures"].get(name)
        lines += [f"## {name}", "",
                  f"Horizon {sm['horizon']:g} s. {_ref_line(sm['reference'])}", ""]
        if fig:
            lines += [f"![{name}: position error against cost](figures/{fig})", ""]
        lines += ["Recommended per tier:", "", *_tier_table(sm["recommended"]), "",
                  "Pareto front (vjm):", "",
                  *_front_table(pareto_front([r for r in rs if r.engine == "vjm"])), ""]
        if sm["matched_accuracy"]:
            lines += ["vjm against MuJoCo at matched accuracy (cheapest row of each within the "
                      "position error):", "", *_match_table(sm["matched_accuracy"]), ""]
    if "scaling" in results:
        sc = _scaling_text(results["scaling"])
        sc = [ln.replace("(scaling.png)", f"(figures/{results['figures'].get('scaling', 'scaling.png')})")
              for ln in sc]
        lines += sc
    lines += _long_runs_text(results.get("long_runs", []))
    lines += _extremes_text()
    return "\n".join(lines) + "\n"


def _docs_command(meta: dict, scenes: list[str]) -> str:
    """The command that rewrites this page, without machine-specific paths."""
    parts = ["vjm bench"]
    default = list(QUICK_SCENES if meta.get("quick") else FULL_SCENES)
    if scenes != default:
        parts += scenes
    if meta.get("quick"):
        parts.append("--quick")
    return " ".join(parts + ["--out bench_out", "--docs docs/accuracy.md"])


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def _worst(rs: Sequence[RowResult], attr: str) -> float | None:
    vals = [getattr(r, attr) for r in rs if getattr(r, attr) is not None]
    return max(vals) if vals else None


def live_table(rows: dict[str, list[RowResult]]) -> list[str]:
    """Every vjm setting at 1 kHz with one step per tick, worst case over the scenes."""
    by: dict[tuple[str, str], list[RowResult]] = {}
    for rs in rows.values():
        for r in rs:
            if r.engine == "vjm" and r.step is not None and r.rate == LIVE_RATE and r.substeps == 1:
                by.setdefault((r.integrator, r.closure), []).append(r)
    lines = ["| integrator | closure | status on the scenes | worst ms per sim s | worst CPU ms "
             "per sim s | worst max closure err m | worst position err m | worst energy drift |",
             "|---|---|---|---|---|---|---|---|"]
    for (integ, closure), rs in by.items():
        states = {}
        for r in rs:
            states[r.status] = states.get(r.status, 0) + 1
        status = ", ".join(f"{v} {k}" for k, v in states.items())
        ran = [r for r in rs if r.ok]
        lines.append(f"| {integ} | {closure} | {status} | {_ms(_worst(ran, 'wall_per_sim_s'))} "
                     f"| {_ms(_worst(ran, 'cpu_per_sim_s'))} | {_e(_worst(ran, 'max_closure_error'))} "
                     f"| {_e(_worst(ran, 'position_deviation'))} | {_e(_worst(ran, 'energy_drift'))} |")
    return lines


def _findings(results: dict, rows: dict[str, list[RowResult]]) -> list[str]:
    out = []
    vjm_rows = [r for rs in rows.values() for r in rs if r.engine == "vjm"]
    thesis = [r for r in vjm_rows if r.closure == THESIS.label and r.ok and r.step is not None]
    exact = [r for r in vjm_rows if r.closure == EXACT.label and r.ok and r.step is not None]
    if thesis:
        khz = [r.max_closure_error for r in thesis if r.rate == LIVE_RATE]
        slow = [r for r in thesis if r.rate < LIVE_RATE]
        rk4 = [r.position_deviation for r in exact if r.integrator == "rk4" and r.rate == LIVE_RATE
               and r.position_deviation is not None]
        text = ("- **The thesis's penalty gains** (Kp = 1e5 N/m, Kv = 100 N·s/m) leave closure "
                f"errors of {_e(min(khz))}–{_e(max(khz))} m at 1 kHz whatever the fixed-step "
                "integrator and substeps: the spring's compliance sets them." if khz else
                "- **The thesis's penalty gains** (Kp = 1e5 N/m, Kv = 100 N·s/m):")
        if slow:
            worst = max(slow, key=lambda r: r.max_closure_error)
            text += (f" At lower rates they grow, up to {_e(worst.max_closure_error)} m "
                     f"({worst.scene}, {worst.label}, position error "
                     f"{_e(worst.position_deviation)} m).")
        if rk4:
            text += (f" Exact closure with rk4 at 1 kHz reaches position errors of "
                     f"{_e(min(rk4))}–{_e(max(rk4))} m on the same scenes.")
        out.append(text)
    for lab in (EXACT.label, EXACT_PROJ.label):
        for integ in ("semi_implicit_euler", "rk4"):
            rs = [r for r in vjm_rows if r.closure == lab and r.integrator == integ and r.ok
                  and r.step is not None and r.rate == LIVE_RATE and r.substeps == 1]
            if rs:
                out.append(f"- **{lab}, {integ} at 1 kHz**: closure error at most "
                           f"{_e(_worst(rs, 'max_closure_error'))} m, position error at most "
                           f"{_e(_worst(rs, 'position_deviation'))} m, energy drift at most "
                           f"{_e(_worst(rs, 'energy_drift'))}, over the scenes.")
    refused: dict[str, int] = {}
    for r in vjm_rows:
        if r.status == REFUSED:
            refused[r.integrator] = refused.get(r.integrator, 0) + 1
    if refused:
        text = ("- **Refused by the stiffness check** (ω_n·h beyond the method's bound, before "
                "running): " + ", ".join(_plural(v, k + " row") for k, v in sorted(refused.items()))
                + ".")
        ie = [r for r in vjm_rows if r.integrator == "implicit_euler" and r.closure != EXACT.label
              and r.step is not None]
        if ie and all(r.status != REFUSED for r in ie):
            text += " `implicit_euler` accepted every penalty gain of the grid at every step."
        out.append(text)
    div = [r for r in vjm_rows if r.status == DIVERGED]
    if div:
        out.append(f"- **Stopped by the divergence guard**: {_plural(len(div), 'row')} that passed "
                   "the stiffness check, e.g. "
                   + "; ".join(f"{r.scene} {r.label} (t = {r.diverged_at:.3g} s)" for r in div[:4])
                   + "."
                   + (" The stiffness check judges the coupled closure modes at the initial "
                      "pose; these stiffened as the pose moved, and the guard caught them."
                      if all(r.closure.startswith("penalty") for r in div) else ""))
    for name in rows:
        match = [m for m in results["scenes"][name].get("matched_accuracy", [])
                 if m["ratio"] is not None]
        if match:
            ratios = ", ".join(f"{m['ratio']:.3g}x within {m['level']:.0e} m" for m in match)
            missing = [m["level"] for m in results["scenes"][name]["matched_accuracy"]
                       if m["mujoco"] is None]
            out.append(f"- **{name} against MuJoCo**, cost of vjm's cheapest setting over MuJoCo's "
                       f"cheapest at matched position error: {ratios}."
                       + (f" No MuJoCo row of the grid reaches {min(missing):.0e} m: its soft "
                          "equality constraints set a floor." if missing else ""))
            lv = results["scenes"][name].get("live", {})
            if lv.get("vjm") and lv.get("mujoco"):
                out.append(
                    f"  At 1 kHz live, the most accurate rows: vjm {lv['vjm']['label']} "
                    f"({_e(lv['vjm']['position_deviation'])} m, {_ms(lv['vjm']['wall_per_sim_s'])} "
                    f"ms per simulated second) and {lv['mujoco']['label']} "
                    f"({_e(lv['mujoco']['position_deviation'])} m, "
                    f"{_ms(lv['mujoco']['wall_per_sim_s'])} ms).")
    if "scaling" in results:
        sc = results["scaling"]
        ratios = []
        for key in _scaling_keys(sc):
            if key.endswith("[numpy kernel]"):
                base = key[: -len(" [numpy kernel]")]
                for family in ("links", "chains"):
                    for r in sc[family]["table"]:
                        if r.get(key) and r.get(base):
                            ratios.append(r[key] / r[base])
        if ratios:
            out.append(f"- **Compiled kernel** (`{results['meta'].get('kernel')}`, the default "
                       f"when numba is installed): {min(ratios):.3g}–{max(ratios):.3g}x less time "
                       "per 1 kHz tick than the numpy reference kernel in the scaling study; every "
                       "timing above uses it.")
        for family, what in (("links", "along one chain"), ("chains", "with the number of chains")):
            g = results["scaling"][family]["growth_exponent"]
            out.append(f"- **Cost per tick {what}** grows roughly as "
                       + ", ".join(f"n^{v:.2f} ({k})" for k, v in g.items() if v is not None)
                       + " for n >= 4 coordinates (see the scaling section).")
    return out + [""]


def _extremes_text() -> list[str]:
    return [
        "## Extremes",
        "",
        "`test/test_extremes.py` asserts what happens at the edges; every case either stays within "
        "the bounds stated there or stops early with a clear error (`StiffnessError` before "
        "running, `DivergenceError` naming the closure, the time and the likely cause), never a "
        "silent NaN:",
        "",
        "- penalty Kp from 1e3 to 1e9 N/m with each fixed-step integrator at 1 kHz: the explicit "
        "methods are refused once ω_n·h passes their bound; `implicit_euler` runs all of them, "
        "with a closure error that falls as Kp grows; with the stiffness check off, the guard stops "
        "the run with a `DivergenceError`;",
        "- steps from 0.1 ms to 20 ms: exact closure stays bounded with every method; penalty "
        "closure at the thesis gains is refused for the explicit methods at large steps;",
        "- singular poses: the five-bar's stretched start, a four-bar within 0.01° of its toggle "
        "pose and a three-chain with one leg stretched keep a full-rank closure Jacobian, and exact "
        "closure stays closed to 1e-7 m; a five-bar whose two stretched legs lie on one line "
        "(the Jacobian loses a rank and the pin is locked) asks for unbounded forces under "
        "gravity: exact closure is stopped by the guard within 20 ms, penalty closure sags by "
        "less than 1 cm;",
        "- mass ratios from 1e-3 to 1e3 (the link carrying the pin) and zero link inertia: exact "
        "closure stays closed to 1e-8 m; penalty gains given as ω_n and ζ scale with the effective "
        "mass, so a light link gets a soft spring (closure error within 2 g Σm / Kp, 8 cm at "
        "1e-3); the thesis's raw gains are refused where the light link makes them too stiff for "
        "the step; a link with neither mass nor inertia at a chain's end is rejected when the "
        "scene loads;",
        "- chains of 1 to 32 links and 1 to 16 chains run with exact closure and with "
        "`implicit_euler` penalty closure; `semi_implicit_euler` with ω_n = 100 rad/s is refused "
        "by the stiffness check on sixteen chains (fifteen hinges pull on one point: the stiffest "
        "coupled closure mode has ω_n = 365 rad/s, ζ = 3.65, against 100 rad/s, ζ = 1 per row); "
        "forced with the check off, it blows up within 50 ms and is stopped by the guard; cost "
        "per tick is in the scaling section;",
        "- one hour of simulated time on `four_bar` with the live setting of the thesis's gains "
        "(`implicit_euler` at 1 kHz, slow test, `pytest -m slow`): finite and closed to 1 mm, "
        "and dissipative (see the long runs above).",
        "",
    ]


# ---------------------------------------------------------------------------------------- CLI
def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="vjm bench",
        description="Speed/accuracy study: integrator x rate/substeps x closure per scene, against "
                    "an exact-closure reference, with MuJoCo side by side when it is installed.",
    )
    p.add_argument("scenes", nargs="*", metavar="SCENE",
                   help=f"built-in names or YAML paths (default: {' '.join(FULL_SCENES)}; "
                        f"--quick: {' '.join(QUICK_SCENES)})")
    p.add_argument("--quick", action="store_true",
                   help="reduced grid, horizons of at most 0.5 s (a few minutes)")
    p.add_argument("--out", type=Path, default=Path("bench_out"),
                   help="output directory (default: bench_out)")
    p.add_argument("--docs", type=Path, metavar="FILE",
                   help="also write the summary page (e.g. docs/accuracy.md) and copy the figures "
                        "to figures/ beside it")
    p.add_argument("--repeats", type=int, default=3, help="timed runs per row (median; default 3)")
    p.add_argument("--horizon", type=float, help="simulated seconds per scene (overrides defaults)")
    p.add_argument("--no-mujoco", action="store_true", help="leave out the MuJoCo rows")
    p.add_argument("--no-scaling", action="store_true", help="leave out the cost-per-tick study")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="extra SimulationSettings field for every vjm row (repeatable)")
    p.add_argument("--long-run", type=float, metavar="SECONDS",
                   help="instead of the grid: run four_bar for SECONDS simulated seconds and write "
                        "OUT/long_run_<setting>.json (included by later reports in OUT)")
    p.add_argument("--long-run-integrator", default=None,
                   help="integrator of --long-run (default: the scene's)")
    p.add_argument("--long-run-closure", choices=["penalty", "exact"], default=None,
                   help="closure of --long-run (default: the scene's)")
    p.add_argument("--long-run-projection", action="store_true",
                   help="exact closure of --long-run with projection")
    p.add_argument("--from-results", type=Path, metavar="FILE",
                   help="run nothing: write the report, figures and --docs again from a "
                        "results.json (adding the long runs found in --out)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    return p


def _parse_set(items: list[str]) -> dict:
    known = {f.name: f for f in fields(SimulationSettings)}
    out = {}
    for item in items:
        if "=" not in item:
            raise ConfigurationError(f"--set: expected KEY=VALUE, found {item!r}")
        key, raw = item.split("=", 1)
        if key not in known:
            raise ConfigurationError(
                f"--set: unknown SimulationSettings field {key!r}; known: {', '.join(known)}"
            )
        try:
            value = json.loads(raw)
        except ValueError:
            value = raw
        out[key] = value
    return out


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``vjm bench``.

    Parameters
    ----------
    argv : list of str, optional
        Arguments after ``bench``.

    Returns
    -------
    int
        0 on success, 2 on bad input.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(argv)
    try:
        if args.repeats < 1:
            raise ConfigurationError(f"--repeats: expected 1 or more, found {args.repeats}")
        if args.horizon is not None and not (math.isfinite(args.horizon) and args.horizon > 0):
            raise ConfigurationError(f"--horizon: expected a positive number, found {args.horizon}")
        extra = _parse_set(args.set)
        if args.long_run is not None:
            return _main_long_run(args)
        if args.from_results is not None:
            opts = BenchOptions(scenes=[], out=args.out, docs=args.docs)
            results = rerender(args.from_results, opts)
            print(f"wrote {opts.out / 'report.md'} and {opts.out / 'results.json'}"
                  + (f"; docs: {opts.docs}" if opts.docs else ""))
            return 0
        names = args.scenes or list(QUICK_SCENES if args.quick else FULL_SCENES)
        for n in names:
            if n not in builtin_scenes() and not Path(n).exists():
                raise SceneError(n, "", f"a built-in scene ({', '.join(builtin_scenes())}) or a "
                                        "YAML file", "no such scene or file")
        opts = BenchOptions(
            scenes=names, quick=args.quick, out=args.out, repeats=args.repeats,
            horizon=args.horizon, mujoco=not args.no_mujoco, scaling=not args.no_scaling,
            docs=args.docs, extra=extra, progress=not args.no_progress,
            command="vjm bench " + " ".join(argv),
        )
        results = run_bench(opts)
    except (SceneError, ConfigurationError) as exc:
        print(f"vjm bench: error: {exc}", file=sys.stderr)
        return 2
    rec = results.get("recommended", {})
    print(f"wrote {opts.out / 'report.md'}, {opts.out / 'results.json'} and "
          f"{len(results.get('figures', {}))} figures"
          + (f"; docs: {opts.docs}" if opts.docs else ""))
    for tier, _ in TIERS:
        b = rec.get(tier)
        print(f"  {tier:11s} {b['label'] if b else 'no single setting qualifies on every scene'}")
    if results["meta"]["mujoco"]["skipped"] and not args.no_mujoco:
        print(f"  MuJoCo rows skipped: {results['meta']['mujoco']['skipped']}")
    return 0


def _main_long_run(args) -> int:
    limit_threads()
    scene = load_scene("four_bar")
    d, g = scene.defaults, scene.gains
    closure = args.long_run_closure or g.get("method", "penalty")
    settings = SimulationSettings(
        integrator=args.long_run_integrator or d.get("integrator", "rk4"),
        rate=d.get("rate", 1000.0), substeps=d.get("substeps", 1), closure=closure,
        projection=bool(args.long_run_projection),
    )
    bar = BenchProgress(args.long_run, enabled=not args.no_progress)
    last = [0.0]

    def tick(t: float) -> None:
        bar.advance(t - last[0], f"four_bar long run, t = {t:.0f} s")
        last[0] = t

    try:
        result = long_run("four_bar", args.long_run, settings, progress=tick)
    finally:
        bar.close()
    args.out.mkdir(parents=True, exist_ok=True)
    tag = f"{settings.integrator}_{settings.closure}" + ("_projection" if settings.projection else "")
    path = args.out / f"long_run_{tag}.json"
    path.write_text(json.dumps(_jsonable(result), indent=1) + "\n")
    print(_long_run_line(result))
    print(f"wrote {path}")
    return 0 if result["error"] is None else 3


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
