"""The bench and sweep rows run a scene's plant as vjm run does: actuator dynamics included."""

from __future__ import annotations

import numpy as np

from vjm_ros.scene.loader import builtin_scene_text, parse_scene
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator
from vjm_ros.studies.bench.grid import RowConfig
from vjm_ros.studies.bench.runs import _make_vjm


def test_bench_rows_run_the_scenes_actuator_lag():
    text = builtin_scene_text("pendulum").replace(
        "- {joint: pivot, limit: 20.0}", "- {joint: pivot, limit: 20.0, time_constant: 0.05, effort: 3.0}")
    scene = parse_scene(text)
    assert scene.plant.actuators[0].time_constant == 0.05
    row = _make_vjm(scene, RowConfig("vjm", "rk4", 1000.0, 1, "exact", {}))
    plain = Simulator(scene.model, SimulationSettings(integrator="rk4", rate=1000.0,
                                                      closure="exact"), {}, scene.plant)
    plain.set_efforts(row.efforts)
    ideal = Simulator(scene.model, SimulationSettings(integrator="rk4", rate=1000.0,
                                                      closure="exact"), {})
    ideal.set_efforts(row.efforts)
    for _ in range(100):
        row.advance()
        plain.advance()
        ideal.advance()
    np.testing.assert_array_equal(row.q, plain.q)  # the lag is in the row
    assert abs(row.q[0] - ideal.q[0]) > 1e-4  # and it matters
