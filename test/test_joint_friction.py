"""Coulomb friction in the joints: sticking, sliding, and the energy it takes.

Oracles written here from the definition of Coulomb friction, not from the kernels:

* a pendulum with friction ``mu`` at its pivot, released outside its sticking region: by energy,
  each half swing from a turning point ``a`` ends at the turning point ``b`` on the other side
  where ``V(a) - V(b) = mu |a - b|`` (the friction's work over the angle swept); the first ``b``
  where ``|dV/dtheta| <= mu`` is where it stops and stays;
* the energy ledger: what the mechanism lost equals the friction's work, in a five-bar with
  friction in every joint too, which also converges (first order) when the step is halved;
* smooth friction ``-mu tanh(rate / v_s)`` in the forward dynamics against the bias of the plain
  Lagrangian oracle of ``test/chains.py``.
"""

from __future__ import annotations

from dataclasses import replace

import chains as ch
import numpy as np
import pytest

from vjm_ros.core.constraints import PenaltyClosure
from vjm_ros.core.errors import SceneError
from vjm_ros.core.mechanism import Mechanism
from vjm_ros.core.model import Model
from vjm_ros.scene.loader import builtin_scene_text, parse_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator

MGP = 9.81 * 0.5  # the rod's m g p, N m
ROD = """
name: rod
chains:
  - name: arm
    links:
      - {name: rod, length: 1.0, mass: 1.0, inertia: 0.0833333333333333, com: [0.5, 0.0],
         joint: {name: pivot, type: revolute, angle: %s, %s}}
"""


def _samples(scene, seconds, rate=1000.0, integrator="rk4", closure=None, substeps=1):
    kw = {"closure": closure} if closure else {}
    settings = SimulationSettings(integrator=integrator, rate=rate, substeps=substeps, **kw)
    sim = Simulator(scene.model, settings, scene.gains if closure != "exact" else {})
    out = [sim.sample()]
    for _ in range(int(round(seconds * rate))):
        sim.advance()
        out.append(sim.sample())
    return out


def _turning_points(start: float, mu: float) -> list[float]:
    """Turning points of the rod from rest at ``start`` by the energy balance of each half
    swing, until one lies in the sticking region ``|MGP cos(theta)| <= mu``."""
    hanging = -np.pi / 2
    points = [start]
    while abs(MGP * np.cos(points[-1])) > mu:
        a = points[-1]
        lo, hi = (hanging, 2 * hanging - a) if a > hanging else (2 * hanging - a, hanging)
        f = lambda b, a=a: MGP * np.sin(a) - MGP * np.sin(b) - mu * abs(a - b)  # noqa: E731
        # f > 0 at the hanging angle (energy left), < 0 at the mirror of a: one root between
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if (f(mid) > 0) == (f(lo) > 0):
                lo = mid
            else:
                hi = mid
        points.append(0.5 * (lo + hi))
    return points


@pytest.mark.parametrize("integrator", ["rk4", "semi_implicit_euler"])
def test_pendulum_stops_where_the_energy_balance_says_and_stays(integrator):
    mu, start = 1.0, -np.pi / 2 + 1.0
    scene = parse_scene(ROD % (start, f"friction: {mu}"))
    samples = _samples(scene, 8.0, integrator=integrator)
    theta = np.array([s.q[0] for s in samples])
    rate = np.array([s.qd[0] for s in samples])
    expected = _turning_points(start, mu)
    assert len(expected) >= 3  # it swings a few times before it sticks
    # one impulse per 1 ms step: the friction is first order in h; the stop angle moves by
    # ~h * |rate| ~ 1e-3 rad at the last reversal
    assert theta[-1] == pytest.approx(expected[-1], abs=3e-3)
    # from here on the rate is round-off: the held friction cancels the other efforts to the
    # last bits, and RK4's later stages see what is left (~1e-17 rad/s^2)
    still = np.flatnonzero(np.abs(rate) > 1e-12)[-1] + 1
    assert still < len(samples) - 2000  # it stuck more than 2 s before the end and stayed
    assert np.ptp(theta[still:]) < 1e-12
    assert abs(MGP * np.cos(theta[-1])) <= mu  # inside the sticking region
    # the ledger: the energy lost is the friction's work
    energy = np.array([s.energy[3] for s in samples])
    work = np.cumsum([s.joint_loss for s in samples])  # per tick, as it was taken
    lost = energy[0] - energy
    assert lost[-1] == pytest.approx(MGP * (np.sin(start) - np.sin(theta[-1])), rel=1e-9)
    # the kernel counts a step's friction work as h mu (v0 + v1) / 2; semi-implicit Euler
    # moves h v1, rk4 to third order in h: per sliding step h^2 mu |a| / 2 ~ 2e-6 J, over ~2000
    # steps ~4e-3 J (measured 3.5e-3), and ~h^3 per step for rk4 (measured 2.5e-6 J)
    assert np.max(np.abs(lost - work)) < {"rk4": 1e-5, "semi_implicit_euler": 5e-3}[integrator]


def test_a_pendulum_inside_its_sticking_region_never_moves():
    scene = parse_scene(ROD % (-np.pi / 2 + 0.1, "friction: 1.0"))  # |MGP cos| = 0.49 < 1
    samples = _samples(scene, 1.0)
    assert max(abs(s.q[0] - samples[0].q[0]) for s in samples) < 1e-12  # round-off, see above
    assert max(abs(s.qd[0]) for s in samples) < 1e-12


def _five_bar_with_friction(mu: float) -> Model:
    text = builtin_scene_text("five_bar")
    for angle in ("45.0", "135.0"):
        text = text.replace(f"type: revolute, angle: {angle}}}",
                            f"type: revolute, angle: {angle}, friction: {mu}}}")
    return parse_scene(text)


@pytest.mark.parametrize("closure", ["exact", "penalty"])
def test_five_bar_with_friction_in_every_joint_keeps_its_ledger(closure):
    scene = _five_bar_with_friction(0.3)
    assert np.count_nonzero(scene.model.friction) == 4
    samples = _samples(scene, 2.0, closure=closure)
    t = np.array([s.t for s in samples])
    energy = np.array([s.energy[3] for s in samples])
    rate = np.array([s.power_in - s.dissipation for s in samples])
    loss = np.array([s.joint_loss for s in samples])
    work = np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t)
                                            - loss[1:])))
    assert energy[0] - energy[-1] > 0.5  # friction took a good part of the motion's energy
    # the friction's work per step to second order in h (above) and the trapezoid rule on the
    # smooth powers at 1 ms; for exact closures Baumgarte's work on residuals ~1e-9 (measured
    # 1.4e-4 J exact, 2.3e-4 J penalty)
    assert np.max(np.abs(energy - energy[0] - work)) < 1e-3


def test_five_bar_with_friction_converges_when_the_step_is_halved():
    """First order: the error at 1 s roughly halves with the step (against h/16)."""
    scene = _five_bar_with_friction(0.3)
    end = {}
    for substeps in (1, 2, 4, 16):
        end[substeps] = _samples(scene, 1.0, closure="exact", substeps=substeps)[-1].q
    errors = [np.max(np.abs(end[s] - end[16])) for s in (1, 2, 4)]
    assert errors[0] > errors[1] > errors[2]
    assert errors[0] / errors[2] > 2.5  # ~4 for first order; stick-slip events blur it


def test_smooth_friction_in_the_forward_dynamics():
    rng = np.random.default_rng(7)
    model = ch.random_model(rng, 4, 2)
    joints = tuple(replace(j, friction=float(rng.uniform(0.5, 2.0)),
                           friction_scale=float(rng.uniform(0.05, 0.5))) for j in model.joints)
    model = Model.build(model.name, model.chains, model.links, joints, gravity=tuple(model.gravity))
    mech = Mechanism(model, PenaltyClosure(np.zeros(0), np.zeros(0)))
    q, qd = ch.random_state(rng, model)
    tau = rng.uniform(-2.0, 2.0, model.n)
    bias = (ch.mass_matrix_fd(model, q + 1e-5 * qd) - ch.mass_matrix_fd(model, q - 1e-5 * qd)) / 2e-5 @ qd
    bias = bias - ch.coordinate_jacobian(lambda x: np.array(ch.kinetic(model, x, qd)), q, 1e-5)
    bias = bias + ch.potential_gradient_fd(model, q)
    friction = model.friction * np.tanh(qd / model.friction_scale)
    expected = np.linalg.solve(ch.mass_matrix_fd(model, q), tau - bias - friction)
    # central differences: ~1e-8 relative (test_plant_terms.py)
    np.testing.assert_allclose(mech.accelerations(q, qd, tau), expected, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("keys,key,expected", [
    ("friction: -1.0", "friction", "a number >= 0"),
    ("friction: 1.0, friction_model: viscous", "friction_model", "stick"),
    ("friction: 1.0, velocity_scale: 0.1", "velocity_scale", "no velocity_scale"),
    ("friction: 1.0, friction_model: smooth", "joint", "velocity_scale"),
    ("friction: 1.0, friction_model: smooth, velocity_scale: 0", "velocity_scale", "positive"),
])
def test_bad_friction_is_refused_naming_the_key(keys, key, expected):
    with pytest.raises(SceneError, match=key) as info:
        parse_scene(ROD % (0.0, keys))
    assert expected in str(info.value)


# ------------------------------------------------------------------------------ hard stops
STOP = -np.pi / 2 + 0.4  # the lower stop: the rod, falling from horizontal, meets it on its way


@pytest.mark.parametrize("restitution", [0.0, 0.5])
def test_pendulum_dropped_on_a_stop_stays_or_rebounds_to_the_height_e2_predicts(restitution):
    """Energy: after an impact at rate ``v`` the rod leaves the stop at ``e v`` and rises until
    ``V(top) - V(stop) = e^2 (V(start) - V(stop))``; with ``e = 0`` it stays on the stop, held
    by gravity (``-MGP cos(stop) < 0`` pushes it into the stop)."""
    scene = parse_scene(ROD % (0.0, f"range: [{STOP}, 3.0], restitution: {restitution}"))
    samples = _samples(scene, 1.5, rate=4000.0)  # the impact at 0.41 s, its rebound's top by 1 s
    theta = np.array([s.q[0] for s in samples])
    rate = np.array([s.qd[0] for s in samples])
    # first-order contact: the step ends on the stop from the rate it predicts; rk4's stages
    # overshoot by ~h |v| / 2 ~ 5e-4 rad at the ~4 rad/s impact (h = 0.25 ms)
    assert theta.min() > STOP - 1e-3
    hit = np.flatnonzero(theta <= STOP + 1e-9)[0]
    if restitution == 0.0:
        assert np.max(np.abs(theta[hit + 10:] - STOP)) < 1e-9  # on the stop, and stays
        assert np.max(np.abs(rate[hit + 10:])) < 1e-9
        return
    after = theta[hit:]
    top = after[: np.argmax(np.diff(after) < 0) + 1].max()  # the highest point of the rebound
    drop = MGP * (np.sin(0.0) - np.sin(STOP))
    rise = MGP * (np.sin(top) - np.sin(STOP))
    # first order in h: the impact's rate is read up to h |a| ~ 2e-3 rad/s of 4 rad/s
    assert rise == pytest.approx(restitution**2 * drop, rel=1e-2)


def test_a_stop_takes_the_impact_energy_in_the_ledger():
    scene = parse_scene(ROD % (0.0, f"range: [{STOP}, 3.0], restitution: 0.3"))
    samples = _samples(scene, 2.0, rate=2000.0)
    energy = np.array([s.energy[3] for s in samples])
    loss = np.array([s.joint_loss for s in samples])
    assert np.all([s.dissipation == 0.0 for s in samples])  # no damping: all of it is the stop's
    assert energy[0] - energy[-1] > 1.0  # the impacts took most of the drop's energy
    impacts = np.flatnonzero(loss > 0.05)
    assert 1 <= len(impacts) <= 10
    err = energy[0] - energy - np.cumsum(loss)
    # at the impacts' ticks too (each takes 4.1 and 0.37 J at once): setting the rod on its stop
    # changes V by m g p cos(stop) * (h |qd|) per impact, ~5e-3 J in all (measured 5.3e-3)
    assert np.max(np.abs(err)) < 1e-2


@pytest.mark.parametrize("keys,key,expected", [
    ("range: [1.0, -1.0]", "range", "lo < hi"),
    ("range: [0.5, 1.0]", "range", "holds the joint's start"),
    ("range: [-1.0, 1.0], restitution: 1.5", "restitution", "[0, 1]"),
    ("restitution: 0.5", "restitution", "only with a range"),
    ("range: [-1.0]", "range", "2"),
])
def test_bad_stops_are_refused_naming_the_key(keys, key, expected):
    with pytest.raises(SceneError, match=key) as info:
        parse_scene(ROD % (0.0, keys))
    assert expected in str(info.value)


@pytest.mark.parametrize("closure", ["exact", "penalty"])
def test_a_stop_inside_a_closed_chain_holds_and_the_closures_recover(closure):
    """five_bar with a stop on ``left_base`` at -1.8 rad (it swings to -3.3 rad without it):
    the joint never goes past the stop by more than a step's travel, it rests on it, and the
    closures stay met to what the impacts disturb (penalty closures: to their own give)."""
    lo = np.degrees(-1.8)
    text = builtin_scene_text("five_bar").replace(
        "{name: left_base, type: revolute, angle: 45.0}",
        f"{{name: left_base, type: revolute, angle: 45.0, range: [{lo}, 60.0]}}")
    samples = _samples(parse_scene(text), 3.0, closure=closure)
    q = np.array([s.q[0] for s in samples])
    assert q.min() > -1.8 - 1e-9  # set back on the stop at the end of every step
    assert np.count_nonzero(np.abs(q + 1.8) < 1e-6) > 100  # it rests on the stop a while
    # an impact sets the chain back by a step's travel (h |qd| = 8.5e-3 rad at the first
    # impact's 8.5 rad/s) along W's row, which keeps the closures to first order: the pin
    # opens by the second-order rest, (8.5e-3)^2 = 7e-5 times second derivatives of the pin's
    # position of a few m (measured 2.3e-4 m; without W's row it was 7e-3 m). Penalty
    # closures give 2.3e-3 m on this motion without the stop; the impacts, whose W is M^-1
    # there (the closures act as forces), open them by ~1e-3 m more (measured 3.2e-3 m)
    bound = {"exact": 1e-3, "penalty": 5e-3}[closure]
    assert max(s.closure_error.max() for s in samples) < bound


def test_controller_model_compensates_coulomb_friction_on_request():
    """With ``plant_terms=True`` the rod's inverse dynamics adds ``mu tanh(qd / 0.01)``
    (the sticking friction made smooth for the controller), and nothing without it."""
    from vjm_ros.control.closed_model import FRICTION_COMPENSATION_SCALE, ClosedChainModel

    model = parse_scene(ROD % (-0.3, "friction: 0.6, range: [-2.0, 2.0]")
                        + "actuators:\n  - {joint: pivot}\n").model
    q, qd, udd = np.array([-0.3]), np.array([0.004]), np.array([2.5])
    ideal = ClosedChainModel(model).inverse_dynamics(q, qd, udd)[0]
    full = ClosedChainModel(model, plant_terms=True).inverse_dynamics(q, qd, udd)[0]
    inertia = 1.0 / 12.0 + 0.25
    assert ideal == pytest.approx(inertia * udd[0] + MGP * np.cos(q[0]), rel=1e-12)
    assert full - ideal == pytest.approx(0.6 * np.tanh(qd[0] / FRICTION_COMPENSATION_SCALE),
                                         rel=1e-12)


def test_adaptive_integrators_refuse_sticking_friction_and_stops():
    """Friction and stops act once per fixed step: an adaptive solve would leave them out."""
    from vjm_ros.core.errors import ConfigurationError

    for keys in ("friction: 0.5", "range: [-2.0, 2.0]"):
        scene = parse_scene(ROD % (0.0, keys))
        with pytest.raises(ConfigurationError, match="integrator: expected a fixed-step"):
            Simulator(scene.model, SimulationSettings(integrator="rk45"), {})
    smooth = parse_scene(ROD % (0.0, "friction: 0.5, friction_model: smooth, velocity_scale: 0.1"))
    Simulator(smooth.model, SimulationSettings(integrator="rk45"), {})  # smooth: a force


def test_blocks_report_the_same_dissipation_as_ticks():
    """The compiled block of ticks (vjm run, the node) reports the energy the friction and the
    stops took as the tick-by-tick path does: the same numbers."""
    scene = parse_scene(ROD % (0.0, f"range: [{STOP}, 3.0], restitution: 0.5, friction: 0.1"))
    a = Simulator(scene.model, SimulationSettings(integrator="rk4", rate=1000.0), {})
    b = Simulator(scene.model, SimulationSettings(integrator="rk4", rate=1000.0), {})
    block = SampleBlock(scene.model, 600)
    b.advance_block(block, 600)
    ticks = []
    for _ in range(600):
        a.advance()
        ticks.append(a.sample().joint_loss)
    assert np.max(ticks) > 0.1  # an impact is among them
    np.testing.assert_allclose(block.loss[:600], ticks, rtol=1e-12, atol=1e-12)


def test_the_summary_ledger_of_a_run_with_impacts_falls_with_the_step():
    """``energy_balance_residual`` stays an accuracy signal with impacts: each impact's energy
    is summed at its tick, so what is left is the step's error, which falls with it (with the
    impacts' energy reported as a power it stayed at 1.69 J, half the first impact)."""
    from vjm_ros.sim.trajectory import Trajectory

    scene = parse_scene(ROD % (0.0, f"range: [{STOP}, 3.0], restitution: 0.5"))
    residual = []
    for substeps in (1, 4, 16):
        sim = Simulator(scene.model, SimulationSettings(integrator="rk4", substeps=substeps), {})
        traj = Trajectory(scene.model)
        traj.append(sim.sample())
        block = SampleBlock(scene.model, 3000)
        sim.advance_block(block, 3000)
        traj.extend(block)
        residual.append(traj.energy_balance_residual())
    # first order (the stops act once per step): measured 6.8e-3, 2.7e-3, 7.9e-4 J
    assert residual[0] < 2e-2
    assert residual[0] / residual[1] > 2.0 and residual[1] / residual[2] > 2.0


@pytest.mark.parametrize("integrator", ["explicit_euler", "semi_implicit_euler", "rk4",
                                        "implicit_euler"])
def test_a_rod_bouncing_on_its_stop_comes_to_rest(integrator):
    """With e = 0.5 the bounces shrink until a rebound is one that gravity undoes within two
    steps; from there the rod rests on the stop, held by the moment statics asks (m g p
    cos(stop)) at every tick. Without the threshold rk4 chattered at the step's period (an
    impact at h |a| every other tick, the stop's moment alternating between 0 and half of it),
    explicit Euler every third step."""
    scene = parse_scene(ROD % (0.0, f"range: [{STOP}, 3.0], restitution: 0.5"))
    samples = _samples(scene, 3.0, integrator=integrator)
    rest = samples[-1000:]  # the bounces are over well before 2 s (e^k of 4 rad/s)
    assert max(abs(s.q[0] - STOP) for s in rest) < 1e-12
    assert max(abs(s.qd[0]) for s in rest) < 1e-9
    np.testing.assert_allclose([s.closure_force[0, 2] for s in rest], MGP * np.cos(STOP),
                               rtol=1e-9)
    # no impact any more (what the resting stop's effort removes is round-off, ~1e-20 J)
    assert max(s.joint_loss for s in rest) < 1e-12
