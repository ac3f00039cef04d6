"""The kernels' interface: a packed model shared between threads, a workspace per thread, entry
points named for what they compute, and the closed-chain reduction written once.

Oracles: the :class:`~vjm_ros.core.mechanism.Mechanism`'s own methods (the named entry points are
what they call, so the numbers must be the same bits), the same work done one thread after the
other (threads that share the model and keep their own workspace must not disturb one another:
the same bits), and the defining identities of the velocity map (``A S = 0``, ``S`` the identity
on the independent coordinates, ``A s = -Adot qd``).
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from vjm_ros.control import ClosedChainModel
from vjm_ros.control.compiled import velocity_map
from vjm_ros.core import kernels as K
from vjm_ros.core import layout
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.mechanism import Mechanism
from vjm_ros.scene.loader import load_scene


def _state(model, seed: int):
    rng = np.random.default_rng(seed)
    q, _ = model.initial_state()
    return q + rng.uniform(-0.02, 0.02, model.n), rng.uniform(-1.0, 1.0, model.n)


@pytest.mark.parametrize("closure", ["exact", "penalty"])
def test_named_entry_points_are_what_the_mechanism_computes(closure):
    model = load_scene("five_bar").model
    r = model.n_rows
    method = ExactClosure() if closure == "exact" else PenaltyClosure(np.full(r, 1e5),
                                                                      np.full(r, 1e2))
    mech = Mechanism(model, method)
    assert isinstance(mech.packed, layout.PackedModel)
    data = mech.new_data()
    assert isinstance(data, layout.Data) and data.mm.shape == (model.n, model.n)
    q, qd = _state(model, 1)
    tau = np.linspace(-1.0, 1.0, model.n)
    out, out_b = np.empty(model.n), np.empty(model.n)
    assert K.evaluate(mech.packed, data, q, qd, tau, out) == 0
    np.testing.assert_array_equal(out, mech.accelerations(q, qd, tau))
    np.testing.assert_array_equal(data.jac, mech.closure_jacobian(q))
    assert K.implicit_velocity(mech.packed, data, q, qd, tau, 1e-3, out) == 0
    np.testing.assert_array_equal(out, mech.implicit_penalty_velocity(q, qd, tau, 1e-3))
    assert K.advance(mech.packed, data, K.RK4, q, qd, tau, 1e-3, 5, out, out_b) == 0
    for a, b in zip((out, out_b), mech.advance_fixed(K.RK4, q, qd, tau, 1e-3, 5), strict=True):
        np.testing.assert_array_equal(a, b)
    assert K.project(mech.packed, data, q, qd, 8, 1e-12, out, out_b) == 0
    for a, b in zip((out, out_b), mech.project(q, qd), strict=True):
        np.testing.assert_array_equal(a, b)
    assert K.residual(mech.packed, data, q) == 0
    np.testing.assert_array_equal(data.crow[:, layout.R_RES], mech.terms(q, jacobian=False)[1].residual)


def test_one_packed_model_serves_threads_with_a_workspace_each():
    """Four threads advance different states on one PackedModel at once, each with its own
    Data: each ends where it ends alone."""
    model = load_scene("three_chain").model
    mech = Mechanism(model, ExactClosure())
    packed = mech.packed
    tau = np.zeros(model.n)
    states = [_state(model, seed) for seed in range(4)]

    def run(q, qd, data):
        q_out, qd_out = np.empty(model.n), np.empty(model.n)
        for _ in range(200):  # many calls, so that the threads overlap
            assert K.advance(packed, data, K.RK4, q, qd, tau, 1e-4, 10, q_out, qd_out) == 0
            q, qd = q_out.copy(), qd_out.copy()
        return q, qd

    alone = [run(q, qd, mech.new_data()) for q, qd in states]
    together = [None] * len(states)

    def worker(i):
        together[i] = run(*states[i], mech.new_data())

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(len(states))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)  # a hang guard: the runs take well under a second
    for (qa, qda), (qb, qdb) in zip(alone, together, strict=True):
        np.testing.assert_array_equal(qa, qb)
        np.testing.assert_array_equal(qda, qdb)


@pytest.mark.parametrize("name", ["five_bar", "three_chain", "four_bar"])
def test_velocity_map_is_the_closed_chain_reduction(name):
    """The one definition of ``S`` and ``s``: ``A S = 0``, ``S`` is the identity on the
    independent coordinates, ``A s = -Adot qd``; and it is what ClosedChainModel returns."""
    cm = ClosedChainModel.from_scene(name)
    q0, _ = cm.model.initial_state()
    mech = Mechanism.reader(cm.model)
    for k in range(5):  # along a motion of the independent coordinates
        q = cm.assemble(q0[cm.independent] + 0.02 * k, guess=q0)
        qd = cm.dependent_velocities(q, np.linspace(0.5, -0.5, cm.dof))
        closure = mech.terms(q, qd)[1]
        s_map, s_bias = np.empty((cm.n, cm.dof)), np.empty(cm.n)
        smallest = velocity_map(closure.jacobian, closure.bias, np.array(cm.independent),
                                np.array(cm.dependent), 1e-9, s_map, s_bias)
        a = closure.jacobian
        assert smallest == pytest.approx(np.linalg.svd(a[:, cm.dependent], compute_uv=False)[-1],
                                         rel=1e-12)
        # round-off of a solve with cond(A_v) below 1e3 on these poses: 1e-12 relative to |A| |S|
        scale = np.abs(a).max() * max(1.0, np.abs(s_map).max())
        assert np.abs(a @ s_map).max() <= 1e-12 * scale
        np.testing.assert_array_equal(s_map[cm.independent], np.eye(cm.dof))
        bias_scale = max(1.0, np.abs(closure.bias).max()) * scale
        assert np.abs(a @ s_bias + closure.bias).max() <= 1e-12 * bias_scale
        np.testing.assert_array_equal(cm.velocity_map(q), velocity_map_of(cm, mech, q))
        np.testing.assert_array_equal(cm.reduced_dynamics(q, qd).acceleration_bias, s_bias)


def velocity_map_of(cm, mech, q):
    closure = mech.terms(q, np.zeros(cm.n))[1]
    s_map, s_bias = np.empty((cm.n, cm.dof)), np.empty(cm.n)
    velocity_map(closure.jacobian, closure.bias, np.array(cm.independent), np.array(cm.dependent),
                 1e-9, s_map, s_bias)
    return s_map
