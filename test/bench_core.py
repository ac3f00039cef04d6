"""Speed of the physics hot path: the numpy reference against the compiled kernel.

Run with ``python -m pytest -m bench test/bench_core.py --benchmark-enable -p no:cacheprovider`` (the
project's pytest options disable benchmarks by default; then each case runs once as a smoke test).
Compare the cases of one group within one run: the machine is shared, so absolute times drift
between runs while ratios hold. ``--benchmark-group-by=group`` (the default here) puts the
reference and the kernel of one operation and scene side by side.

Operations:

* ``accelerations``: one ``accelerations(q, qd, tau)`` call;
* ``rk4_tick``: one 1 kHz control tick of RK4 (four evaluations), through the integrator's
  ``advance`` as the simulator calls it (the kernel side uses the fused integrator, the numpy
  side the oracle's own RK4 steps: the package's integrators run only in the kernel);
* ``simulator_tick``: one ``Simulator.advance()`` (the tick plus the divergence guard). Case
  ``numba_guard`` also reads the guard's closure errors from the kernel
  (:meth:`vjm_ros.core.mechanism.Mechanism.closure_errors`), as the simulator would with a fast
  mechanism; the reference guard evaluates the closures with numpy on every tick.
"""

from __future__ import annotations

import numpy as np
import pytest
from oracle.fixed import RK4 as OracleRK4
from oracle.mechanism import Mechanism

from vjm_ros.core.compiled import HAVE_NUMBA
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.errors import DivergenceError
from vjm_ros.core.integrators import make_integrator
from vjm_ros.core.mechanism import Mechanism as FastMechanism
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

pytestmark = [
    pytest.mark.bench,
    pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed"),
]

SCENES = ("four_bar", "five_bar")
CLOSURES = ("penalty", "exact")
KERNELS = ("numpy", "numba")


def _setup(scene: str, closure: str, kernel: str):
    model = load_scene(scene).model
    r = model.n_rows
    method = (
        PenaltyClosure(np.full(r, 1e5), np.full(r, 100.0))
        if closure == "penalty"
        else ExactClosure(alpha=20.0, beta=20.0)
    )
    mech = FastMechanism(model, method) if kernel == "numba" else Mechanism(model, method)
    q, qd = model.initial_state()
    return mech, q, qd, np.zeros(model.n)


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("closure", CLOSURES)
@pytest.mark.parametrize("scene", SCENES)
def test_accelerations(benchmark, scene, closure, kernel):
    """One ``accelerations`` call at the scene's initial state."""
    mech, q, qd, tau = _setup(scene, closure, kernel)
    benchmark.group = f"accelerations {scene} {closure}"
    qdd = benchmark(mech.accelerations, q, qd, tau)
    assert np.all(np.isfinite(qdd))


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("closure", CLOSURES)
@pytest.mark.parametrize("scene", SCENES)
def test_rk4_tick(benchmark, scene, closure, kernel):
    """One RK4 step of 1 ms through ``Integrator.advance``."""
    mech, q, qd, tau = _setup(scene, closure, kernel)
    if kernel == "numba":
        integrator = make_integrator("rk4")
    else:
        integrator = OracleRK4()
    benchmark.group = f"rk4_tick {scene} {closure}"
    q1, qd1 = benchmark(integrator.advance, mech, 0.0, q, qd, tau, 1e-3, 1)
    assert np.all(np.isfinite(q1)) and np.all(np.isfinite(qd1))


def _kernel_guard(sim: Simulator):
    """The simulator's divergence guard with the closure errors read from the kernel."""

    def guard():
        if not (np.all(np.isfinite(sim.q)) and np.all(np.isfinite(sim.qd))):
            raise DivergenceError(sim.t, "the state is no longer finite", None, "")
        if sim.model.n_rows and sim.divergence_limit:
            err = sim.mechanism.closure_errors(sim.q)
            worst = int(np.argmax(err))
            if err[worst] > sim.divergence_limit:
                raise DivergenceError(sim.t, "closure residual beyond the limit", None, "")

    return guard


@pytest.mark.parametrize("kernel", ("numba", "numba_guard"))
@pytest.mark.parametrize("scene", SCENES)
def test_simulator_tick(benchmark, scene, kernel):
    """One ``Simulator.advance()`` at 1 kHz with RK4 and the scene's penalty gains (the
    simulator runs only on the compiled kernels; the oracle is timed in the rows above)."""
    loaded = load_scene(scene)
    sim = Simulator(loaded.model, SimulationSettings(integrator="rk4"), loaded.gains)
    if kernel == "numba_guard":
        sim._guard = _kernel_guard(sim)
    benchmark.group = f"simulator_tick {scene}"
    benchmark.pedantic(sim.advance, setup=sim.reset, rounds=200, iterations=1)
    assert np.all(np.isfinite(sim.q))
