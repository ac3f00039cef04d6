"""The preload of redundant actuation keeps one orientation along a motion.

three_chain (3 base actuators, 2 degrees of freedom) released under gravity with exact closure,
as ``vjm run three_chain --closure exact --duration 5`` records it: at every tick the efforts for
the recorded accelerations with a 20 N m preload. Oracles for the preload's direction ``z``:

* statics in closed form: three RR chains on one pin. The base rates of a pin velocity ``v``
  are ``thetad_i = u(phi_i) . v / (a_i sin e_i)`` (``phi_i`` the distal link's angle, ``e_i``
  the elbow angle, ``a_i`` the proximal length), so efforts that move nothing have
  ``sum_i tau_i u(phi_i) / (a_i sin e_i) = 0`` for every ``v``: ``tau_i ∝ a_i sin(e_i) s_i``
  with ``s_1 = u_2 x u_3``, ``s_2 = u_3 x u_1``, ``s_3 = u_1 x u_2`` (``sum s_i u_i = 0``);
* its orientation rule, checked with numpy's determinant rather than the formula that builds
  it: the closures balance ``z`` (``B z = -A^T lambda``) and ``det([[A^T B]; (lambda, z)]) > 0``.
"""

from __future__ import annotations

import numpy as np
import pytest

from vjm_ros.control import ClosedChainModel, distribute
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

PRELOAD = 20.0  # N m
DURATION = 5.0  # s


@pytest.fixture(scope="module")
def motion():
    """Time (s), q, qd, qdd per tick of three_chain's fall, the scene's rk4 at 1 kHz, exact."""
    scene = load_scene("three_chain")
    sim = Simulator(scene.model, SimulationSettings(closure="exact", integrator="rk4",
                                                    rate=1000.0), scene.gains)
    rows = [sim.sample(geometry=False)]
    for _ in range(int(round(DURATION * 1000))):
        sim.advance()
        rows.append(sim.sample(geometry=False))
    t = np.array([s.t for s in rows])
    return t, *(np.array([getattr(s, k) for s in rows]) for k in ("q", "qd", "qdd"))


def cross(a: np.ndarray, b: np.ndarray) -> float:
    """The plane cross product ``a x b`` (z component)."""
    return float(a[0] * b[1] - a[1] * b[0])


def statics(m: ClosedChainModel, q: np.ndarray, qd: np.ndarray | None = None, h: float = 0.0):
    """The closed-form direction (max-norm 1) at ``q``, or at the link angles moved by
    ``h`` seconds at the rates ``qd``."""
    theta = m.mechanism.kinematics(q).theta
    links, names = m.model.link_names, m.model.joint_names
    out = []
    for c in ("c1", "c2", "c3"):
        prox, dist = theta[links.index(f"{c}_proximal")], theta[links.index(f"{c}_distal")]
        if qd is not None:
            base, elbow = qd[names.index(f"{c}_base")], qd[names.index(f"{c}_elbow")]
            prox, dist = prox + h * base, dist + h * (base + elbow)
        out.append((prox, dist))
    a = 2.0  # every proximal link of three_chain is 2 m long
    u = [np.array([np.cos(phi), np.sin(phi)]) for _, phi in out]
    s = [cross(u[1], u[2]), cross(u[2], u[0]), cross(u[0], u[1])]
    z = np.array([a * np.sin(phi - theta) * s_i for (theta, phi), s_i in zip(out, s, strict=True)])
    return z / np.max(np.abs(z))


def test_preload_keeps_its_orientation_and_the_efforts_are_continuous(motion):
    t, q, qd, qdd = motion
    m = ClosedChainModel.from_scene("three_chain")
    dt = t[1] - t[0]
    taus, dirs, rates = [], [], []
    sign = None
    for k in range(len(t)):
        udd = qdd[k, m.independent]
        tau = m.inverse_dynamics(q[k], qd[k], udd, preload=PRELOAD, respect_limits=False)
        base = m.inverse_dynamics(q[k], qd[k], udd, respect_limits=False)
        z = (tau - base) / PRELOAD
        oracle = statics(m, q[k])
        sign = sign or float(np.sign(oracle @ z))
        # one orientation for the whole motion; 1e-9: round-off of 6 x 6 determinants of
        # entries <= 5 m (the scene's lengths) after the division by the largest
        np.testing.assert_allclose(z, sign * oracle, atol=1e-9, err_msg=f"t = {t[k]}")
        h = 1e-6  # the oracle's rate by central differences along the link rates (~h^2)
        rates.append(np.max(np.abs(statics(m, q[k], qd[k], h) - statics(m, q[k], qd[k], -h)))
                     / (2 * h))
        taus.append(tau)
        dirs.append(z)
        if k % 50 == 0:  # every 50 ms: the orientation rule, P tau = w, numpy against compiled
            rd = m.reduced_dynamics(q[k], qd[k])
            a = m.constraint_jacobian(q[k])
            lam = np.linalg.lstsq(a.T, -m.selection @ z, rcond=None)[0]
            np.testing.assert_allclose(a.T @ lam + m.selection @ z, 0.0, atol=1e-9)
            assert np.linalg.det(np.vstack((np.hstack((a.T, m.selection)),
                                            np.concatenate((lam, z))))) > 0
            w = rd.mass_matrix @ udd + rd.coriolis + rd.gravity
            # solves with P P^T of condition <= 1e4 along this motion on w of ~1e2 N m
            np.testing.assert_allclose(rd.effort_map @ tau, w,
                                       atol=1e-9 * max(1.0, np.abs(w).max()))
            numpy_path = distribute(rd.effort_map, w, np.full(3, np.inf), preload=PRELOAD,
                                    direction=rd.preload_direction)
            np.testing.assert_allclose(numpy_path, tau, atol=1e-9 * PRELOAD)
    taus, dirs, rates = np.array(taus), np.array(dirs), np.array(rates)
    # no reversal of the antagonism between two ticks (an SVD's null vector flipped 8 times)
    assert np.all(np.einsum("ij,ij->i", dirs[1:], dirs[:-1]) > 0)
    # continuity: over one tick the efforts change by at most PRELOAD * |dz/dt| * dt, with the
    # closed form's own rate at either end of the tick; the factor 1.5 covers the change of that
    # rate within the tick (measured: at most 1.04), 1e-4 N m the efforts without preload (the
    # recorded motion's zero efforts, reproduced to ~1e-5 N m). A flip would jump 40 N m; the
    # largest jump is 1.5 N m, the bound at most 2.3 N m along this motion.
    jump = np.max(np.abs(np.diff(taus, axis=0)), axis=1)
    bound = 1.5 * PRELOAD * dt * np.maximum(rates[1:], rates[:-1]) + 1e-4
    worst = int(np.argmax(jump / bound))
    assert np.all(jump <= bound), (t[worst + 1], jump[worst], bound[worst])


def test_the_preload_direction_does_not_depend_on_the_independent_coordinates_or_weights():
    """Assembled poses around three_chain's start: the direction from the model equals the
    closed form with one orientation, whichever independent coordinates the model uses (their
    P differ) and whatever the effort weights; the numpy (reduced_dynamics) and the compiled
    (inverse_dynamics) paths agree."""
    ref = ClosedChainModel.from_scene("three_chain")
    models = [ref, ClosedChainModel(ref.model, ["c2_base", "c3_base"]),
              ClosedChainModel(ref.model, ["c3_base", "c1_base"])]
    q0, _ = ref.model.initial_state()
    sign = None
    for du in (0.0, 0.05, -0.05, 0.1):
        q = ref.assemble(q0[ref.independent] + du, guess=q0)
        oracle = statics(ref, q)
        for m in models:
            qd = m.dependent_velocities(q, [0.3, -0.2])
            rd = m.reduced_dynamics(q, qd)
            sign = sign or float(np.sign(oracle @ rd.preload_direction))
            np.testing.assert_allclose(rd.preload_direction, sign * oracle, atol=1e-9)
            for weights in (None, [1.0, 4.0, 2.0]):
                udd = np.array([0.2, 0.1])
                got = (m.inverse_dynamics(q, qd, udd, weights=weights, preload=7.0,
                                          respect_limits=False)
                       - m.inverse_dynamics(q, qd, udd, weights=weights,
                                            respect_limits=False)) / 7.0
                np.testing.assert_allclose(got, sign * oracle, atol=1e-9)
