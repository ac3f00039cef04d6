"""The hub solves (:mod:`vjm_ros.core.hub_linalg`) against the dense ones and the numpy oracle.

Chains whose tips meet at one pin (:func:`vjm_ros.scene.generated.star_scene`) have their
closure rows laid out around the first chain; the kernels then solve ``A M^-1 A^T`` by
Woodbury's identity and ``M + h A^T W A`` by block elimination instead of dense solves.

Tolerances. The hub and the dense solves are both backward stable and differ only in the order
of their sums, so their results differ by about ``eps * kappa`` with ``kappa`` the condition
number of the solve (as between the kernels and the oracle, ``test/test_fast.py``): the check is
``max |hub - dense| <= max(1e-12, 4 eps kappa) * max |dense|``. At the poses used here
``kappa`` stays below 1e4 (asserted), so the bound is 1e-12, against differences measured at
~1e-14. Where the hub solve refuses (a stretched leg) the dense solve runs unchanged, and the
results are equal to the last bit.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from oracle.mechanism import Mechanism as OracleMechanism

from vjm_ros.core import hub_linalg, kernels, layout, pipeline, small_linalg
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.mechanism import Mechanism
from vjm_ros.core.packing import HUB_MIN_GROUPS, chain_blocks, closure_layout
from vjm_ros.scene.generated import star_scene
from vjm_ros.scene.loader import builtin_scenes, load_scene

pytest.importorskip("numba")

RTOL = 1e-12
EPS = float(np.finfo(float).eps)
KAPPA_MAX = 1e4


def _tol(kappa: float) -> float:
    return max(RTOL, 4.0 * EPS * kappa)


def _close(value, ref, kappa):
    scale = max(float(np.max(np.abs(ref))), 1e-300)
    err = float(np.max(np.abs(np.asarray(value) - np.asarray(ref))))
    assert err <= _tol(kappa) * scale, f"max error {err:.3g} vs scale {scale:.3g}"


def _pair(model, method):
    """The same mechanism twice: with the hub layout (forced, whatever the number of chains)
    and with the dense solves."""
    blocks = chain_blocks(model)
    hub, dense = Mechanism(model, method), Mechanism(model, method)
    hub._data = layout.make_data(hub.packed, closure_layout(model, blocks, min_groups=1))
    dense._data = layout.make_data(dense.packed)
    assert hub._data.layout[model.n_rows, 0] >= 0
    # the compiled copies that hold the hub solves (the plain ones solve densely)
    hub._step, hub._advance_ticks = kernels.step_with_hub, pipeline.advance_ticks_with_hub
    dense._step, dense._advance_ticks = kernels.step, pipeline.advance_ticks
    return hub, dense


def test_a_mechanism_takes_the_copy_with_the_hub_solves_only_with_a_hub_layout():
    """Mechanisms with a hub layout (four chains or more on one pin) run the compiled copies with
    the hub solves; the others the plain ones, which compile none of that code."""
    star = Mechanism(star_scene(6).model, ExactClosure())
    assert star.entry_points[0] is kernels.step_with_hub
    assert star.entry_points[1] is pipeline.advance_ticks_with_hub
    for name in ("four_bar", "three_chain"):
        mech = Mechanism(load_scene(name).model, ExactClosure())
        assert mech.entry_points[0] is kernels.step
        assert mech.entry_points[1] is pipeline.advance_ticks


def _hub_taken(model, q, rcond=1e-10):
    """Whether :func:`hub_linalg.hub_correction` solves at ``q`` (True) or refuses (False)."""
    dyn, closure = Mechanism.reader(model).terms(q)
    packed = Mechanism.reader(model).packed
    blocks = packed.blocks
    n, r = model.n, model.n_rows
    data = layout.make_data(packed, closure_layout(model, blocks, min_groups=1))
    lu, piv, minv_at, g, v, vec = data.lu, data.piv, data.minv_at, data.g, data.v, data.vec
    lu[:] = dyn.mass_matrix
    assert small_linalg.lu_factor_blocks(lu, piv, blocks) == 0
    c = np.linspace(-1.0, 1.0, r)
    return hub_linalg.hub_correction(lu, piv, np.ascontiguousarray(closure.jacobian), c, rcond,
                                     np.empty(n), minv_at, g, v, vec, blocks, data.layout)


def _kappa_exact(model, q):
    """``cond(M) cond(A M^-1 A^T)`` at ``q`` (the exact closure's solve)."""
    dyn, closure = Mechanism.reader(model).terms(q)
    m, a = dyn.mass_matrix, closure.jacobian
    w = np.linalg.eigvalsh(a @ np.linalg.solve(m, a.T))
    return float(np.linalg.cond(m) * w[-1] / w[0])


def _state(model, seed):
    rng = np.random.default_rng(seed)
    q, _ = model.initial_state()
    return q, rng.uniform(-2.0, 2.0, model.n), rng.normal(0.0, 5.0, model.n)


def test_built_in_scenes_keep_the_dense_solves():
    """No built-in scene has enough chains around one for the hub layout: their numbers are
    those of the dense solves, bit for bit."""
    for name in builtin_scenes():
        model = load_scene(name).model
        assert closure_layout(model, chain_blocks(model))[model.n_rows, 0] == -1, name


def test_star_layout():
    """Chains meeting at one pin: the first chain is the hub, one group of two rows per other
    chain; below HUB_MIN_GROUPS other chains only when asked for."""
    for chains in (2, HUB_MIN_GROUPS, HUB_MIN_GROUPS + 1, 16):
        model = star_scene(chains).model
        blocks = chain_blocks(model)
        r = model.n_rows
        lay = closure_layout(model, blocks)
        assert lay[r, 0] == (0 if chains - 1 >= HUB_MIN_GROUPS else -1)
        forced = closure_layout(model, blocks, min_groups=1)
        assert list(forced[r, :2]) == [0, chains - 1]
        assert list(forced[r, 2:chains + 2]) == list(range(0, r + 1, 2))
        assert list(forced[:r, hub_linalg.H_OTHER]) == [1 + i // 2 for i in range(r)]
        assert list(forced[:r, hub_linalg.H_HUB]) == [0] * r


@pytest.mark.parametrize("chains", [2, 3, 4, 8, 16])
def test_hub_solves_equal_the_dense_ones(chains):
    """Accelerations with exact closures, the penalty-implicit velocity and the projection:
    the hub solves against the dense ones and against the numpy oracle."""
    model = star_scene(chains).model
    q, qd, tau = _state(model, chains)
    kappa = _kappa_exact(model, q)
    assert kappa < KAPPA_MAX
    assert _hub_taken(model, q)
    exact = ExactClosure(alpha=20.0, beta=15.0)
    hub, dense = _pair(model, exact)
    ref = dense.accelerations(q, qd, tau)
    _close(hub.accelerations(q, qd, tau), ref, kappa)
    _close(hub.accelerations(q, qd, tau), OracleMechanism(model, exact).accelerations(q, qd, tau),
           kappa)
    moved = q + 1e-3 * np.sin(np.arange(model.n))  # off the closure manifold
    for got, want in zip(hub.project(moved, qd), dense.project(moved, qd), strict=True):
        _close(got, want, kappa)
    penalty = PenaltyClosure(np.full(model.n_rows, 1e5), np.full(model.n_rows, 100.0))
    hub, dense = _pair(model, penalty)
    v_ref = dense.implicit_penalty_velocity(q, qd, tau, 1e-3)
    _close(hub.implicit_penalty_velocity(q, qd, tau, 1e-3), v_ref, kappa)
    _close(hub.implicit_penalty_velocity(q, qd, tau, 1e-3),
           OracleMechanism(model, penalty).implicit_penalty_velocity(q, qd, tau, 1e-3), kappa)
    for op in (kernels.RK4, kernels.IMPLICIT_EULER):
        method = exact if op == kernels.RK4 else penalty
        hub, dense = _pair(model, method)
        for got, want in zip(hub.advance_fixed(op, q, qd, tau, 1e-3, 20),
                             dense.advance_fixed(op, q, qd, tau, 1e-3, 20), strict=True):
            _close(got, want, kappa)


def _stretched(model, chain):
    """The star's state with the elbow of ``chain`` straight (its leg stretched)."""
    q, _ = model.initial_state()
    q = q.copy()
    q[2 * chain + 1] = 0.0
    return q


@pytest.mark.parametrize("chains", [3, 8])
def test_a_stretched_leg_falls_back_to_the_dense_solve(chains):
    """A stretched leg besides the hub makes its own ``J M^-1 J^T`` singular while the whole
    ``A M^-1 A^T`` keeps full rank: the hub solve refuses and the dense solve gives today's
    numbers, to the last bit."""
    model = star_scene(chains).model
    q = _stretched(model, chains - 1)
    dyn, closure = Mechanism.reader(model).terms(q)
    m, a = dyn.mass_matrix, closure.jacobian
    w = np.linalg.eigvalsh(a @ np.linalg.solve(m, a.T))
    assert w[0] > 1e-6 * w[-1]  # full rank
    assert not _hub_taken(model, q)
    _, qd, tau = _state(model, chains)
    hub, dense = _pair(model, ExactClosure())
    assert np.array_equal(hub.accelerations(q, qd, tau), dense.accelerations(q, qd, tau))
    assert _hub_taken(model, _stretched(model, 0))  # the hub's own leg stretched: no matter
    # the implicit step's blocks M_b + h J^T W J stay regular there: the hub solve, to round-off
    kp, kv, h = np.full(model.n_rows, 1e5), np.full(model.n_rows, 100.0), 1e-3
    hub, dense = _pair(model, PenaltyClosure(kp, kv))
    kappa = float(np.linalg.cond(m + h * (a.T * (h * kp + kv)) @ a))
    _close(hub.implicit_penalty_velocity(q, qd, tau, h),
           dense.implicit_penalty_velocity(q, qd, tau, h), kappa)


def test_five_bar_start_falls_back_to_the_dense_solve():
    """The five-bar starts with both legs stretched; laid out around its first chain, the hub
    solve refuses and the numbers are those of the dense solve."""
    model = load_scene("five_bar").model
    q, qd = model.initial_state()
    assert not _hub_taken(model, q)
    hub, dense = _pair(model, ExactClosure())
    tau = np.ones(model.n)
    assert np.array_equal(hub.accelerations(q, qd, tau), dense.accelerations(q, qd, tau))


_NO_ALLOCATION = """
from numba.core.runtime import rtsys
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.scene.generated import star_scene
sc = star_scene(6)
for integ, closure in (("rk4", "exact"), ("implicit_euler", "penalty")):
    sim = Simulator(sc.model, SimulationSettings(integrator=integ, closure=closure), sc.gains)
    assert sim.mechanism.new_data().layout[sc.model.n_rows, 0] == 0
    big = SampleBlock(sc.model, 200)
    sim.blocks_compiled()
    sim.advance_block(big, 200)
    before = rtsys.get_allocation_stats()
    for _ in range(3):
        sim.advance_block(big, 200)
    after = rtsys.get_allocation_stats()
    print(integ, after.alloc - before.alloc, after.mi_alloc - before.mi_alloc)
"""


def test_hub_solves_allocate_nothing():
    """The hub solves create no arrays either (numba's counters, as in test_pipeline.py)."""
    env = dict(os.environ, NUMBA_NRT_STATS="1")
    out = subprocess.run([sys.executable, "-c", _NO_ALLOCATION], env=env, capture_output=True,
                         text=True, timeout=300, check=True).stdout.split("\n")
    rows = [line.split() for line in out if line.strip()]
    assert [r[0] for r in rows] == ["rk4", "implicit_euler"]
    assert all(r[1:] == ["0", "0"] for r in rows), rows
