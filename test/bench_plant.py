"""Cost of the plant keys (actuator dynamics, sensors) per tick, beside the same scene without.

Run with ``python -m pytest -m bench test/bench_plant.py --benchmark-enable -p no:cacheprovider``
(without ``--benchmark-enable`` each case runs once as a smoke test). Compare the cases of one
group within one run (the machine is shared). Scene: the built-in four-bar (rk4, 1 kHz) as it
ships (``plain``), with a 20 ms lag and a 2-tick delay on its actuator (``lag``, a command that
changed: every tick of the block runs the actuators, the lag never settles within it), and with
noisy, quantized, delayed sensors (``sensors``).

* ``block``: ``advance_block`` of 1000 ticks, as ``vjm run`` runs them;
* ``tick``: ``set_efforts`` and ``advance_block`` of one tick, as the node runs them.
"""

from __future__ import annotations

import numpy as np
import pytest

from vjm_ros.core.compiled import HAVE_NUMBA
from vjm_ros.jit import tiers
from vjm_ros.scene.loader import builtin_scene_text, parse_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.simulator import SimulationSettings, Simulator

pytestmark = [
    pytest.mark.bench,
    pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed"),
]

ACTUATOR = "  - {joint: crank_joint, limit: 100.0}"
PLANTS = {
    "plain": "",
    "lag": "  - {joint: crank_joint, limit: 100.0, time_constant: 0.02, delay: 0.002}",
    "sensors": """sensors:
  joint_states:
    position: {noise: 0.01, resolution: 0.001}
    velocity: {noise: 0.1}
    effort: {noise: 0.05}
    delay: 0.002
    seed: 1""",
}


def _simulator(plant: str) -> Simulator:
    text = builtin_scene_text("four_bar")
    assert ACTUATOR in text
    if plant == "lag":
        text = text.replace(ACTUATOR, PLANTS["lag"])
    elif plant == "sensors":
        text = text.replace(ACTUATOR, ACTUATOR + "\n" + PLANTS["sensors"])
    scene = parse_scene(text)
    tiers.compile_first()
    sim = Simulator(scene.model, SimulationSettings(integrator="rk4"), scene.gains, scene.plant)
    sim.blocks_compiled()
    return sim


@pytest.mark.parametrize("plant", list(PLANTS))
def test_block(benchmark, plant):
    sim = _simulator(plant)
    block = SampleBlock(sim.model, 1000)
    command = iter(np.resize([1.0, -1.0], 10_000))

    def setup():
        sim.reset()
        sim.set_efforts([next(command)])

    benchmark.group = "plant block of 1000 ticks (four_bar, rk4)"
    benchmark.pedantic(sim.advance_block, args=(block, 1000), setup=setup, rounds=20)
    assert block.rows == 1000 and np.all(np.isfinite(block.q))


@pytest.mark.parametrize("plant", list(PLANTS))
def test_tick(benchmark, plant):
    sim = _simulator(plant)
    block = SampleBlock(sim.model, 1)
    efforts = np.array([0.5])

    def tick():
        sim.set_efforts(efforts)
        sim.advance_block(block, 1)

    benchmark.group = "plant node tick (four_bar, rk4)"
    benchmark.pedantic(tick, setup=None, rounds=2000, iterations=1, warmup_rounds=100)
    assert np.all(np.isfinite(sim.q))
