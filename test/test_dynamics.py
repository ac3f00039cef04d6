"""Open-chain dynamics against closed forms and an independent Lagrangian.

Oracles: the pendulum's linear and elliptic-integral periods and its torque balance; the block on
an incline's constant acceleration; for random chains, the Euler-Lagrange equations of ``T`` and
``V`` computed from the chain geometry written out in ``test/chains.py`` (not from the package's
kinematics) with central differences.
"""

from __future__ import annotations

import chains as ch
import numpy as np
import pytest
from oracle.dynamics import (
    bias_forces,
    forward_dynamics,
    inverse_dynamics,
    kinetic_energy,
    mass_matrix,
    potential_energy,
)
from scipy.special import ellipk

from vjm_ros.core.model import PRISMATIC, REVOLUTE, Actuator, Chain, Joint, Link, Model
from vjm_ros.sim.simulator import SimulationSettings, Simulator

G = 9.81

# --------------------------------------------------------------------------- pendulum

PEND_M, PEND_P, PEND_I, PEND_L = 1.5, 0.4, 0.02, 0.5
PEND_IEFF = PEND_I + PEND_M * PEND_P**2  # inertia about the pivot, kg m^2
PEND_W = np.sqrt(PEND_M * G * PEND_P / PEND_IEFF)  # small-angle angular frequency, rad/s
HANG = -np.pi / 2  # the link points straight down


def pendulum(angle: float, rate: float = 0.0, actuated: bool = False) -> Model:
    """One revolute link hinged at the origin; ``angle`` is its absolute angle (ground angle 0)."""
    return Model.build(
        "pendulum",
        (Chain("c", (0.0, 0.0), 0.0, 0.0, (0,)),),
        (Link("bob", 0, PEND_L, PEND_M, PEND_I, (PEND_P, 0.0)),),
        (Joint("pivot", REVOLUTE, angle, 0.0, rate),),
        actuators=(Actuator(0),) if actuated else (),
    )


def simulate_angles(model: Model, duration: float, rate: float = 500.0):
    """Joint angle after every tick of an rk4 run; also the total energy of every tick."""
    sim = Simulator(model, SimulationSettings(integrator="rk4", rate=rate))
    ticks = int(round(duration * rate))
    t = np.zeros(ticks + 1)
    q = np.zeros(ticks + 1)
    energy = np.zeros(ticks + 1)
    s = sim.sample()
    q[0], energy[0] = s.q[0], s.energy[3]
    for k in range(1, ticks + 1):
        sim.advance()
        s = sim.sample()
        t[k], q[k], energy[k] = s.t, s.q[0], s.energy[3]
    return t, q, energy


def crossing_period(t, x):
    """Period from the zero crossings of ``x`` (linear interpolation between ticks)."""
    idx = np.nonzero(np.sign(x[:-1]) * np.sign(x[1:]) < 0)[0]
    tc = t[idx] - x[idx] * (t[idx + 1] - t[idx]) / (x[idx + 1] - x[idx])
    assert len(tc) >= 3
    return 2.0 * (tc[-1] - tc[0]) / (len(tc) - 1)


def test_pendulum_small_angle_period():
    """Oracle: small-angle period 2 pi sqrt((I + m p^2) / (m g p))."""
    amp = 0.01
    period0 = 2 * np.pi / PEND_W
    t, q, energy = simulate_angles(pendulum(HANG + amp), 2.2 * period0)
    period = crossing_period(t, q - HANG)
    # The finite amplitude lengthens the period by amp^2/16 = 6e-6 (series of K); RK4's phase
    # error at omega h = 1e-2 is ~ (omega h)^4/120 ~ 1e-10 per radian; linear interpolation at a
    # zero crossing (where the curvature vanishes) errs by ~ (omega h)^2 h / 12 ~ 2e-8 s. 3e-5
    # leaves room for the first term only.
    assert period == pytest.approx(period0, rel=3e-5)
    assert period > period0  # and the amplitude correction has its sign
    # RK4's energy error on an oscillator is ~ (omega h)^4/120 ~ 1e-10 of the swing energy
    # (measured 2e-11); bound 1e-8.
    swing = PEND_M * G * PEND_P * (1 - np.cos(amp))
    assert np.max(np.abs(energy - energy[0])) < 1e-8 * swing


def test_pendulum_large_amplitude_period_and_energy():
    """Oracle: exact period 4 sqrt(I_eff / (m g p)) K(sin^2(amp/2)), and T, V in closed form."""
    amp = 1.0
    exact = 4.0 / PEND_W * ellipk(np.sin(amp / 2) ** 2)  # scipy's ellipk takes m = k^2
    t, q, energy = simulate_angles(pendulum(HANG + amp), 2.2 * exact)
    # As above without the amplitude term: RK4 phase error (omega h)^4/120 ~ 1e-10 and the
    # interpolation ~ 2e-8 s out of ~1.4 s; 1e-6 is a safe relative bound.
    assert crossing_period(t, q - HANG) == pytest.approx(exact, rel=1e-6)
    # Energy of release V(HANG + amp) = m g p sin(HANG + amp); RK4 at omega h ~ 1e-2 keeps it
    # within ~ (omega h)^4/120 ~ 1e-10 of the swing energy m g p (1 - cos amp) (measured 3e-11);
    # bound 1e-8.
    assert energy[0] == pytest.approx(PEND_M * G * PEND_P * np.sin(HANG + amp), rel=1e-12)
    swing = PEND_M * G * PEND_P * (1 - np.cos(amp))
    assert np.max(np.abs(energy - energy[0])) < 1e-8 * swing


def test_pendulum_energy_closed_form():
    """Oracle: T = (I + m p^2) w^2 / 2 and V = m g p sin(theta) at arbitrary states."""
    model = pendulum(0.0)
    rng = np.random.default_rng(11)
    for _ in range(20):
        th, w = rng.uniform(-np.pi, np.pi), rng.uniform(-5, 5)
        q, qd = np.array([th]), np.array([w])
        # Both are a handful of floating-point operations: agreement to round-off.
        assert kinetic_energy(model, q, qd) == pytest.approx(0.5 * PEND_IEFF * w**2, rel=1e-12)
        assert potential_energy(model, q) == pytest.approx(
            PEND_M * G * PEND_P * np.sin(th), rel=1e-12, abs=1e-12
        )


@pytest.mark.parametrize("tau", [0.0, 1.0, -2.5])
def test_pendulum_effort_acceleration(tau):
    """Oracle: I_eff theta'' = tau - m g p cos(theta) (moment balance about the pivot)."""
    model = pendulum(0.0)
    for th in np.linspace(-3.0, 3.0, 13):
        for w in (0.0, 3.0):
            acc = forward_dynamics(model, np.array([th]), np.array([w]), np.array([tau]))
            expect = (tau - PEND_M * G * PEND_P * np.cos(th)) / PEND_IEFF
            # One division and a few products: round-off only (1e-12 relative, 1e-12 absolute
            # near the zeros of the right side).
            assert acc[0] == pytest.approx(expect, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("tau", [0.5, -1.5, 3.0])
def test_pendulum_static_equilibrium_under_effort(tau):
    """Oracle: static balance sin(psi) = tau / (m g p), psi measured from hanging straight down."""
    psi = np.arcsin(tau / (PEND_M * G * PEND_P))
    model = pendulum(HANG + psi, actuated=True)
    sim = Simulator(model, SimulationSettings(integrator="rk4", rate=1000))
    sim.set_efforts([tau])
    # The residual acceleration at the balance is round-off (~1e-16 * m g p / I_eff ~ 1e-15
    # rad/s^2); the pose is a stable centre, so over 0.5 s the angle may move ~1e-15 rad. 1e-12
    # is far below any real imbalance (a 1e-6 error in tau would move it 1e-7 rad).
    assert abs(sim.sample().qdd[0]) < 1e-12
    for _ in range(500):
        sim.advance()
    assert abs(sim.q[0] - (HANG + psi)) < 1e-12
    assert abs(sim.qd[0]) < 1e-12


# --------------------------------------------------------------------------- block on a slide

def block(theta1: float, slide: float, speed: float) -> Model:
    """A prismatic link sliding along n(theta1) of a ground link at angle theta1."""
    return Model.build(
        "block",
        (Chain("c", (0.1, -0.2), theta1, 0.3, (0,)),),
        (Link("block", 0, 0.4, 2.5, 0.1, (0.15, 0.05)),),
        (Joint("slide", PRISMATIC, 0.7, slide, speed),),
        actuators=(Actuator(0),),
    )


@pytest.mark.parametrize("theta1_deg, force", [(60.0, 0.0), (60.0, 4.0), (135.0, -3.0), (0.0, 2.0)])
def test_block_on_incline(theta1_deg, force):
    """Oracle: a = F/m - g sin(incline), x = x0 + v0 t + a t^2 / 2 (rk4 over 1 s)."""
    theta1 = np.radians(theta1_deg)
    # The slide direction n(theta1) rises by sin(incline) = n_y = cos(theta1) per metre.
    incline = np.arcsin(np.cos(theta1))
    mass = 2.5
    a = force / mass - G * np.sin(incline)
    x0, v0 = 0.25, 0.4
    model = block(theta1, x0, v0)
    acc = forward_dynamics(model, np.array([x0]), np.array([v0]), np.array([force]))
    assert acc[0] == pytest.approx(a, rel=1e-12, abs=1e-12)  # round-off only
    sim = Simulator(model, SimulationSettings(integrator="rk4", rate=1000))
    sim.set_efforts([force])
    worst = 0.0
    for _ in range(1000):
        sim.advance()
        t = sim.t
        worst = max(worst, abs(sim.q[0] - (x0 + v0 * t + 0.5 * a * t * t)))
    # RK4 integrates a constant acceleration exactly; what is left is the round-off of 1000
    # steps on values ~5 m: ~1000 * 1e-15 = 1e-12 m.
    assert worst < 1e-11
    assert sim.qd[0] == pytest.approx(v0 + a * sim.t, abs=1e-11)


# --------------------------------------------------------------------------- random chains

def random_cases(count: int, seed: int):
    """Seeded random models (1-6 links, 1-3 chains) with a random state each."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        n_links = int(rng.integers(1, 7))
        model = ch.random_model(rng, n_links, int(rng.integers(1, 4)))
        q, qd = ch.random_state(rng, model)
        yield model, q, qd


CASES = list(random_cases(24, seed=20240611))
CASE_IDS = [f"n{m.n}-c{len(m.chains)}-{''.join('R' if r else 'P' for r in m.is_revolute)}"
            for m, _, _ in CASES]

# Step of the outer central differences (in q, along qd). T carries the inner velocity
# differences' round-off (~1e-10 J, see chains.VEL_STEP); divided by 2 * OUTER_STEP that is
# ~2e-7, while the truncation ~ OUTER_STEP^2/6 * |T'''| ~ 1e-8 * T. Measured errors on these
# cases are < 2e-7 of max(|b|, 1 N).
OUTER_STEP = 3e-4


def el_bias(model: Model, q, qd):
    """``d/dt dT/dqd - dT/dq + dV/dq`` at ``qdd = 0`` from the independent T and V."""
    n = model.n
    eye = np.eye(n)

    def momentum(qq):
        # T is exactly quadratic in qd, so this unit-step central difference is exact.
        return np.array(
            [(ch.kinetic(model, qq, qd + eye[k]) - ch.kinetic(model, qq, qd - eye[k])) / 2
             for k in range(n)]
        )

    s = OUTER_STEP
    ddt = (momentum(q + s * qd) - momentum(q - s * qd)) / (2 * s)
    dtdq = np.array(
        [(ch.kinetic(model, q + s * eye[k], qd) - ch.kinetic(model, q - s * eye[k], qd)) / (2 * s)
         for k in range(n)]
    )
    dvdq = np.array(
        [(ch.potential(model, q + s * eye[k]) - ch.potential(model, q - s * eye[k])) / (2 * s)
         for k in range(n)]
    )
    return ddt - dtdq + dvdq


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_mass_matrix_symmetric_positive_definite(case):
    """Oracle: M = M^T and every eigenvalue > 0 (all links have mass and inertia)."""
    model, q, _ = case
    m = mass_matrix(model, q)
    # Sums of the same products in another order: round-off ~1e-15 of the largest entry.
    assert np.allclose(m, m.T, rtol=0, atol=1e-13 * np.max(np.abs(m)))
    assert np.linalg.eigvalsh(0.5 * (m + m.T))[0] > 0
    np.linalg.cholesky(m)


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_mass_matrix_is_hessian_of_kinetic_energy(case):
    """Oracle: M_kl = d^2 T / dqd_k dqd_l of the independent T (polarization, exact for a quadratic)."""
    model, q, _ = case
    n = model.n
    eye = np.eye(n)
    hess = np.zeros((n, n))
    for k in range(n):
        for j in range(n):
            hess[k, j] = (
                ch.kinetic(model, q, eye[k] + eye[j])
                - ch.kinetic(model, q, eye[k] - eye[j])
            ) / 2
    m = mass_matrix(model, q)
    # The only error is that of the velocity differences (chains.VEL_STEP): ~1e-10 of the
    # entries (measured < 2e-10); 1e-8 leaves a margin of 50.
    assert np.allclose(hess, m, rtol=0, atol=1e-8 * np.max(np.abs(m)))


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_energies_match_independent_geometry(case):
    """Oracle: T and V from the chain loop of docs/design.md section 1 (test/chains.py)."""
    model, q, qd = case
    # T: velocity-difference error ~1e-10 relative; V: same positions, round-off only.
    assert kinetic_energy(model, q, qd) == pytest.approx(ch.kinetic(model, q, qd), rel=1e-8)
    assert potential_energy(model, q) == pytest.approx(ch.potential(model, q), rel=1e-12, abs=1e-12)
    assert kinetic_energy(model, q, qd) == pytest.approx(0.5 * qd @ mass_matrix(model, q) @ qd,
                                                         rel=1e-12)


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_bias_equals_euler_lagrange_terms(case):
    """Oracle: b = d/dt dT/dqd - dT/dq + dV/dq (at qdd = 0) of the independent T and V."""
    model, q, qd = case
    b = bias_forces(model, q, qd)
    el = el_bias(model, q, qd)
    # Error budget in OUTER_STEP's comment: < 2e-7 measured; bound 2e-6 of max(|b|, 1 N).
    scale = max(float(np.max(np.abs(b))), 1.0)
    assert np.allclose(b, el, rtol=0, atol=2e-6 * scale)


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_bias_velocity_part_is_quadratic(case):
    """Oracle: b(q, s qd) - b(q, 0) = s^2 (b(q, qd) - b(q, 0)) (Coriolis terms are quadratic)."""
    model, q, qd = case
    b0 = bias_forces(model, q, np.zeros(model.n))
    c1 = bias_forces(model, q, qd) - b0
    c3 = bias_forces(model, q, 3.0 * qd) - b0
    scale = max(float(np.max(np.abs(c3))), float(np.max(np.abs(b0))), 1.0)
    assert np.allclose(c3, 9.0 * c1, rtol=0, atol=1e-11 * scale)  # round-off only


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_inverse_dynamics_inverts_forward_dynamics(case):
    """Oracle: inverse_dynamics(forward_dynamics(tau)) == tau and the converse."""
    model, q, qd = case
    rng = np.random.default_rng(model.n)
    tau = rng.uniform(-10, 10, model.n)
    qdd = forward_dynamics(model, q, qd, tau)
    back = inverse_dynamics(model, q, qd, qdd)
    m = mass_matrix(model, q)
    # A linear solve and a product: error ~ cond(M) * eps * (|tau| + |b|).
    cond = np.linalg.cond(m)
    scale = float(np.max(np.abs(tau)) + np.max(np.abs(bias_forces(model, q, qd))))
    assert np.allclose(back, tau, rtol=0, atol=100 * cond * 2.2e-16 * scale)
    acc = rng.uniform(-5, 5, model.n)
    assert np.allclose(
        forward_dynamics(model, q, qd, inverse_dynamics(model, q, qd, acc)),
        acc,
        rtol=0,
        atol=100 * cond * 2.2e-16 * max(float(np.max(np.abs(acc))), 1.0) * 10,
    )


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_rest_without_gravity_or_effort_stays_at_rest(case):
    """Oracle: zero gravity, zero velocity and zero effort give zero acceleration."""
    model, q, _ = case
    still = Model.build("still", model.chains, model.links, model.joints, gravity=(0.0, 0.0))
    acc = forward_dynamics(still, q, np.zeros(model.n), np.zeros(model.n))
    assert np.all(acc == 0.0)  # every term of b is a product with a zero rate or gravity
