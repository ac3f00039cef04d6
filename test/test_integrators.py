"""Fixed-step integrators: energy conservation, observed orders, stability bounds, registry.

Oracles: conservation of T + V on open chains (no closures, no efforts); the observed order
log2(e(h) / e(h/2)) against a much finer RK4 reference; the closed-form stability limits of each
method on the oscillator x'' + 2 zeta x' + x = 0.
"""

from __future__ import annotations

import chains as ch
import numpy as np
import pytest
from oracle.fixed import INTEGRATORS as ORACLE_STEPS
from oracle.fixed import ButcherTableau
from oracle.mechanism import Mechanism

from vjm_ros.core.compiled import make_mechanism
from vjm_ros.core.constraints import PenaltyClosure
from vjm_ros.core.integrators import FIXED_STEP, INTEGRATORS, make_integrator
from vjm_ros.core.model import (
    GROUND,
    PRISMATIC,
    SLIDER,
    Actuator,
    Chain,
    Closure,
    Joint,
    Link,
    Model,
    PointRef,
)
from vjm_ros.sim.simulator import SimulationSettings, Simulator

# --------------------------------------------------------------------------- energy


@pytest.mark.parametrize(
    "seed, n_links, n_chains, gravity, p_revolute, substeps",
    [
        # a chaotic 4-link pendulum in gravity (bounded motion, swings up to ~13 rad/s), h = 1 ms
        (3, 4, 1, (0.0, -9.81), 1.0, 50),
        # revolute and prismatic joints on two chains without gravity (sliding and turning,
        # rates ~2 rad/s), h = 2 ms
        (4, 5, 2, (0.0, 0.0), 0.5, 25),
    ],
)
def test_open_chain_conserves_energy(seed, n_links, n_chains, gravity, p_revolute, substeps):
    """Oracle: T + V is constant on open chains without efforts (rk4, small step, 5 s)."""
    rng = np.random.default_rng(seed)
    model = ch.random_model(rng, n_links, n_chains, gravity=gravity, p_revolute=p_revolute)
    sim = Simulator(model, SimulationSettings(integrator="rk4", rate=20.0, substeps=substeps))
    e0 = sim.sample().energy
    drift, t_max = 0.0, e0[0]
    for _ in range(100):
        sim.advance()
        e = sim.sample().energy
        drift = max(drift, abs(e[3] - e0[3]))
        t_max = max(t_max, e[0])
    assert t_max > 1.0  # the chain does move
    # RK4's energy error grows like C (omega h)^4 per unit time: omega h <= ~1.3e-2 here gives
    # ~1e-8 of the kinetic energy scale over 5 s at most (measured 5e-10 for the pendulum chain,
    # 1e-11 for the other). Bound: 1e-7 of max T.
    assert drift < 1e-7 * t_max


# --------------------------------------------------------------------------- orders


def order_model():
    """A fixed 3-link chain: revolute, prismatic, revolute, in gravity, with initial rates."""
    return ch.random_model(np.random.default_rng(3), 3, 1)


def final_state(model, name, steps, duration=1.0, oracle=False):
    """State after ``duration`` with ``steps`` equal steps of the method (one control tick): the
    package's compiled ticks, or the numpy oracle's steps on the oracle's mechanism."""
    q, qd = model.initial_state()
    method = PenaltyClosure(np.zeros(0), np.zeros(0))
    if oracle:
        mech, integ = Mechanism(model, method), ORACLE_STEPS[name]()
    else:
        mech = make_mechanism(model, method)
        integ = make_integrator(name)
        assert integ.kernel_method >= 0  # the compiled path vjm run and the node take
    q1, qd1 = integ.advance(mech, 0.0, q, qd, np.zeros(model.n), duration, steps)
    return np.concatenate((q1, qd1))


@pytest.fixture(scope="module")
def reference():
    """The oracle's RK4 with 1280 steps: its error (~e_rk4(1/160) / 8^4) is below 1e-3 of every
    compared one."""
    model = order_model()
    assert not model.is_revolute.all() and model.is_revolute.any()
    return model, final_state(model, "rk4", 1280, oracle=True)


@pytest.mark.parametrize(
    "name, steps, lo, hi",
    [
        # h = 1/40 .. 1/160 s: asymptotic for the chain's ~5 rad/s motion, errors 1e-5 .. 1e-8
        # (far above round-off), so log2 ratios sit within 0.1 of 4.
        ("rk4", (40, 80, 160), 3.5, 4.5),
        # first-order methods, h = 4 ms .. 1 ms: errors ~1e-2 .. 1e-3, ratios within 0.02 of 1.
        ("semi_implicit_euler", (250, 500, 1000), 0.8, 1.2),
        ("explicit_euler", (250, 500, 1000), 0.8, 1.2),
    ],
)
def test_observed_order(reference, name, steps, lo, hi):
    """Oracle: log2(e(h) / e(h/2)) ~ the method's order, errors against a fine RK4 reference."""
    model, ref = reference
    errs = [float(np.max(np.abs(final_state(model, name, n) - ref))) for n in steps]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all((orders >= lo) & (orders <= hi)), (errs, orders)
    assert make_integrator(name).order == round(float(np.mean(orders)))


def test_oracle_rk4_tableau_meets_the_order_conditions():
    """Oracle check: the tableau that drives the oracle's RK4 (the reference above and
    ``test/test_fast.py``'s steps) meets Butcher's eight conditions of order 4, and a tableau
    whose rows of ``A`` do not sum to its nodes ``c`` is refused."""
    got = ORACLE_STEPS["rk4"].tableau.order_conditions()
    want = {"b": 1, "bc": 1 / 2, "bc2": 1 / 3, "bAc": 1 / 6,
            "bc3": 1 / 4, "bcAc": 1 / 8, "bAc2": 1 / 12, "bAAc": 1 / 24}
    for key, value in want.items():
        # sums of four products of binary fractions and thirds: a few eps
        assert got[key] == pytest.approx(value, rel=1e-15), key
    with pytest.raises(ValueError, match="row sums"):
        ButcherTableau([[0.0, 0.0], [0.4, 0.0]], [0.5, 0.5], [0.0, 0.5])


# --------------------------------------------------------------------------- stability bounds


@pytest.mark.parametrize("zeta", [0.05, 0.3, 0.7, 0.95])
def test_explicit_euler_bound(zeta):
    """Oracle: |1 + h (-zeta +- i sqrt(1 - zeta^2))| = 1 at h = 2 zeta (zeta < 1)."""
    # The bisection ends where the spectral radius exceeds 1 + 1e-12; near the bound it rises
    # with slope ~ zeta, so the bound is found to ~1e-11.
    assert make_integrator("explicit_euler").stability_bound(zeta) == pytest.approx(
        2 * zeta, abs=1e-9
    )


def test_explicit_euler_undamped_is_never_stable():
    """Oracle: at zeta = 0 the radius is sqrt(1 + h^2) > 1 for every h > 0 (bound 0)."""
    # The radius 1 + h^2/2 passes the method's 1e-12 tolerance up to h = sqrt(2e-12) = 1.4e-6.
    assert make_integrator("explicit_euler").stability_bound(0.0) < 2e-6


@pytest.mark.parametrize("zeta", [0.0, 0.1, 0.5])
def test_semi_implicit_euler_bound(zeta):
    """Oracle: 2 (sqrt(1 + zeta^2) - zeta) (Jury test on trace 2 - h^2 - 2 zeta h, det 1 - 2 zeta h).

    At zeta = 0 this is the textbook omega h < 2.
    """
    # At zeta = 0 the step matrix is defective at h = 2 and its computed eigenvalues carry
    # ~sqrt(eps) error nearby, so allow 1e-7 relative; elsewhere the bound is found to ~1e-12.
    expect = 2 * (np.sqrt(1 + zeta**2) - zeta)
    assert make_integrator("semi_implicit_euler").stability_bound(zeta) == pytest.approx(
        expect, rel=1e-7
    )


def test_rk4_bound():
    """Oracle: |R(iy)|^2 = 1 - y^6/72 + y^8/576 = 1 at y = 2 sqrt(2) (undamped)."""
    # The radius crosses 1 with slope ~1 (simple eigenvalues): bisection accuracy ~1e-12.
    assert make_integrator("rk4").stability_bound(0.0) == pytest.approx(2 * np.sqrt(2), rel=1e-9)


def test_implicit_penalty_euler_is_unconditionally_stable():
    """Oracle: the implicit treatment of the penalty forces has no step limit (bound inf), and
    its step map on the oscillator, |eig|^2 = det = 1 / (1 + 2 zeta x + x^2) below critical
    damping, never grows (x = omega_n h up to 1e4)."""
    integ = make_integrator("implicit_euler")
    assert integ.stability_bound(0.1) == np.inf
    x = np.geomspace(1e-3, 1e4, 200)
    for zeta in (0.0, 0.3, 2.0):
        step = integ.step_matrix((x * x)[:, None, None], (2 * zeta * x)[:, None, None], 1.0)
        assert np.all(np.abs(np.linalg.eigvals(step)) <= 1.0 + 1e-12)


# ------------------------------------------------ the analysis against the compiled kernel


def sliding_blocks(masses, kp, kv):
    """Blocks stacked on slides along y, each pinned to y = 0 by a penalty slider: linear.

    One chain at the origin along x with prismatic joints only, so every angle is locked at 0:
    block ``i`` sits at ``y_i = B_1 + ... + B_i``, ``M`` is constant, there is no Coriolis term
    and no gravity, and each slider row is ``C_i = y_i`` (``A`` lower triangular of ones). The
    closure dynamics are exactly ``C'' = -G Kp C - G Kv C'`` with ``G = A M^-1 A^T``, and so is
    one step of any method run by the kernel on this mechanism.
    """
    k = len(masses)
    model = Model.build(
        "blocks",
        (Chain("c", (0.0, 0.0), 0.0, 0.0, tuple(range(k))),),
        tuple(Link(f"b{i}", 0, 0.0, m, 0.0, (0.0, 0.0)) for i, m in enumerate(masses)),
        tuple(Joint(f"j{i}", PRISMATIC, 0.0, 0.0) for i in range(k)),
        closures=tuple(
            Closure(f"pin{i}", SLIDER, PointRef(i, (0.0, 0.0)), PointRef(GROUND, (0.0, 0.0)),
                    (1.0, 0.0))
            for i in range(k)
        ),
        gravity=(0.0, 0.0),
    )
    mech = make_mechanism(model, PenaltyClosure(np.asarray(kp, float), np.asarray(kv, float)))
    a = np.tril(np.ones((k, k)))
    mass = a.T @ np.diag(masses) @ a  # y = A B, T = 1/2 sum m_i y_i'^2
    return mech, a, a @ np.linalg.solve(mass, a.T)


def kernel_step_map(name, mech, a, h):
    """One step of the registry's method, run by the compiled kernel, as a matrix on
    ``(C, C')``: its columns are the steps from unit states (the map is linear)."""
    integ = make_integrator(name)  # a Mechanism: advance_fixed, the kernel's steps
    p = a.shape[0]
    cols = []
    for e in np.eye(2 * p):
        q, qd = np.linalg.solve(a, e[:p]), np.linalg.solve(a, e[p:])  # C = A B, C' = A B'
        q1, qd1 = integ.advance(mech, 0.0, q, qd, np.zeros(p), h, 1)
        cols.append(np.concatenate((a @ q1, a @ qd1)))
    return np.array(cols).T


@pytest.mark.parametrize("name", FIXED_STEP)
def test_step_matrix_is_the_kernels_step(name):
    """The closed-form one-step map that the stiffness check uses equals one step of the
    compiled kernel on an exactly linear mechanism: two coupled blocks, gains not proportional
    (Kv != c Kp), steps from soft to past every bound (omega_n h ~ 0.1 .. 3)."""
    masses, kp, kv = (1.5, 0.5), np.array([2.0, 3.0]), np.array([0.4, 1.1])
    mech, a, g = sliding_blocks(masses, kp, kv)
    integ = make_integrator(name)
    for h in (0.1, 0.7, 1.3, 2.9):
        got = kernel_step_map(name, mech, a, h)
        want = integ.step_matrix(g * kp[None, :], g * kv[None, :], h)
        # entries ~1e-2 .. 1e2 from a few products and a 2 x 2 solve of O(1) numbers: the two
        # sides differ by round-off, ~1e-15 of the largest entry.
        assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want)), (h, got, want)


@pytest.mark.parametrize(
    "name, zeta",
    [
        ("explicit_euler", 0.5),
        ("explicit_euler", 1.5),
        ("semi_implicit_euler", 0.1),
        ("semi_implicit_euler", 0.7),
        ("rk4", 0.0),
        ("rk4", 0.3),
        ("rk4", 1.5),
    ],
)
def test_kernel_grows_just_above_the_bound(name, zeta):
    """Oracle: the compiled kernel itself on ``x'' = -omega^2 x - 2 zeta omega x'`` (one block,
    m = 1 kg, h = 1 s, omega = omega_n h): 400 steps from ``x = 1`` at 0.97 of the method's
    bound decay, at 1.03 of it they grow."""
    bound = make_integrator(name).stability_bound(zeta)
    assert np.isfinite(bound)
    sizes = []
    for factor in (0.97, 1.03):
        w = factor * bound
        mech, _, _ = sliding_blocks((1.0,), [w * w], [2.0 * zeta * w])
        integ = make_integrator(name)
        q, qd = integ.advance(mech, 0.0, np.ones(1), np.zeros(1), np.zeros(1), 400.0, 400)
        sizes.append(float(np.hypot(q[0], qd[0] / w)))
    # 3 % off the bound the spectral radius of a step is <= 0.986 below and >= 1.015 above
    # (explicit Euler at zeta = 0.5, the flattest case; 0.81 .. 0.94 and 1.06 .. 1.40 in the
    # others): 400 steps scale the amplitude by <= e^-5.9 and >= e^6, far beyond the factor
    # of a few that the eigenvectors' conditioning adds.
    assert sizes[0] < 0.2 and sizes[1] > 5.0, sizes


def test_registry_has_fixed_step_methods():
    """The live-node methods of docs/design.md section 3 are registered as fixed-step."""
    for name in ("explicit_euler", "semi_implicit_euler", "rk4", "implicit_euler"):
        assert name in FIXED_STEP


def test_unknown_integrator_name():
    """Oracle: a ValueError whose message names every registered integrator."""
    with pytest.raises(ValueError) as info:
        make_integrator("leapfrog_9000")
    message = str(info.value)
    assert "leapfrog_9000" in message
    for name in INTEGRATORS:
        assert name in message
    with pytest.raises(ValueError) as info:
        Simulator(order_model(), SimulationSettings(integrator="leapfrog_9000"))
    for name in INTEGRATORS:
        assert name in str(info.value)


# --------------------------------------------------------------------------- efforts per tick


def block_model():
    """A 2 kg block on a slide rising 30 degrees (n(theta1) with theta1 = 60 deg), actuated."""
    return Model.build(
        "block",
        (Chain("c", (0.0, 0.0), np.radians(60.0), 0.2, (0,)),),
        (Link("block", 0, 0.3, 2.0, 0.05, (0.1, 0.0)),),
        (Joint("slide", PRISMATIC, 0.0, 0.1, 0.3),),
        actuators=(Actuator(0),),
    )


@pytest.mark.parametrize("name", ["rk4", "dop853", "rk45", "rk23", "radau"])
def test_efforts_switch_only_at_tick_boundaries(name):
    """Oracle: piecewise-constant acceleration (F_k / m - g sin 30 deg), integrated in closed form.

    The effort changes every third tick. Every Runge-Kutta method of order >= 2 (and its dense
    output) is exact on a constant acceleration, so any error beyond round-off means an effort
    acted inside a step begun under another one (that would be off by ~F/m dt^2 ~ 1e-4 m).
    """
    model = block_model()
    mass, g = 2.0, 9.81
    sim = Simulator(model, SimulationSettings(integrator=name, rate=100.0, substeps=4))
    x, v = 0.1, 0.3
    dt = 0.01
    worst = 0.0
    for k in range(60):
        force = 6.0 if (k // 3) % 2 == 0 else -4.0
        sim.advance([force])
        a = force / mass - g * 0.5
        x, v = x + v * dt + 0.5 * a * dt * dt, v + a * dt
        worst = max(worst, abs(sim.q[0] - x), abs(sim.qd[0] - v))
    # Round-off of 60 ticks on values ~1: measured <= 3e-15.
    assert worst < 1e-12
