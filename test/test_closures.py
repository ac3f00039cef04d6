"""Loop closures: exact and penalty enforcement, forces, stiffness and energy on the built-in
four-bar, and every closure kind (hinge, slider, angle) on random chains.

Oracles: the closure residual measured with the chain geometry written out in ``test/chains.py``;
the Lagrange-multiplier system solved in the test from central-difference ``M``, ``A`` and
``dV/dq``; the penalty law ``F = -(Kp C + Kv Cdot)``; the stability limit of RK4 on the coupled
closure modes; and the energy
ledger of docs/design.md section 2 integrated by the trapezoid rule.
"""

from __future__ import annotations

import chains as ch
import numpy as np
import pytest
from oracle.constraints import ClosureSet
from oracle.dynamics import bias_forces, mass_matrix
from oracle.kinematics import forward_kinematics
from oracle.mechanism import Mechanism

from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.errors import StiffnessError
from vjm_ros.core.model import ANGLE, GROUND, HINGE, SLIDER, Closure, Model, PointRef
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

PIN = np.array([1.0, 0.0])  # ground point of the four-bar's tip pin, m (four_bar.yaml)


@pytest.fixture(scope="module")
def four_bar():
    """The built-in scene, assembled."""
    return load_scene("four_bar")


def tip_residual(model, q):
    """``C = tip - pin`` from the independent chain loop (the rocker is the last link)."""
    rocker = model.link_names.index("rocker")
    return ch.point_on_link(model, q, rocker, (model.links[rocker].length, 0.0)) - PIN


def closure_jacobian(model, q):
    """``A = dC/dq`` by central differences of :func:`tip_residual` (error ~1e-10, JAC_STEP)."""
    return ch.coordinate_jacobian(lambda x: tip_residual(model, x), q, ch.JAC_STEP)


def make_sim(scene, **settings):
    """A simulator of ``scene`` with the scene's gains and the given settings."""
    return Simulator(scene.model, SimulationSettings(**settings), scene.gains)


# --------------------------------------------------------------------------- exact closure


def test_exact_closure_holds_for_ten_seconds(four_bar):
    """Oracle: |C| from the independent geometry stays <= 1e-9 m; T + V is conserved."""
    sim = make_sim(four_bar, closure="exact", integrator="rk4", rate=1000)
    model = four_bar.model
    e0 = sim.sample().energy
    worst, drift, t_max = float(np.linalg.norm(tip_residual(model, sim.q))), 0.0, 0.0
    for k in range(1, 10001):
        sim.advance()
        worst = max(worst, float(np.linalg.norm(tip_residual(model, sim.q))))
        if k % 10 == 0:
            e = sim.sample().energy
            drift = max(drift, abs(e[3] - e0[3]))
            t_max = max(t_max, e[0])
    assert t_max > 1.0  # the linkage swings (about 3.9 J of kinetic energy at most)
    # With Baumgarte alpha = beta = 20 1/s, RK4's local errors (~(omega h)^5 L ~ 1e-12 m per
    # step) are pulled back within ~0.1 s: the residual stays ~1e-10 m (measured 2.2e-10).
    assert worst <= 1e-9
    # The exact closure does no work, so T + V drifts only by RK4 error and the Baumgarte terms
    # acting on a ~1e-10 m residual: measured 7e-9 of max T; bound 1e-6 (docs/design.md energy_drift).
    assert drift < 1e-6 * t_max


def kkt_at_rest(model, q, tau):
    """Accelerations and pin force from ``[M -A^T; A 0] [qdd; lam] = [tau - dV/dq; 0]``.

    At rest ``b = dV/dq`` and ``Adot qd = 0``; ``M``, ``A`` and ``dV/dq`` all come from central
    differences of the independent geometry.
    """
    m = ch.mass_matrix_fd(model, q)
    a = closure_jacobian(model, q)
    dv = ch.potential_gradient_fd(model, q)
    n, r = model.n, a.shape[0]
    kkt = np.block([[m, -a.T], [a, np.zeros((r, r))]])
    sol = np.linalg.solve(kkt, np.concatenate((tau - dv, np.zeros(r))))
    return sol[:n], sol[n:]


@pytest.mark.parametrize("effort", [0.0, 2.0, -5.0])
def test_exact_closure_force_at_rest(four_bar, effort):
    """Oracle: the pin force and accelerations of the multiplier system built in the test."""
    sim = make_sim(four_bar, closure="exact", integrator="rk4", rate=1000)
    sim.set_efforts([effort])
    s = sim.sample()
    model = four_bar.model
    qdd, lam = kkt_at_rest(model, s.q, model.actuator_matrix() @ np.array([effort]))
    # The independent M, A and dV/dq carry ~1e-10 relative difference error, amplified by the
    # conditioning of the KKT matrix (~1e2 here); the Baumgarte term beta^2 C ~ 400 * 2e-16 is
    # negligible. Measured 4e-11; bound 1e-7 relative to the force (~20 N) and accelerations.
    force = s.closure_force[0]
    assert np.allclose(force[:2], lam, rtol=0, atol=1e-7 * np.max(np.abs(lam)))
    assert force[2] == 0.0  # a hinge carries no moment
    assert np.allclose(s.qdd, qdd, rtol=0, atol=1e-7 * max(np.max(np.abs(qdd)), 1.0))
    # The pin force is the rocker tip's reaction: it must hold the tip still, A qdd = 0.
    assert np.max(np.abs(closure_jacobian(model, s.q) @ s.qdd)) < 1e-7 * np.max(np.abs(s.qdd))


def test_exact_closure_generalized_force_identity_in_motion(four_bar):
    """Oracle: M qdd = tau - b + A^T lam and Cddot = -(2 alpha Cdot + beta^2 C) while moving.

    ``A`` and ``Adot qd`` (the second derivative of C along qd) come from central differences of
    the independent tip position; M and b are the package's, verified in test_dynamics.
    """
    sim = make_sim(four_bar, closure="exact", integrator="rk4", rate=1000)
    sim.set_efforts([1.5])
    for _ in range(300):
        sim.advance()
    s = sim.sample()
    model = four_bar.model
    q, qd, qdd = s.q, s.qd, s.qdd
    assert np.max(np.abs(qd)) > 1.0  # really moving
    lam = s.closure_force[0, :2]
    a = closure_jacobian(model, q)
    lhs = mass_matrix(model, q) @ qdd
    rhs = s.effort - bias_forces(model, q, qd) + a.T @ lam
    # A carries ~1e-10 relative error times |lam| ~ 12 N (measured 2e-11 of the generalized
    # force scale); bound 1e-7.
    scale = max(float(np.max(np.abs(lhs))), float(np.max(np.abs(a.T @ lam))))
    assert np.allclose(lhs, rhs, rtol=0, atol=1e-7 * scale)
    # Second central difference of C(q + s qd) at s = 1e-4: truncation s^2 |qd|^4 L / 12 ~ 1e-7,
    # round-off 1e-16 / s^2 ~ 1e-8 (m/s^2), against a velocity-product term of ~5 m/s^2
    # (measured 2e-8 relative); bound 1e-6.
    step = 1e-4
    adot_qd = (
        tip_residual(model, q + step * qd) - 2 * tip_residual(model, q)
        + tip_residual(model, q - step * qd)
    ) / step**2
    method = sim.method
    cddot = a @ qdd + adot_qd
    feedback = -(2 * method.alpha * (a @ qd) + method.beta**2 * tip_residual(model, q))
    assert np.allclose(cddot, feedback, rtol=0, atol=1e-6 * max(np.max(np.abs(adot_qd)), 1.0))
    assert np.max(np.abs(adot_qd)) > 1.0  # the velocity-product term matters here


# --------------------------------------------------------------------------- penalty closure


def link_ends(sim, seconds):
    """Every link's start and end point after every tick, shape (ticks, n, 2, 2)."""
    out = []
    for _ in range(int(round(seconds * sim.settings.rate))):
        sim.advance()
        out.append(sim.sample().segments)
    return np.array(out)


def test_penalty_converges_to_exact_as_stiffness_grows(four_bar):
    """Oracle: the exact-closure run; the penalty deflection ~ force / Kp shrinks ~10x per decade."""
    exact = link_ends(make_sim(four_bar, closure="exact", integrator="rk4", rate=1000), 0.5)
    deviation, residual = [], []
    for kp in (1e4, 1e5, 1e6):
        # The thesis's damping Kv = 100 N s/m; two RK4 substeps keep omega_n h <= 0.47 for the
        # stiffest gain (omega_n ~ 930 rad/s), far inside RK4's stability bound 2.83.
        sim = make_sim(four_bar, closure="penalty", integrator="rk4", rate=1000, substeps=2,
                       kp=kp, kv=100.0)
        ends = link_ends(sim, 0.5)
        deviation.append(float(np.max(np.abs(ends - exact))))
        residual.append(float(np.linalg.norm(tip_residual(four_bar.model, sim.q))))
    # Deviations measured 2.4e-3, 3.0e-4, 3.3e-5 m: the compliance of the springs under the ~20 N
    # pin force, i.e. ~1/Kp. Monotone, at least 5x per decade, and 1e-4 m at Kp = 1e6 (the RK4
    # errors of both runs, ~1e-9 m, do not interfere).
    assert deviation[0] > deviation[1] > deviation[2]
    assert deviation[0] / deviation[1] > 5 and deviation[1] / deviation[2] > 5
    assert deviation[2] < 1e-4
    assert residual[0] > residual[1] > residual[2]


def test_penalty_force_law(four_bar):
    """Oracle: the reported force equals -(Kp C + Kv Cdot) with C, Cdot from the test geometry."""
    kp, kv = 1e5, 100.0
    sim = make_sim(four_bar, closure="penalty", integrator="rk4", rate=1000, kp=kp, kv=kv)
    sim.set_efforts([1.0])
    for _ in range(200):
        sim.advance()
    s = sim.sample()
    model = four_bar.model
    c = tip_residual(model, s.q)
    step = 1e-6  # central difference along qd: error ~ step^2 |qd|^3 L ~ 1e-11 m/s
    cdot = (tip_residual(model, s.q + step * s.qd) - tip_residual(model, s.q - step * s.qd)) / (
        2 * step
    )
    expect = -(kp * c + kv * cdot)
    # Kp * (position round-off 1e-16 m) and Kv * (difference error 1e-10 m/s): ~1e-8 N (measured)
    # against a ~15 N force.
    assert np.allclose(s.closure_force[0, :2], expect, rtol=0, atol=1e-6)
    assert np.linalg.norm(expect) > 1.0
    assert s.energy[2] == pytest.approx(0.5 * kp * float(c @ c), rel=1e-9)
    assert s.dissipation == pytest.approx(kv * float(cdot @ cdot), rel=1e-6)


# --------------------------------------------------------------------------- stiffness


def test_stiff_penalty_refused_for_rk4(four_bar):
    """Oracle: omega_n h = sqrt(1e8 / m_eff) * 1e-3 ~ 9.3 exceeds RK4's bound 2.83: refused."""
    with pytest.raises(StiffnessError) as info:
        make_sim(four_bar, closure="penalty", integrator="rk4", rate=1000, kp=1e8, kv=100.0)
    message = str(info.value)
    assert "tip_pin" in message and "rk4" in message


def test_stiffness_threshold_matches_rk4_bound(four_bar):
    """Oracle: the largest accepted Kp is (2 sqrt(2) / h)^2 / lambda_max(A M^-1 A^T).

    The tip pin's two rows share every link, so the closure error's stiffest mode has
    ``omega_n^2 = Kp lambda_max(G)``, ``G = A M^-1 A^T``, above each row's ``Kp / m_eff`` with
    ``m_eff = 1 / G_ii``. M and A are central differences of the independent geometry; Kv = 0
    makes zeta = 0, where RK4's bound is 2 sqrt(2) exactly.
    """
    model = four_bar.model
    q, _ = model.initial_state()
    m = ch.mass_matrix_fd(model, q)
    a = closure_jacobian(model, q)
    g = a @ np.linalg.solve(m, a.T)
    h = 1e-3
    kp_max = (2 * np.sqrt(2) / h) ** 2 / float(np.linalg.eigvalsh(g)[-1])
    kp_row = (2 * np.sqrt(2) / h) ** 2 / float(np.max(np.diag(g)))
    assert kp_max < 0.9 * kp_row  # the coupled limit is the stricter one (0.87 here)
    # The FD M and A are accurate to ~1e-9; 1 % either side of the limit is unambiguous.
    make_sim(four_bar, closure="penalty", integrator="rk4", rate=1000, kp=0.99 * kp_max, kv=0.0)
    with pytest.raises(StiffnessError):
        make_sim(four_bar, closure="penalty", integrator="rk4", rate=1000, kp=1.01 * kp_max, kv=0.0)


def test_stiff_penalty_runs_with_implicit_euler(four_bar):
    """Oracle: finite state, small |C| and bounded energy over 2 s at Kp = 1e8, 1 kHz."""
    sim = make_sim(four_bar, closure="penalty", integrator="implicit_euler", rate=1000,
                   kp=1e8, kv=100.0)
    model = four_bar.model
    e0 = sim.sample().energy[3]
    worst, e_dev, t_max = 0.0, 0.0, 0.0
    for k in range(1, 2001):
        sim.advance()
        worst = max(worst, float(np.linalg.norm(tip_residual(model, sim.q))))
        if k % 10 == 0:
            e = sim.sample().energy
            assert np.all(np.isfinite(e))
            e_dev = max(e_dev, abs(e[3] - e0))
            t_max = max(t_max, e[0])
    assert np.all(np.isfinite(sim.q)) and np.all(np.isfinite(sim.qd))
    assert t_max > 1.0
    # The static deflection is ~30 N / 1e8 N/m = 3e-7 m; the step linearizes C, leaving the
    # curvature term h^2 |v_tip|^2 / (2 L) ~ 4e-6 m per step (measured max 1.4e-5 m). Bound 1e-4.
    assert worst < 1e-4
    # A first-order method at h = 1 ms on motions of a few rad/s keeps T + V within a few
    # percent of max T (measured 1 %); an instability would grow without bound.
    assert e_dev < 0.05 * t_max


# --------------------------------------------------------------------------- energy ledger


def ledger(sim, seconds):
    """Time, total energy and the right side of the ledger at every tick (including t = 0)."""
    samples = [sim.sample()]
    for _ in range(int(round(seconds * sim.settings.rate))):
        sim.advance()
        samples.append(sim.sample())
    t = np.array([s.t for s in samples])
    energy = np.array([s.energy[3] for s in samples])
    power = np.array([s.power_in - s.dissipation for s in samples])
    dissipated = np.array([s.dissipation for s in samples])
    kinetic = np.array([s.energy[0] for s in samples])
    return t, energy, power, dissipated, kinetic


def trapezoid(t, y):
    """Cumulative trapezoid integral of ``y(t)`` from ``t[0]``."""
    return np.concatenate(([0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))))


def test_penalty_energy_ledger(four_bar):
    """Oracle: E = T + V + sum Kp C^2 / 2 obeys dE/dt = tau . qd - sum Kv Cdot^2 (docs/design.md section 2)."""
    sim = make_sim(four_bar, closure="penalty", integrator="rk4", rate=2000)  # scene Kp, Kv
    sim.set_efforts([1.0])
    t, energy, power, dissipated, kinetic = ledger(sim, 0.5)
    residual = energy - energy[0] - trapezoid(t, power)
    scale = float(np.max(kinetic))
    # The residual is the trapezoid rule's error, Delta^2 / 12 * integral of |P''|: measured
    # 1.0e-6 of max T at Delta = 0.5 ms and 4.1e-6 at 1 ms, the rule's Delta^2. RK4's own energy
    # error is ~1e-9. Bound 2e-5.
    assert np.max(np.abs(residual)) < 2e-5 * scale
    # The damper term is resolved: dropping it (7e-4 of max T here) would break the bound.
    assert trapezoid(t, dissipated)[-1] > 10 * 2e-5 * scale


def test_exact_energy_ledger(four_bar):
    """Oracle: with multipliers d(T + V)/dt = tau . qd (the closure does no work)."""
    sim = make_sim(four_bar, closure="exact", integrator="rk4", rate=1000)
    sim.set_efforts([1.0])
    t, energy, power, dissipated, kinetic = ledger(sim, 0.5)
    assert np.all(dissipated == 0.0)
    residual = energy - energy[0] - trapezoid(t, power)
    # Trapezoid error Delta^2 / 12 * integral of |P''| at Delta = 1 ms: measured 3.7e-6 of max T
    # (9e-7 at 0.5 ms, the rule's Delta^2); bound 4e-5.
    assert np.max(np.abs(residual)) < 4e-5 * float(np.max(kinetic))


# --------------------------------------------------------------------------- every closure kind


def closure_model(seed):
    """Two random chains (5 and 4 links) joined by one closure of every kind (need not hold).

    Eight closure rows on nine coordinates, so that ``A`` has full row rank at a random pose.
    """
    rng = np.random.default_rng(seed)
    base = ch.random_model(rng, 9, 2, sizes=(5, 4))
    first, second = (list(c.links) for c in base.chains)
    a_end, b_end = first[-1], second[-1]
    # an angle closure needs a link that some revolute joint turns
    turned = [i for i in first if base.is_revolute[first[0] : i + 1].any()]

    def local():
        return (float(rng.uniform(-0.5, 1.0)), float(rng.uniform(-0.3, 0.3)))

    def unit():
        ang = rng.uniform(-np.pi, np.pi)
        return (float(np.cos(ang)), float(np.sin(ang)))

    closures = (
        Closure("pin", HINGE, PointRef(a_end, local()), PointRef(b_end, local())),
        Closure("pin_ground", HINGE, PointRef(second[1], local()), PointRef(GROUND, (0.3, -0.2))),
        Closure("rail", SLIDER, PointRef(first[1], local()), PointRef(GROUND, (0.2, 0.5)), unit()),
        Closure("carried_rail", SLIDER, PointRef(b_end, local()), PointRef(a_end, local()), unit()),
        Closure("level", ANGLE, PointRef(turned[0], (0, 0)), PointRef(GROUND, (0, 0)), offset=0.3),
        Closure("parallel", ANGLE, PointRef(b_end, (0, 0)), PointRef(a_end, (0, 0)), offset=-1.1),
    )
    model = Model.build("closures", base.chains, base.links, base.joints, closures)
    q, qd = ch.random_state(rng, model)
    return model, q, qd


def closure_rows(model, q):
    """Residuals of docs/design.md section 2 from the independent geometry, stacked in scene order."""
    _, angles = ch.frames(model, q)
    rows = []
    for c in model.closures:
        if c.kind == HINGE:
            pa = ch.point_on_link(model, q, c.point.link, c.point.local)
            rows.extend(pa - ch.point_on_link(model, q, c.target.link, c.target.local))
        elif c.kind == SLIDER:
            pa = ch.point_on_link(model, q, c.point.link, c.point.local)
            p0 = ch.point_on_link(model, q, c.target.link, c.target.local)
            turn = 0.0 if c.target.link == GROUND else angles[c.target.link]
            dx, dy = c.direction
            d = dx * ch.u(turn) + dy * ch.n(turn)  # the line direction in the world
            rows.append((pa - p0) @ np.array([-d[1], d[0]]))
        else:
            other = 0.0 if c.target.link == GROUND else angles[c.target.link]
            diff = angles[c.point.link] - other - c.offset
            rows.append((diff + np.pi) % (2 * np.pi) - np.pi)
    return np.array(rows)


def row_directions(model, q):
    """World force of a unit multiplier on each row: x, y for hinges, the line normal for
    sliders, a moment for angles."""
    _, angles = ch.frames(model, q)
    out = []
    for c in model.closures:
        if c.kind == HINGE:
            out += [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]
        elif c.kind == SLIDER:
            turn = 0.0 if c.target.link == GROUND else angles[c.target.link]
            d = c.direction[0] * ch.u(turn) + c.direction[1] * ch.n(turn)
            out.append((-d[1], d[0], 0.0))
        else:
            out.append((0.0, 0.0, 1.0))
    return np.array(out)


# Seeds whose closure Jacobian has full row rank (smallest singular value > 0.1; with too many
# prismatic joints some of these closures become structurally redundant).
CLOSURE_SEEDS = [5, 8, 16, 17]


@pytest.mark.parametrize("seed", CLOSURE_SEEDS)
def test_closure_rows_match_independent_geometry(seed):
    """Oracle: C, A, Cdot = A qd and Adot qd by central differences of the residuals of docs/design.md section 2.

    Covers hinges (link-link and link-ground), sliders on a ground line and on a line carried by
    a moving link, and angle closures to ground and between links.
    """
    model, q, qd = closure_model(seed)
    terms = ClosureSet(model).evaluate(forward_kinematics(model, q, qd))
    c = closure_rows(model, q)
    # Same positions by another loop: round-off only.
    assert np.allclose(terms.residual, c, rtol=0, atol=1e-12)
    a = ch.coordinate_jacobian(lambda x: closure_rows(model, x), q, ch.JAC_STEP)
    # Central differences at 1e-5 on ~1 m chains: ~1e-10 (truncation and round-off); bound 1e-8.
    assert np.allclose(terms.jacobian, a, rtol=0, atol=1e-8)
    assert np.allclose(terms.rate, a @ qd, rtol=0, atol=1e-8 * max(np.max(np.abs(qd)), 1.0))
    step = 1e-4
    adot_qd = (
        closure_rows(model, q + step * qd) - 2 * c + closure_rows(model, q - step * qd)
    ) / step**2
    # Second difference: truncation step^2 |qd|^4 L / 12 ~ 1e-7, round-off 1e-16 / step^2 ~ 1e-8
    # (rates up to 2/s, chains of ~4 m); bound 1e-6 of the term's scale.
    assert np.allclose(terms.bias, adot_qd, rtol=0, atol=1e-6 * max(np.max(np.abs(adot_qd)), 1.0))


@pytest.mark.parametrize("seed", CLOSURE_SEEDS)
def test_exact_multipliers_for_every_closure_kind(seed):
    """Oracle: M qdd = tau - b + A^T lam, Cddot = -(2 alpha Cdot + beta^2 C), forces = lam * dir.

    A, Adot qd and the row directions come from the independent geometry; M and b are the
    package's (checked against the Lagrangian in test_dynamics).
    """
    model, q, qd = closure_model(seed)
    method = ExactClosure(alpha=7.0, beta=5.0)
    mech = Mechanism(model, method)
    tau = np.random.default_rng(seed).uniform(-3, 3, model.n)
    ev = mech.evaluate(q, qd, tau)
    a = ch.coordinate_jacobian(lambda x: closure_rows(model, x), q, ch.JAC_STEP)
    # independent rows, so the multipliers are unique (FD noise in A is ~1e-10)
    assert np.linalg.svd(a, compute_uv=False)[-1] > 0.05
    lam = ev.row_force
    lhs = mass_matrix(model, q) @ ev.qdd
    rhs = tau - bias_forces(model, q, qd) + a.T @ lam
    # A is good to ~1e-10 (times |lam|); the solve adds cond * eps. Bound 1e-7 of the scale.
    scale = max(float(np.max(np.abs(lhs))), float(np.max(np.abs(a.T @ lam))), 1.0)
    assert np.allclose(lhs, rhs, rtol=0, atol=1e-7 * scale)
    step = 1e-4
    c = closure_rows(model, q)
    adot_qd = (
        closure_rows(model, q + step * qd) - 2 * c + closure_rows(model, q - step * qd)
    ) / step**2
    cddot = a @ ev.qdd + adot_qd
    feedback = -(2 * method.alpha * (a @ qd) + method.beta**2 * c)
    # Error of the second difference as above (~1e-7 of |Adot qd|) plus A's on |qdd|.
    tol = 1e-6 * max(float(np.max(np.abs(adot_qd))), float(np.max(np.abs(a @ ev.qdd))), 1.0)
    assert np.allclose(cddot, feedback, rtol=0, atol=tol)
    forces = mech.closures.closure_forces(ev.closure, lam)
    expect = np.zeros((len(model.closures), 3))
    np.add.at(expect, mech.closures.row_closure, row_directions(model, q) * lam[:, None])
    assert np.allclose(forces, expect, rtol=0, atol=1e-12 * max(np.max(np.abs(lam)), 1.0))


@pytest.mark.parametrize("seed", CLOSURE_SEEDS)
def test_penalty_generalized_force_for_every_closure_kind(seed):
    """Oracle: M qdd = tau - b + A^T F with F = -(Kp C + Kv A qd), A from the test geometry."""
    model, q, qd = closure_model(seed)
    r = model.n_rows
    kp, kv = np.linspace(50.0, 400.0, r), np.linspace(1.0, 6.0, r)
    mech = Mechanism(model, PenaltyClosure(kp=kp, kv=kv))
    tau = np.random.default_rng(seed).uniform(-3, 3, model.n)
    ev = mech.evaluate(q, qd, tau)
    a = ch.coordinate_jacobian(lambda x: closure_rows(model, x), q, ch.JAC_STEP)
    force = -(kp * closure_rows(model, q) + kv * (a @ qd))
    # F uses A qd (error ~1e-10 * |qd| * Kv) and C (round-off): ~1e-9 N on forces of ~100 N.
    assert np.allclose(ev.row_force, force, rtol=0, atol=1e-7 * max(np.max(np.abs(force)), 1.0))
    lhs = mass_matrix(model, q) @ ev.qdd
    rhs = tau - bias_forces(model, q, qd) + a.T @ force
    scale = max(float(np.max(np.abs(lhs))), float(np.max(np.abs(a.T @ force))), 1.0)
    assert np.allclose(lhs, rhs, rtol=0, atol=1e-7 * scale)


# --------------------------------------------------------------------------- gains and projection


def test_gains_from_natural_frequency(four_bar):
    """Oracle: Kp = m_eff wn^2, Kv = 2 zeta m_eff wn, m_eff = 1 / (A M^-1 A^T)_ii (docs/design.md section 2)."""
    model = four_bar.model
    q, _ = model.initial_state()
    m = ch.mass_matrix_fd(model, q)
    a = closure_jacobian(model, q)
    m_eff = 1.0 / np.diag(a @ np.linalg.solve(m, a.T))
    wn, zeta = 200.0, 0.7
    sim = make_sim(four_bar, closure="penalty", integrator="rk4", rate=1000, omega_n=wn, zeta=zeta)
    # The central-difference M and A are good to ~1e-10 relative.
    assert np.allclose(sim.method.kp, m_eff * wn**2, rtol=1e-8, atol=0)
    assert np.allclose(sim.method.kv, 2 * zeta * m_eff * wn, rtol=1e-8, atol=0)


def test_exact_closure_with_projection(four_bar):
    """Oracle: after every tick C = 0 and A qd = 0 (the independent C and A) to round-off."""
    sim = make_sim(four_bar, closure="exact", integrator="rk4", rate=1000, projection=True)
    sim.set_efforts([2.0])
    model = four_bar.model
    worst_c, worst_v = 0.0, 0.0
    for _ in range(300):
        sim.advance()
        worst_c = max(worst_c, float(np.max(np.abs(tip_residual(model, sim.q)))))
        worst_v = max(worst_v, float(np.max(np.abs(closure_jacobian(model, sim.q) @ sim.qd))))
    assert np.max(np.abs(sim.qd)) > 1.0
    # The position projection iterates to |C| <= 1e-12 m; the velocity projection is exact up
    # to round-off, seen through the central-difference A (~1e-10 relative times |qd| ~ 5).
    assert worst_c <= 1e-11
    assert worst_v <= 1e-8
