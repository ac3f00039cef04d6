"""A point's singular task Jacobian is detected, at five_bar's start and on the way to it.

Oracle: the five-bar's task Jacobian in closed form. Each leg is a proximal link (length
``a = 0.25 m``, angle ``theta_i``, driven at its base) and a distal link (angle ``phi_i``) to the
shared pin, so the pin velocity ``v = a thetad_i n(theta_i) + b phid_i n(phi_i)`` gives
``u(phi_i) . v = a sin(e_i) thetad_i`` with the elbow angle ``e_i = phi_i - theta_i``: with
``U`` the rows ``u(phi_l), u(phi_r)`` and ``D = diag(a sin e_l, a sin e_r)``,
``J_t = U^-1 D``. At the start both arms are stretched (``e = 0``): ``J_t = 0``, the pin cannot
be accelerated at all, while ``A_v`` is regular (its smallest singular value is 0.75).
"""

from __future__ import annotations

import numpy as np
import pytest
from oracle.mechanism import Mechanism

from vjm_ros.control import ClosedChainModel, SingularConfigurationError
from vjm_ros.control.closed_model import TASK_SINGULAR_TOLERANCE
from vjm_ros.core.constraints import ExactClosure

A = 0.25  # m, five_bar's proximal links


def closed_form(m: ClosedChainModel, q: np.ndarray) -> np.ndarray:
    """``J_t = U^-1 D`` of five_bar's pin (module docstring), shape (2, 2), m/rad."""
    rows, diag = [], []
    for side in ("left", "right"):
        theta = m.link_frame(q, f"{side}_proximal")[1]
        phi = m.link_frame(q, f"{side}_distal")[1]
        rows.append([np.cos(phi), np.sin(phi)])
        diag.append(A * np.sin(phi - theta))
    return np.linalg.solve(np.array(rows), np.diag(diag))


def scale(m: ClosedChainModel, q: np.ndarray) -> float:
    """``|J|_2 |S|_2``, the largest singular value ``J_t`` can have (m/rad)."""
    jac = m._point("left_tip", q)[2]
    return float(np.linalg.norm(jac, 2) * np.linalg.norm(m.velocity_map(q), 2))


@pytest.mark.parametrize("point", ["left_tip", "right_tip"])
@pytest.mark.parametrize("respect_limits", [True, False])
def test_five_bar_start_is_refused_naming_the_point_and_the_rank(point, respect_limits):
    m = ClosedChainModel.from_scene("five_bar")
    q, qd = m.model.initial_state()
    np.testing.assert_allclose(closed_form(m, q), 0.0, atol=1e-17)  # sin(0) after assembly
    # round-off of J S: 1e-16 m/rad measured; the A_v measure stays 0.75 (it missed this pose)
    assert m.singularity_measure(q, point=point) < 1e-15
    assert m.singularity_measure(q) == pytest.approx(0.75)
    with pytest.raises(SingularConfigurationError, match=f"'{point}'.*rank 0"):
        m.inverse_dynamics(q, qd, point=point, xdd=[0.0, -1.0], respect_limits=respect_limits)
    # the joint-space form has no point to refuse: the efforts that hold the start pose
    assert np.all(np.isfinite(m.inverse_dynamics(q, qd, [0.0, 0.0])))


def test_approaching_the_start_the_measure_follows_the_closed_form_until_it_is_refused():
    """Elbows closing as e(t) = 0.3 (1 - t)^3 (stretched at t = 1), with the rates of that motion:
    the measure equals the closed form's smallest singular value all the way; efforts are given
    (and produce the asked pin acceleration in the simulator's dynamics) while it is above
    TASK_SINGULAR_TOLERANCE |J| |S|, refused below."""
    m = ClosedChainModel.from_scene("five_bar")
    elbows = ClosedChainModel(m.model, ["left_elbow", "right_elbow"])
    q = m.model.initial_state()[0]
    mech = Mechanism(m.model, ExactClosure(alpha=0.0, beta=0.0))
    xdd = np.array([0.3, -1.0])
    seen = {"given": 0, "refused": 0}
    for t in np.concatenate((np.linspace(0.0, 0.9, 10), 1.0 - np.logspace(-1.2, -5.0, 12), [1.0])):
        e, edot = 0.3 * (1.0 - t) ** 3, -0.9 * (1.0 - t) ** 2
        q = elbows.assemble([e, -e], guess=q)
        qd = elbows.dependent_velocities(q, [edot, -edot])
        want = closed_form(m, q)
        # J_t to round-off of entries <= |J||S| ~ 2 m/rad
        np.testing.assert_allclose(m.task_jacobian(q, "left_tip"), want, atol=1e-14)
        sigma = np.linalg.svd(want, compute_uv=False)[-1]
        measure = m.singularity_measure(q, point="left_tip")
        assert measure == pytest.approx(sigma, rel=1e-6, abs=1e-15), t
        tol = TASK_SINGULAR_TOLERANCE * scale(m, q)
        if sigma > 10 * tol:
            tau = m.inverse_dynamics(q, qd, point="left_tip", xdd=xdd, respect_limits=False)
            qdd = mech.accelerations(q, qd, m.selection @ tau)
            got = m.task_jacobian(q, "left_tip") @ qdd[m.independent] + m.task_bias(
                q, qd, "left_tip")
            # efforts grow as 1/sigma (to 2e5 N m at sigma = 1.6e-7 m/rad): the solves'
            # round-off in qdd may grow with them, ~1e-16 * |tau| / (kg m^2) (measured: the
            # pin's acceleration to 4e-15 m/s^2 all the way)
            np.testing.assert_allclose(got, xdd, atol=1e-7 + 1e-13 * np.abs(tau).max())
            seen["given"] += 1
        elif sigma < tol / 10:
            with pytest.raises(SingularConfigurationError, match="'left_tip'.*rank [01]"):
                m.inverse_dynamics(q, qd, point="left_tip", xdd=xdd, respect_limits=False)
            seen["refused"] += 1
    assert seen["given"] == 13 and seen["refused"] == 8, seen  # two poses between


def test_singularity_measure_of_a_point_without_two_degrees_of_freedom():
    """four_bar (1 degree of freedom): the measure is |J_t| (the speed of the tip per rad/s of
    the crank), checked by a central difference of the assembled tip position."""
    m = ClosedChainModel.from_scene("four_bar")
    q0, _ = m.model.initial_state()
    q = m.assemble(q0[m.independent] + 0.2, guess=q0)
    h = 1e-6  # central difference: h^2 truncation, assembly noise 1e-10 / h
    u = q[m.independent]
    fd = (m.forward_kinematics(m.assemble(u + h, guess=q), "chain1_tip")
          - m.forward_kinematics(m.assemble(u - h, guess=q), "chain1_tip")) / (2 * h)
    assert m.singularity_measure(q, point="chain1_tip") == pytest.approx(np.linalg.norm(fd),
                                                                         abs=1e-7)
