"""Joint damping, armature and constant loads in the dynamics, against oracles we derive here.

* the forward dynamics of random chains with every plant term equals
  ``M_fd + diag(armature)`` solved against ``tau - b_0 - c qd + Q_load``, with ``M_fd`` and the
  unloaded bias from the plain-loop geometry of ``test/chains.py`` (finite differences of the
  Lagrangian) and ``Q_load = -dV_load/dq`` by central differences of the loads' potential written
  from its definition;
* a damped pendulum against scipy's solution of its own ODE;
* the small-oscillation period of a pendulum with armature against ``2 pi sqrt(J / (m g p))``;
* the energy ledger (loads as potential, damping as dissipation) along motions of closed chains.
"""

from __future__ import annotations

from dataclasses import replace

import chains as ch
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.errors import SceneError
from vjm_ros.core.mechanism import Mechanism
from vjm_ros.core.model import GROUND, Load, Model, PointRef
from vjm_ros.scene.loader import parse_scene
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator


def _with_plant(model: Model, rng: np.random.Generator) -> Model:
    """``model`` with random damping and armature on every joint and two loads per chain."""
    joints = tuple(replace(j, damping=float(rng.uniform(0.1, 2.0)),
                           armature=float(rng.uniform(0.01, 0.5))) for j in model.joints)
    loads = []
    for c, chain in enumerate(model.chains):
        for k, link in enumerate((chain.links[0], chain.links[-1])):
            loads.append(Load(f"load{c}_{k}", PointRef(link, tuple(rng.uniform(-0.5, 1.0, 2))),
                              tuple(rng.uniform(-5.0, 5.0, 2)), float(rng.uniform(-2.0, 2.0))))
    return Model.build(model.name, model.chains, model.links, joints, model.closures,
                       model.actuators, model.points, tuple(model.gravity), loads=tuple(loads))


def _load_potential(model: Model, q) -> float:
    """``V = -sum(F . P + torque * theta)`` from the plain-loop geometry."""
    _, theta = ch.mass_centres(model, q)
    total = 0.0
    for load in model.loads:
        p = ch.point_on_link(model, q, load.point.link, load.point.local)
        total -= float(np.dot(load.force, p)) + load.torque * theta[load.point.link]
    return total


def _bias_fd(model: Model, q, qd) -> np.ndarray:
    """The unloaded, undamped bias ``b = Mdot qd - dT/dq + dV/dq`` by central differences of
    the Lagrangian of ``test/chains.py``."""
    step = ch.JAC_STEP
    mdot = (ch.mass_matrix_fd(model, q + step * qd) - ch.mass_matrix_fd(model, q - step * qd)) / (2 * step)
    dt_dq = ch.coordinate_jacobian(lambda x: np.array(ch.kinetic(model, x, qd)), q, step)
    return mdot @ qd - dt_dq + ch.potential_gradient_fd(model, q)


@pytest.mark.parametrize("seed", range(4))
def test_forward_dynamics_with_damping_armature_and_loads(seed):
    rng = np.random.default_rng(100 + seed)
    model = _with_plant(ch.random_model(rng, 5, 2), rng)
    mech = Mechanism(model, PenaltyClosure(np.zeros(0), np.zeros(0)))
    for _ in range(3):
        q, qd = ch.random_state(rng, model)
        tau = rng.uniform(-3.0, 3.0, model.n)
        mass = ch.mass_matrix_fd(model, q) + np.diag(model.armature)
        q_load = -ch.coordinate_jacobian(lambda x: np.array(_load_potential(model, x)), q, ch.JAC_STEP)
        expected = np.linalg.solve(mass, tau - _bias_fd(model, q, qd) - model.damping * qd + q_load)
        # central differences of trigonometric positions: ~1e-10 relative on M and on the
        # potential gradients (step 1e-5), ~1e-8 on Mdot (a difference of differences)
        np.testing.assert_allclose(mech.accelerations(q, qd, tau), expected, rtol=1e-6, atol=1e-6)


ROD = """
name: rod
chains:
  - name: arm
    links:
      - {name: rod, length: 1.0, mass: 1.0, inertia: 0.0833333333333333, com: [0.5, 0.0],
         joint: {name: pivot, type: revolute, angle: %(angle)s, damping: %(c)s, armature: %(a)s}}
%(extra)s
"""


def _rod(angle=-1.0, c=0.0, a=0.0, extra=""):
    return parse_scene(ROD % {"angle": angle, "c": c, "a": a, "extra": extra})


def _run(scene, seconds, rate=1000.0, integrator="rk4"):
    sim = Simulator(scene.model, SimulationSettings(integrator=integrator, rate=rate), scene.gains)
    t, q, energy, diss = [0.0], [sim.q[0]], [], []
    s = sim.sample()
    energy.append(s.energy[3])
    diss.append(s.dissipation)
    for _ in range(int(round(seconds * rate))):
        sim.advance()
        s = sim.sample()
        t.append(sim.t)
        q.append(sim.q[0])
        energy.append(s.energy[3])
        diss.append(s.dissipation)
    return np.array(t), np.array(q), np.array(energy), np.array(diss)


def test_damped_pendulum_follows_its_ode():
    """``(I + m p^2) theta'' = -m g p cos(theta) - c theta'``, solved by scipy at 1e-12."""
    c, inertia = 0.7, 1.0 / 12.0 + 0.25
    t, q, energy, diss = _run(_rod(angle=-0.2, c=c), 3.0)
    ref = solve_ivp(lambda _, y: [y[1], (-9.81 * 0.5 * np.cos(y[0]) - c * y[1]) / inertia],
                    (0.0, 3.0), [-0.2, 0.0], t_eval=t, rtol=1e-12, atol=1e-12, method="DOP853")
    # RK4 at h = 1 ms on a motion of period ~1.6 s: global error ~ (h w)^4 ~ 1e-10 rad
    np.testing.assert_allclose(q, ref.y[0], rtol=0, atol=1e-8)
    assert energy[-1] < energy[0] - 1.0  # it lost energy, and the ledger says where it went
    work = np.concatenate(([0.0], np.cumsum(0.5 * (diss[1:] + diss[:-1]) * np.diff(t))))
    # trapezoid rule on a smooth dissipation at 1 ms: ~h^2 * |d2P/dt2| * T / 12 ~ 1e-6 J
    np.testing.assert_allclose(energy[0] - energy, work, rtol=0, atol=1e-5)


def test_armature_sets_the_small_oscillation_period():
    """``T = 2 pi sqrt((I + m p^2 + a) / (m g p))`` for a swing of 1e-3 rad about hanging."""
    a = 0.5
    t, q, _, _ = _run(_rod(angle=-np.pi / 2 + 1e-3, a=a), 6.0)
    x = q + np.pi / 2
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    crossings = t[up] - x[up] * (t[up + 1] - t[up]) / (x[up + 1] - x[up])  # linear interpolation
    period = np.mean(np.diff(crossings))
    expected = 2 * np.pi * np.sqrt((1.0 / 12.0 + 0.25 + a) / (9.81 * 0.5))
    # amplitude correction theta0^2/16 ~ 6e-8; crossings interpolated on a 1 ms grid: ~1e-7 s
    assert period == pytest.approx(expected, rel=1e-5)
    assert abs(period - 2 * np.pi * np.sqrt((1.0 / 12.0 + 0.25) / (9.81 * 0.5))) > 0.5


def test_constant_loads_balance_gravity_at_the_closed_form_angle():
    """A tip force ``(Fx, 0)`` and a torque ``tz`` hold the rod where
    ``-m g p cos(theta) - a Fx sin(theta) + tz = 0``; damping lets it settle there."""
    extra = ("loads:\n  - {name: push, point: {link: rod, at: tip}, force: [3.0, 0.0], "
             "torque: 1.5}\n")
    _, q, _, _ = _run(_rod(angle=-1.0, c=2.0, extra=extra), 20.0, rate=500.0)
    residual = lambda th: -9.81 * 0.5 * np.cos(th) - 3.0 * np.sin(th) + 1.5  # noqa: E731
    assert abs(residual(q[-1])) < 1e-6  # settled within e^-(c/2J) 20 s ~ 1e-26 of the balance
    assert q[-1] == pytest.approx(_bisect(residual, -np.pi / 2, 0.0), abs=1e-6)


def _bisect(f, lo, hi):
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(lo) * f(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("closure", ["penalty", "exact"])
def test_ledger_holds_in_a_closed_chain_with_every_plant_term(closure):
    """five_bar with damping and armature in every joint and a load on the pin, 2 s: the
    energy ledger (loads in the potential, damping dissipated) closes to the step's accuracy."""
    from vjm_ros.scene.loader import builtin_scene_text

    text = builtin_scene_text("five_bar").replace(
        "type: revolute, angle: 45.0}", "type: revolute, angle: 45.0, damping: 0.3, armature: 0.05}"
    ).replace("type: revolute, angle: 135.0}", "type: revolute, angle: 135.0, damping: 0.3}")
    text += ("loads:\n  - {name: weight, point: {link: left_distal, at: tip}, force: [2.0, -5.0],"
             " torque: 0.4}\n")
    scene = parse_scene(text)
    assert scene.model.has_plant_terms and scene.model.loads[0].point.link != GROUND
    settings = SimulationSettings(integrator="rk4", rate=1000.0, closure=closure)
    sim = Simulator(scene.model, settings, scene.gains if closure == "penalty" else {})
    samples = [sim.sample()]
    for _ in range(2000):
        sim.advance()
        samples.append(sim.sample())
    t = np.array([s.t for s in samples])
    rate = np.array([s.power_in - s.dissipation for s in samples])
    total = np.array([s.energy[3] for s in samples])
    work = np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))))
    assert np.all(np.diff(total) <= 1e-9) or closure == "exact"  # passive: E never grows
    # trapezoid rule of a power that swings by ~10 W in ~0.1 s, at 1 ms: ~1e-4 J over 2 s;
    # Baumgarte's stabilization adds its own work in exact mode, on residuals ~1e-9
    assert np.max(np.abs(total - total[0] - work)) < 2e-3
    assert total[-1] < total[0] - 0.05  # damping took energy out


@pytest.mark.parametrize("text,key", [
    ("damping: -1.0", "chains[0].links[0].joint.damping"),
    ("armature: .nan", "chains[0].links[0].joint.armature"),
])
def test_negative_or_invalid_joint_terms_are_refused(text, key):
    bad = ROD.replace("damping: %(c)s, armature: %(a)s", text) % {"angle": 0.0, "extra": ""}
    with pytest.raises(SceneError, match=key.replace("[", r"\[").replace("]", r"\]")):
        parse_scene(bad)


@pytest.mark.parametrize("load,key", [
    ("{name: w, point: {link: nowhere, at: tip}, force: [1, 0]}", "loads[0].point.link"),
    ("{name: w, point: {ground: [0, 0]}, force: [1, 0]}", "loads[0].point"),
    ("{name: w, point: {link: rod}, force: [1]}", "loads[0].force"),
    ("{point: {link: rod}}", "loads[0]"),
])
def test_bad_loads_are_refused_naming_the_key(load, key):
    with pytest.raises(SceneError, match=key.replace("[", r"\[").replace("]", r"\]")):
        _rod(extra=f"loads:\n  - {load}\n")


def test_a_scene_without_plant_terms_packs_none():
    """A scene without the keys runs the kernels' code of before (the plant flag off)."""
    from vjm_ros.core import layout
    from vjm_ros.core.packing import pack_model
    from vjm_ros.scene.loader import load_scene

    model = load_scene("four_bar").model
    assert not model.has_plant_terms
    assert pack_model(model, ExactClosure()).par[layout.P_PLANT] == 0.0
    assert pack_model(_rod(c=0.1).model, ExactClosure()).par[layout.P_PLANT] == 1.0


def test_controller_model_compensates_the_plant_terms_on_request():
    """The rod's inverse dynamics: ``(I + m p^2 + a) udd + m g p cos(theta) + c qd - tz`` with
    the plant terms, the ideal ``(I + m p^2) udd + m g p cos(theta)`` without them (default)."""
    from vjm_ros.control.closed_model import ClosedChainModel

    extra = ("actuators:\n  - {joint: pivot}\nloads:\n  - {name: twist, point: {link: rod}, "
             "torque: 0.8}\n")
    model = _rod(c=0.4, a=0.2, extra=extra).model
    q, qd, udd = np.array([-0.3]), np.array([1.7]), np.array([2.5])
    gravity = 9.81 * 0.5 * np.cos(q[0])
    ideal = ClosedChainModel(model).inverse_dynamics(q, qd, udd)
    full = ClosedChainModel(model, plant_terms=True).inverse_dynamics(q, qd, udd)
    inertia = 1.0 / 12.0 + 0.25
    assert ideal[0] == pytest.approx(inertia * udd[0] + gravity, rel=1e-12)
    assert full[0] == pytest.approx((inertia + 0.2) * udd[0] + gravity + 0.4 * qd[0] - 0.8,
                                    rel=1e-12)
