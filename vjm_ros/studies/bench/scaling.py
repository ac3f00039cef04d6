"""The scaling study: cost per tick of generated chain and star scenes against their size."""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Sequence

import numpy as np

from vjm_ros.core.errors import (
    VjmError,
)
from vjm_ros.scene.generated import chain_scene, star_scene
from vjm_ros.scene.loader import Scene
from vjm_ros.sim.samples import RUN_BLOCK_TICKS, SampleBlock
from vjm_ros.sim.simulator import SimulationSettings, Simulator
from vjm_ros.studies.bench.grid import (
    MAX_SCALING_TICKS,
    Grid,
)
from vjm_ros.studies.bench.progress import (
    BenchProgress,
)

SCALING_METHODS = (
    ("semi_implicit_euler", {"closure": "penalty", "omega_n": 100.0, "zeta": 1.0}),
    ("implicit_euler", {"closure": "penalty", "kp": 1e5, "kv": 100.0}),
    ("rk4", {"closure": "exact"}),
)
"""Settings timed in the cost-per-tick study (1 kHz, one step per tick)."""


ONE_LINK_TICKS = 4000
"""Ticks per repeat of the one-link comparison of observed ticks with bare steps."""


def tick_cost(scene: Scene, integrator: str, settings: dict, ticks: int, repeats: int) -> float:
    """Median wall time of one 1 kHz tick, s: ticks run and observed in blocks, as ``vjm run``
    runs them (one compiled call per block with the compiled kernel, tick by tick without).

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
        block = SampleBlock(scene.model, RUN_BLOCK_TICKS)
        sim.blocks_compiled()
        sim.advance_block(block, 1)  # warm-up
        t0 = time.perf_counter()
        while sim.ticks <= ticks:
            sim.advance_block(block, min(RUN_BLOCK_TICKS, ticks + 1 - sim.ticks))
        samples.append((time.perf_counter() - t0) / ticks)
    return float(statistics.median(samples))


def timed_ticks(scene: Scene, integrator: str, settings: dict, grid: Grid) -> int:
    """Ticks of each timed repeat of the scaling study: ``grid.scaling_ticks``, or as many as
    ``grid.scaling_seconds`` of wall time take (from one untimed repeat of
    ``grid.scaling_ticks``), at most :data:`~vjm_ros.studies.bench.grid.MAX_SCALING_TICKS`."""
    if grid.scaling_seconds <= 0:
        return grid.scaling_ticks
    cost = tick_cost(scene, integrator, settings, grid.scaling_ticks, 1)
    wanted = math.ceil(grid.scaling_seconds / cost) if cost > 0 else MAX_SCALING_TICKS
    return int(min(max(grid.scaling_ticks, wanted), MAX_SCALING_TICKS))


def bare_step_cost(scene: Scene, integrator: str, settings: dict, ticks: int,
                   repeats: int) -> float:
    """Median wall time of one bare step, s: ``ticks`` steps of the same method at 1 kHz in one
    compiled call (:meth:`~vjm_ros.core.mechanism.Mechanism.advance_fixed`), nothing observed
    or stored, no projection. The arithmetic a tick cannot go below.

    Parameters and returns as :func:`tick_cost`.
    """
    samples = []
    for _ in range(max(repeats, 1)):
        sim = Simulator(scene.model, SimulationSettings(integrator=integrator, rate=1000.0,
                                                        **settings), scene.gains)
        method = sim.integrator.kernel_method
        q, qd, tau = sim.q, sim.qd, sim.tau
        sim.mechanism.advance_fixed(method, q, qd, tau, sim.dt, 1)  # warm-up
        t0 = time.perf_counter()
        sim.mechanism.advance_fixed(method, q, qd, tau, sim.dt, ticks)
        samples.append((time.perf_counter() - t0) / ticks)
    return float(statistics.median(samples))


def _slope(ns: Sequence[float], costs: Sequence[float]) -> float | None:
    pairs = [(math.log(n), math.log(c)) for n, c in zip(ns, costs, strict=True) if n >= 4 and c and c > 0]
    if len(pairs) < 2:
        return None
    x, y = np.array(pairs).T
    return float(np.polyfit(x, y, 1)[0])


def _scaling_methods(extra: dict) -> list[tuple[str, str, dict]]:
    """(key, integrator, settings) of the scaling study, on the compiled kernels."""
    return [(f"{integ} {settings['closure']}", integ, {**settings, **extra})
            for integ, settings in SCALING_METHODS]


def run_scaling(grid: Grid, repeats: int, progress: BenchProgress | None = None,
                extra: dict | None = None) -> dict:
    """Cost per tick against chain length and number of chains.

    Each method of :data:`SCALING_METHODS` is timed on the compiled kernels.

    Returns
    -------
    dict
        ``methods`` (column keys), ``links`` and ``chains`` tables (size, closure rows, seconds
        per tick per method) and the fitted growth exponent of each method for sizes >= 4.
    """
    methods = _scaling_methods(dict(extra or {}))
    out: dict = {"methods": [m[0] for m in methods], "seconds_per_repeat": grid.scaling_seconds}
    for family, sizes, build in (("links", grid.scaling_links, chain_scene),
                                 ("chains", grid.scaling_chains, star_scene)):
        table = []
        for size in sizes:
            scene = build(size)
            row = {"size": size, "n": scene.model.n, "rows": scene.model.n_rows}
            for key, integ, settings in methods:
                try:
                    ticks = timed_ticks(scene, integ, settings, grid)
                    row.setdefault("ticks", {})[key] = ticks
                    row[key] = tick_cost(scene, integ, settings, ticks, repeats)
                except (VjmError, np.linalg.LinAlgError) as exc:
                    row[key] = None
                    row.setdefault("errors", {})[key] = str(exc)
                if progress:
                    progress.advance(scaling_work(scene.model.n, integ, grid, repeats)
                                     / len(methods) * 3,
                                     f"scaling {family} {size}")
            if family == "links" and size == 1:  # enough ticks to time a step of 0.1 us
                ticks = max(grid.scaling_ticks, ONE_LINK_TICKS)
                row["bare"] = {key: bare_step_cost(scene, integ, settings, ticks, repeats)
                               for key, integ, settings in methods}
                row["observed"] = {key: tick_cost(scene, integ, settings, ticks, repeats)
                                   for key, integ, settings in methods}
            table.append(row)
        growth = {key: _slope([r["n"] for r in table], [r.get(key) for r in table])
                  for key, _, _ in methods}
        out[family] = {"table": table, "growth_exponent": growth}
    return out


def _scaling_keys(scaling: dict) -> list[str]:
    return scaling.get("methods") or [f"{i} {s['closure']}" for i, s in SCALING_METHODS]


def scaling_work(n: int, integ: str, grid: Grid, repeats: int) -> float:
    """Rough cost of timing one method on a scene of ``n`` coordinates (for the progress bar)."""
    stages = 4.0 if integ == "rk4" else 1.0
    return stages * (grid.scaling_ticks + 1) * max(repeats, 1) * (1 + n / 8)
