"""The runs of one row: the exact reference, vjm and MuJoCo runs, their errors and timing."""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field

import numpy as np

from vjm_ros.core.errors import (
    ConfigurationError,
    DivergenceError,
    StiffnessError,
    VjmError,
)
from vjm_ros.core.kinematics import link_segments, point_positions
from vjm_ros.core.readers import forward_kinematics
from vjm_ros.scene.loader import Scene
from vjm_ros.sim.samples import RUN_BLOCK_TICKS, SampleBlock
from vjm_ros.sim.simulator import SimulationSettings, Simulator
from vjm_ros.sim.trajectory import Trajectory
from vjm_ros.studies.bench.grid import (
    CHECK_SETTINGS,
    DIVERGED,
    FAILED,
    OK,
    REFERENCE_RATE,
    REFERENCE_SETTINGS,
    REFUSED,
    RowConfig,
    jsonable,
)


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


def _exact_run(scene: Scene, horizon: float, rate: float, opts: dict) -> tuple[np.ndarray, np.ndarray, float]:
    settings = SimulationSettings(closure="exact", rate=rate, **opts)
    sim = _started(scene, Simulator(scene.model, settings, scene.gains, scene.plant))
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
    diverged_at: float | None = None  # simulated s
    wall_per_sim_s: float | None = None  # wall s per simulated s (median of the samples)
    wall_samples: list = field(default_factory=list)
    cpu_per_sim_s: float | None = None  # CPU s per simulated s
    cpu_samples: list = field(default_factory=list)
    realtime_factor: float | None = None  # simulated s per wall s
    steps_per_s: float | None = None  # integrator steps per wall s
    evaluations_per_sim_s: float | None = None  # right-hand sides per simulated s
    max_closure_error: float | None = None  # m
    rms_closure_error: float | None = None  # m
    energy_drift: float | None = None  # of the largest kinetic energy
    energy_balance_residual: float | None = None  # J
    tip_deviation: float | None = None  # m, from the reference run
    position_deviation: float | None = None  # m, tips and link ends
    finite: bool | None = None

    @property
    def ok(self) -> bool:
        """True when the row ran to the horizon."""
        return self.status == OK


def _new_result(scene: str, cfg: RowConfig) -> RowResult:
    return RowResult(scene, cfg.engine, cfg.integrator, cfg.rate, cfg.substeps, cfg.step,
                     cfg.closure, cfg.label(), cfg.key(), jsonable(cfg.settings))


def _make_vjm(scene: Scene, cfg: RowConfig) -> Simulator:
    settings = SimulationSettings(integrator=cfg.integrator, rate=cfg.rate,
                                  substeps=cfg.substeps, **cfg.settings)
    return _started(scene, Simulator(scene.model, settings, scene.gains, scene.plant))


def _started(scene: Scene, sim):
    """``sim`` with the scene's default efforts applied (a simulator of either engine)."""
    if scene.model.actuators:
        sim.set_efforts(np.array([a.effort for a in scene.model.actuators], dtype=float))
    return sim


def run_vjm(scene: Scene, cfg: RowConfig, horizon: float, ref: Reference | None) -> RowResult:
    res = _new_result(scene.name, cfg)
    try:
        warm = _make_vjm(scene, cfg)  # a compiled kernel compiles here, not in the timed loop
        try:
            warm.blocks_compiled()
            warm.advance_block(SampleBlock(scene.model, 1), 1)
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
    clock = _Clock()
    evals0 = sim.mechanism.evaluations
    block = SampleBlock(scene.model, RUN_BLOCK_TICKS)
    try:
        while sim.ticks < ticks:
            first = sim.ticks + 1
            try:
                with clock:
                    sim.advance_block(block, min(RUN_BLOCK_TICKS, ticks - sim.ticks))
            finally:
                traj.extend(block)
                done = len(block)  # the block observed the points and link ends already
                pts[first:first + done] = block.points[:done]
                ends[first:first + done] = block.segments[:done, :, 1]
    except DivergenceError as exc:
        res.status, res.message, res.diverged_at = DIVERGED, str(exc), exc.time
        res.finite = False
        return res
    except (VjmError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
        res.status, res.message = FAILED, f"{type(exc).__name__}: {exc}"
        return res
    evals = sim.mechanism.evaluations - evals0 - ticks  # a sample evaluates once per tick
    summary = traj.summary()
    clock.record(res, horizon, ticks * (cfg.substeps if not cfg.adaptive else 1))
    res.evaluations_per_sim_s = evals / horizon
    for k in ("max_closure_error", "rms_closure_error", "energy_drift", "energy_balance_residual",
              "finite"):
        setattr(res, k, summary[k])
    _deviation(res, ref, cfg.rate, ticks, pts, ends)
    return res


class _Clock:
    """Wall and CPU time (s) spent inside ``with clock:`` blocks, summed."""

    def __init__(self) -> None:
        self.wall = self.cpu = 0.0

    def __enter__(self) -> None:
        self._w, self._c = time.perf_counter(), time.process_time()

    def __exit__(self, *exc) -> None:
        self.wall += time.perf_counter() - self._w
        self.cpu += time.process_time() - self._c

    def record(self, res: RowResult, horizon: float, steps: int) -> None:
        """Store the per-simulated-second costs (s/s) and the step rate (1/s) of ``res``."""
        res.wall_samples = [self.wall / horizon]
        res.cpu_samples = [self.cpu / horizon]
        res.cpu_per_sim_s = self.cpu / horizon
        res.steps_per_s = steps / self.wall if self.wall > 0 else None


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
    block = SampleBlock(scene.model, RUN_BLOCK_TICKS)
    t0, c0 = time.perf_counter(), time.process_time()
    while sim.ticks < ticks:
        sim.advance_block(block, min(RUN_BLOCK_TICKS, ticks - sim.ticks))
    return (time.perf_counter() - t0) / horizon, (time.process_time() - c0) / horizon


def _make_mujoco(scene: Scene, cfg: RowConfig):
    from vjm_ros.studies.compare_mujoco import MujocoSettings, MujocoSimulator

    ms = MujocoSettings(integrator=cfg.integrator, rate=cfg.rate, substeps=cfg.substeps,
                        solref=tuple(cfg.settings["solref"]), solimp=tuple(cfg.settings["solimp"]))
    return _started(scene, MujocoSimulator(scene.model, ms))


def run_mujoco(scene: Scene, cfg: RowConfig, horizon: float, ref: Reference | None) -> RowResult:
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

    clock = _Clock()
    with sim:
        sample(0)
        try:
            for i in range(ticks):
                with clock:
                    sim.step_tick()
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
    clock.record(res, horizon, ticks * cfg.substeps)
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
        # Blocks of ticks in one call, as vjm's rows run (the efforts are held over the run).
        mj, m, d = sim.mj, sim.m, sim.d
        t0, c0 = time.perf_counter(), time.process_time()
        for start in range(0, ticks, RUN_BLOCK_TICKS):
            mj.mj_step(m, d, nstep=min(RUN_BLOCK_TICKS, ticks - start) * sim.substeps)
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
