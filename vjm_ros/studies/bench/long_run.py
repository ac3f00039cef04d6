"""One long run (an hour of simulated time) and its drift figures."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict

import numpy as np

from vjm_ros.core.errors import (
    DivergenceError,
)
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator
from vjm_ros.studies.bench.grid import (
    jsonable,
)
from vjm_ros.studies.bench.runs import (
    _started,
)

SAMPLE_EVERY = 10
"""Ticks between samples of energy and closure error."""


def long_run(seconds: float, settings: SimulationSettings,
             progress: Callable[[float], None] | None = None) -> dict:
    """Simulate ``four_bar`` for a long time and report its energy drift and closure error.

    Parameters
    ----------
    seconds : float
        Simulated seconds.
    settings : SimulationSettings
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
    scene = load_scene("four_bar")
    sim = _started(scene, Simulator(scene.model, settings, scene.gains, scene.plant))
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
            if i % SAMPLE_EVERY == 0 or i == ticks:
                last = sim.sample()
                tv = float(last.energy[0] + last.energy[1])
                max_t = max(max_t, float(last.energy[0]))
                max_dev = max(max_dev, abs(tv - tv0))
                max_gain = max(max_gain, tv - tv0)
                max_err = max(max_err, last.max_closure_error)
                if progress and i % (100 * SAMPLE_EVERY) == 0:
                    progress(sim.t)
    except DivergenceError as exc:
        error = str(exc)
    wall = time.perf_counter() - t0
    return {
        "scene": scene.name,
        "settings": jsonable(asdict(settings)),
        "sim_time": sim.t,
        "wall_time": wall,
        "sample_every_ticks": SAMPLE_EVERY,
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
