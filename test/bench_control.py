"""Cost of one inverse-dynamics call of the closed-chain model, from Python.

Target: at most 20 us on three_chain (3 actuators, 2 degrees of freedom), so that a Python
controller at 1 kHz spends a small share of its tick on the model. Run with
``python -m pytest -m bench test/bench_control.py --benchmark-enable -p no:cacheprovider``.
"""

from __future__ import annotations

import numpy as np
import pytest

from vjm_ros.control import ClosedChainModel

pytestmark = pytest.mark.bench


@pytest.mark.parametrize("scene", ["three_chain", "five_bar"])
def test_inverse_dynamics_call(benchmark, scene):
    m = ClosedChainModel.from_scene(scene)
    q, _ = m.model.initial_state()
    if scene == "five_bar":  # away from the thesis's singular start
        q = m.assemble(q[m.independent] + 0.3, guess=q)
    qd = m.dependent_velocities(q, np.linspace(0.3, -0.2, m.dof))
    udd = np.linspace(0.1, 0.2, m.dof)
    m.inverse_dynamics(q, qd, udd, respect_limits=False)  # compile (or load from the cache)
    benchmark(m.inverse_dynamics, q, qd, udd, respect_limits=False)
    if benchmark.enabled:
        mean = benchmark.stats.stats.mean
        print(f"{scene}: inverse_dynamics {mean * 1e6:.1f} us per call")
        assert mean <= 20e-6
