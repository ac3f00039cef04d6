"""The closed-chain model for controllers, against independent oracles.

* finite differences of positions along assembled poses (task Jacobian, task bias, A);
* the simulator's own exact-closure forward dynamics: the efforts from inverse dynamics,
  applied, must give back the requested acceleration;
* least squares (numpy's lstsq) for the minimum-norm distribution of redundant actuators.
"""

from __future__ import annotations

import numpy as np
import pytest
from oracle.mechanism import Mechanism

from vjm_ros.control import ClosedChainModel, InfeasibleEffortsError, SingularConfigurationError
from vjm_ros.core.constraints import ExactClosure
from vjm_ros.core.errors import ConfigurationError

SCENES = ["five_bar", "three_chain", "four_bar", "six_bar"]


def state(m: ClosedChainModel, ud=None):
    """An assembled pose near the start and closure-consistent rates."""
    q0, _ = m.model.initial_state()
    u = q0[m.independent] + 0.05
    q = m.assemble(u, guess=q0)
    ud = np.linspace(0.3, -0.4, m.dof) if ud is None else np.asarray(ud, dtype=float)
    return q, m.dependent_velocities(q, ud), ud


def tip(m: ClosedChainModel) -> str:
    return m.model.points[0].name


@pytest.mark.parametrize("name", SCENES)
def test_constraint_jacobian_and_task_jacobian_by_finite_differences(name):
    m = ClosedChainModel.from_scene(name)
    q, _, _ = state(m)
    h = 1e-6  # central differences: truncation ~h^2 = 1e-12, round-off ~1e-16/h = 1e-10
    a = m.constraint_jacobian(q)
    fd = np.column_stack([(m.closure_residual(q + h * e) - m.closure_residual(q - h * e)) / (2 * h)
                          for e in np.eye(m.n)])
    np.testing.assert_allclose(a, fd, atol=1e-8)
    jt = m.task_jacobian(q, tip(m))
    u = q[m.independent]
    cols = []
    for e in np.eye(m.dof):
        plus = m.forward_kinematics(m.assemble(u + h * e, guess=q), tip(m))
        minus = m.forward_kinematics(m.assemble(u - h * e, guess=q), tip(m))
        cols.append((plus - minus) / (2 * h))
    np.testing.assert_allclose(jt, np.column_stack(cols), atol=1e-7)  # assembly to 1e-10 / h


@pytest.mark.parametrize("name", ["five_bar", "three_chain"])
def test_task_bias_is_the_second_derivative_along_a_motion(name):
    """x(t) along u(t) = u0 + ud t + udd t^2/2 (assembled): xdd(0) = J_t udd + task_bias."""
    m = ClosedChainModel.from_scene(name)
    q, qd, ud = state(m)
    udd = np.array([0.7, -0.5])
    u0, h = q[m.independent], 1e-4
    xs = [m.forward_kinematics(m.assemble(u0 + ud * t + 0.5 * udd * t * t, guess=q), tip(m))
          for t in (-h, 0.0, h)]
    xdd = (xs[0] - 2 * xs[1] + xs[2]) / h**2  # error ~h^2 x'''' + 1e-10/h^2 = 1e-8 + 1e-2?
    expected = m.task_jacobian(q, tip(m)) @ udd + m.task_bias(q, qd, tip(m))
    # assembly leaves ~1e-12 m here (tolerance 1e-10 is reached in a few Newton steps to ~1e-15);
    # the bound 1e-4 m/s^2 covers h^2 terms and that noise divided by h^2
    np.testing.assert_allclose(xdd, expected, atol=1e-4)


@pytest.mark.parametrize("name", SCENES)
def test_inverse_dynamics_efforts_give_back_the_acceleration_in_the_simulator(name):
    """The simulator's exact-closure dynamics with these efforts: udd to round-off."""
    m = ClosedChainModel.from_scene(name)
    q, qd, _ = state(m)
    udd = np.linspace(1.5, -0.8, m.dof)
    tau = m.inverse_dynamics(q, qd, udd, respect_limits=False)  # three_chain needs > 200 N m
    # Baumgarte terms vanish on the manifold (C = 0, Cdot = 0 to 1e-10): the oracle is the plain
    # Lagrange-multiplier solution of the open chains plus closures.
    mech = Mechanism(m.model, ExactClosure(alpha=0.0, beta=0.0))
    qdd = mech.accelerations(q, qd, m.selection @ tau)
    np.testing.assert_allclose(qdd[m.independent], udd, atol=1e-7)
    rd = m.reduced_dynamics(q, qd)
    np.testing.assert_allclose(qdd, rd.velocity_map @ udd + rd.acceleration_bias, atol=1e-7)


def test_task_space_inverse_dynamics_gives_the_point_acceleration():
    m = ClosedChainModel.from_scene("five_bar")
    q, qd, _ = state(m)
    xdd = np.array([0.3, -1.2])
    tau = m.inverse_dynamics(q, qd, point=tip(m), xdd=xdd)
    qdd = Mechanism(m.model, ExactClosure(alpha=0.0, beta=0.0)).accelerations(
        q, qd, m.selection @ tau)
    udd = qdd[m.independent]
    got = m.task_jacobian(q, tip(m)) @ udd + m.task_bias(q, qd, tip(m))
    np.testing.assert_allclose(got, xdd, atol=1e-7)


def test_redundant_actuation_minimum_norm_weights_preload_and_limits():
    m = ClosedChainModel.from_scene("three_chain")
    q, qd, _ = state(m)
    udd = np.array([0.5, -0.4])
    rd = m.reduced_dynamics(q, qd)
    w = rd.mass_matrix @ udd + rd.coriolis + rd.gravity
    tau = m.inverse_dynamics(q, qd, udd, respect_limits=False)
    np.testing.assert_allclose(rd.effort_map @ tau, w, atol=1e-9)
    lstsq = np.linalg.lstsq(rd.effort_map, w, rcond=None)[0]  # numpy's minimum-norm solution
    np.testing.assert_allclose(tau, lstsq, atol=1e-9)
    weights = np.array([1.0, 4.0, 1.0])
    tw = m.inverse_dynamics(q, qd, udd, weights=weights, respect_limits=False)
    np.testing.assert_allclose(rd.effort_map @ tw, w, atol=1e-9)
    scaled = np.linalg.lstsq(rd.effort_map / np.sqrt(weights), w, rcond=None)[0] / np.sqrt(weights)
    np.testing.assert_allclose(tw, scaled, atol=1e-9)
    tp = m.inverse_dynamics(q, qd, udd, preload=5.0, respect_limits=False)
    np.testing.assert_allclose(rd.effort_map @ (tp - tau), 0.0, atol=1e-9)  # moves nothing
    assert np.max(np.abs(tp - tau)) == pytest.approx(5.0)
    # limits: the minimum-norm answer is beyond them, but a null-space shift fits them
    from vjm_ros.control import distribute

    # a distribution 30 % lower on the largest effort exists along the null space: limits just
    # above it refuse the minimum-norm answer but admit a shifted one
    z = np.linalg.svd(rd.effort_map)[2][-1]
    k = int(np.argmax(np.abs(tau)))
    shifted = tau - 0.3 * tau[k] / z[k] * z
    limits = np.abs(shifted) * 1.05
    assert np.any(np.abs(tau) > limits)
    fit = distribute(rd.effort_map, w, limits)
    np.testing.assert_allclose(rd.effort_map @ fit, w, atol=1e-9)
    assert np.all(np.abs(fit) <= limits * (1 + 1e-9))
    with pytest.raises(InfeasibleEffortsError, match="beyond the limits"):
        distribute(rd.effort_map, w, np.full(3, 1e-3))


def test_singular_configuration_is_refused():
    """five_bar with both distal links parallel: A_v has rank 1."""
    m = ClosedChainModel.from_scene("five_bar")
    names = m.model.joint_names
    q, _, _ = state(m)
    assert m.singularity_measure(q) > 0.1
    # turn the right elbow until both distal links are parallel: the pin's two columns in A_v
    # (one per elbow, each normal to its distal link) become parallel
    theta_l = m.link_frame(q, "left_distal")[1]
    theta_r = m.link_frame(q, "right_distal")[1]
    q_sing = q.copy()
    q_sing[names.index("right_elbow")] += theta_l - theta_r
    assert m.singularity_measure(q_sing) < 1e-12
    # (q_sing is not assembled: the closure check is relaxed to reach the rank test)
    with pytest.raises(SingularConfigurationError, match="singular configuration"):
        _singular_call(m, q_sing)


def _singular_call(m, q):
    """The velocity map at ``q`` with the closure check relaxed (q need not be assembled)."""
    return ClosedChainModel(m.model, closure_tolerance=np.inf).velocity_map(q)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda m, q, qd: m.forward_kinematics(q, "elbow"), "point: expected a named point"),
        (lambda m, q, qd: m.forward_kinematics(q[:2], "pin"), "q: expected 4 values"),
        (lambda m, q, qd: m.reduced_dynamics(q, np.full(4, np.nan)), "qd: expected finite"),
        (lambda m, q, qd: m.inverse_dynamics(q, qd, [1.0]), "udd: expected 2 values"),
        (lambda m, q, qd: m.reduced_dynamics(q + 0.1, qd), "meets the closures"),
        (lambda m, q, qd: m.forward_kinematics({"knee": 0.0}, "pin"), "q: expected joints"),
        (lambda m, q, qd: m.assemble([np.pi, 0.0]), "u: expected independent coordinates"),
    ],
    ids=["point", "length", "nan", "udd_length", "off_manifold", "name", "unreachable"],
)
def test_bad_arguments_are_named(call, message):
    m = ClosedChainModel.from_scene("five_bar")
    q, qd, _ = state(m)
    with pytest.raises(ConfigurationError, match=message):
        call(m, q, qd)


def test_model_from_the_description_the_node_publishes():
    from vjm_ros.scene import load_scene
    from vjm_ros.scene.description import assembled_scene_yaml

    text = assembled_scene_yaml(load_scene("three_chain"))
    a, b = ClosedChainModel.from_yaml(text), ClosedChainModel.from_scene("three_chain")
    q, qd, _ = state(b)
    np.testing.assert_allclose(a.inverse_dynamics(q, qd, [0.1, 0.2], respect_limits=False),
                               b.inverse_dynamics(q, qd, [0.1, 0.2], respect_limits=False),
                               atol=1e-12)
    with pytest.raises(InfeasibleEffortsError, match="limit of 200"):  # the scene's limits
        b.inverse_dynamics(q, qd, [0.1, 0.2])


def test_vjm_model_prints_what_the_api_computes():
    import json
    import os
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-m", "vjm_ros.app.cli", "model", "three_chain", "--udd", "0.5", "-0.2",
         "--no-limits", "--json"], capture_output=True, text=True, timeout=120,
        env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"))
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    m = ClosedChainModel.from_scene("three_chain")
    q, qd = m.model.initial_state()
    tau = m.inverse_dynamics(q, qd, [0.5, -0.2], respect_limits=False)
    assert list(got["efforts"].values()) == pytest.approx(tau.tolist(), abs=1e-9)
    assert got["dof"] == 2 and got["independent"] == ["c1_base", "c2_base"]
    bad = subprocess.run([sys.executable, "-m", "vjm_ros.app.cli", "model", "five_bar",
                          "--rates", "left_elbow=1"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "--rates: expected independent joints" in bad.stderr


@pytest.mark.parametrize("name", SCENES)
def test_compiled_path_equals_the_numpy_formulation(name):
    """Joint-space inverse dynamics runs compiled; the reduced dynamics, the task Jacobian and
    bias of the package (from the kernels' M, b, A) and those of the numpy oracle
    (test/oracle/closed_model.py) agree to 1e-11: the same formulas summed in another order,
    through solves with A_v and S^T B of condition ~1e1-1e3 on these poses."""
    from oracle import closed_model as oracle

    from vjm_ros.control import distribute

    m = ClosedChainModel.from_scene(name)
    q, qd, _ = state(m)
    udd = np.linspace(0.4, -0.3, m.dof)
    m_r, c_r, g_r, s_map, s, p = oracle.reduced_dynamics(m.model, m.independent, q, qd)
    rd = m.reduced_dynamics(q, qd)
    for got, want in ((rd.mass_matrix, m_r), (rd.coriolis, c_r), (rd.gravity, g_r),
                      (rd.velocity_map, s_map), (rd.acceleration_bias, s), (rd.effort_map, p)):
        np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-11 * max(1.0, np.abs(want).max()))
    w = m_r @ udd + c_r + g_r
    expected = distribute(p, w, np.full(len(m.limits), np.inf))
    got = m.inverse_dynamics(q, qd, udd, respect_limits=False)
    np.testing.assert_allclose(got, expected, rtol=1e-11, atol=1e-11)
    for point in m.model.points:
        x, a_bias, jac = oracle.point_terms(m.model, point.ref.link, point.ref.local, q, qd)
        np.testing.assert_allclose(m.forward_kinematics(q, point.name), x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(m.task_jacobian(q, point.name), jac @ s_map, rtol=1e-11,
                                   atol=1e-11)
        np.testing.assert_allclose(m.task_bias(q, qd, point.name), jac @ s + a_bias,
                                   rtol=1e-11, atol=1e-11 * max(1.0, np.abs(a_bias).max()))
    with pytest.raises(ConfigurationError, match="qd: expected finite"):
        m.inverse_dynamics(q, np.full(m.n, np.nan), udd)
    with pytest.raises(ConfigurationError, match="meets the closures"):
        m.inverse_dynamics(q + 0.05, qd, udd)


@pytest.mark.parametrize("name", ["five_bar", "three_chain", "six_bar"])
def test_reduced_dynamics_balance_the_power_of_the_energies(name):
    """Oracle: d(T + V)/dt along a motion equals ud . (M_r udd + c_r + g_r), the power the
    actuators deliver (B tau . qd = (S^T B tau) . ud). T and V come from the energy functions
    of the open chains (mass-centre velocities and heights), differentiated numerically."""
    from oracle.dynamics import kinetic_energy, potential_energy

    m = ClosedChainModel.from_scene(name)
    q, qd, ud = state(m)
    udd = np.linspace(0.8, -0.6, m.dof)
    u0 = q[m.independent]

    def energy(t):
        qt = m.assemble(u0 + ud * t + 0.5 * udd * t * t, guess=q)
        qdt = m.dependent_velocities(qt, ud + udd * t)
        return kinetic_energy(m.model, qt, qdt) + potential_energy(m.model, qt)

    h = 1e-5  # central difference: h^2 terms ~1e-10 J/s; assembly noise 1e-13 J / h ~1e-8
    power_fd = (energy(h) - energy(-h)) / (2 * h)
    rd = m.reduced_dynamics(q, qd)
    power = ud @ (rd.mass_matrix @ udd + rd.coriolis + rd.gravity)
    assert power_fd == pytest.approx(power, rel=1e-6, abs=1e-6)
