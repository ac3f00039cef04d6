"""Whole control ticks in one compiled call: the steps, the divergence guard and every observable.

:func:`advance_ticks` runs ``ticks`` control ticks of a fixed-step integrator with the efforts
held, as :meth:`vjm_ros.sim.simulator.Simulator.advance` followed by
:meth:`~vjm_ros.sim.simulator.Simulator.sample` would, and writes each tick's end state and its
observables into preallocated arrays (one row per tick). It calls the same compiled physics
(:func:`vjm_ros.core.kernels.step`) with the same arguments as the tick-by-tick path, so the states
are bit-identical to it; the observables are the same sums in the same order.

It stops at the first tick whose step fails (a singular matrix), whose state is not finite or
whose closure residual exceeds the divergence limit, and says which tick: the caller replays
that tick on the tick-by-tick path, which raises the full diagnostic.

Output arrays (``T`` ticks, ``n`` joints, ``p`` named points, ``k`` closures, ``s`` joints with a
stop, ``f = k + s``), each row ``i`` for the state at the end of tick ``i``:

* ``q``, ``qd``, ``qdd`` (T, n): rad or m, per s, per s^2;
* ``theta`` (T, n): absolute link angles, rad;
* ``points`` (T, p, 2): named points, m;
* ``force`` (T, f, 3): ``(Fx, Fy, Mz)`` of each closure on its point, N and N m, then of each
  stop (:attr:`vjm_ros.core.model.Model.stop_joints`) on its joint's link: the stop effort ``s``
  held over the tick's last step as a moment ``(0, 0, s)`` (revolute) or a force ``s n(theta_pred)``
  (prismatic) at the link's origin;
* ``error`` (T, k): ``|C|`` per closure, m or rad;
* ``cpoints`` (T, f, 2): the closures' points of application, then the stopped joints, m;
* ``energy`` (T, 4): kinetic, potential, constraint (penalty springs), total, J;
* ``power`` (T,): ``tau . qd``, W; ``dissipation`` (T,): ``sum Kv Cdot^2`` (penalty), joint
  damping and smooth friction, W;
* ``loss`` (T,): the energy sticking friction and stops (their impacts included) took over the
  tick, J (:mod:`vjm_ros.core.joint_efforts`): a sum over the tick's steps, not a power, since an
  impact takes its energy at once;
* ``segments`` (T, n, 2, 2): start and end of every link, m.

With :data:`~vjm_ros.core.kernels.RK4`, a tick's first stage is the acceleration observed at the
end of the tick before (the same state and efforts, so the same numbers): from the second tick of
a block on, a tick costs ``4 substeps`` evaluations, the observation included.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from vjm_ros.core import kernels as K
from vjm_ros.core import layout
from vjm_ros.core.joint_efforts import has_stop
from vjm_ros.core.terms import point_motion
from vjm_ros.jit import jit as _jit
from vjm_ros.jit import variant as _variant

if TYPE_CHECKING:
    from collections.abc import Sized
    from typing import Protocol

    class ModelSizes(Protocol):
        """What the functions below read of a :class:`vjm_ros.core.model.Model` (this layer
        does not import it)."""

        n: int
        points: Sized
        closures: Sized
        stop_joints: Sized

OBSERVABLES = ("q", "qd", "qdd", "theta", "points", "force", "error", "cpoints", "energy",
               "power", "dissipation", "loss", "segments")
"""Names of the output arrays, in the order :func:`observe` takes them."""


def observable_shapes(model: ModelSizes) -> tuple[tuple[int, ...], ...]:
    """Shape of one row of each output array of ``model``, a
    :class:`~vjm_ros.core.model.Model` (:data:`OBSERVABLES` order)."""
    n, p, k = model.n, len(model.points), len(model.closures)
    f = k + len(model.stop_joints)
    return ((n,), (n,), (n,), (n,), (p, 2), (f, 3), (k,), (f, 2), (4,), (), (), (), (n, 2, 2))


def new_outputs(rows: int, model: ModelSizes) -> tuple[np.ndarray, ...]:
    """Zeroed output arrays of ``model`` (a :class:`~vjm_ros.core.model.Model`) for ``rows``
    ticks."""
    return tuple(np.zeros((rows,) + shape) for shape in observable_shapes(model))


OK = 0
"""Every tick ran."""
SINGULAR = 1
"""A matrix was exactly singular in the failing tick."""
NOT_FINITE = 2
"""The state after the failing tick is not finite."""
BEYOND_LIMIT = 3
"""A closure residual after the failing tick exceeds the divergence limit."""


_step = K.step
"""The kernel the functions below call; their copies ``*_with_hub`` call
:data:`vjm_ros.core.kernels.step_with_hub`."""
_tick_step = K.step_inline
"""The same kernel inlined into :func:`advance_ticks` for the tick's steps (one call per tick:
:data:`vjm_ros.core.kernels.step_inline`); the projection, when asked for, calls :data:`_step`."""


@_jit(allocates=False, inline="always")
def observe(row: int, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, model: tuple, data: tuple,
            lengths: np.ndarray, plink: np.ndarray, plocal: np.ndarray, out: tuple,
            evaluated: bool) -> int:
    """Every observable at ``(q, qd)`` with efforts ``tau``, into row ``row`` of ``out``.

    Parameters
    ----------
    row : int
    q, qd, tau : ndarray, shape (n,)
    model : tuple
        A :class:`vjm_ros.core.layout.PackedModel`'s fields as a plain tuple
        (:func:`vjm_ros.core.kernels.as_arguments`).
    data : tuple
        The kernel's workspace (:func:`vjm_ros.core.layout.make_data`), likewise.
    lengths : ndarray, shape (n,)
        Link lengths, m.
    plink : ndarray of int64, shape (p,)
        Link of each named point (``-1``: ground).
    plocal : ndarray, shape (p, 2)
        ``(s, w)`` of each named point in its link frame, m (world position on the ground).
    out : tuple
        ``(q, qd, qdd, theta, points, force, error, cpoints, energy, power, dissipation,
        loss, segments)`` output arrays (module docstring).
    evaluated : bool
        ``data`` already holds the evaluation at ``(q, qd)`` with ``tau``, its acceleration
        in ``out``'s ``qdd[row]`` and its energies in ``kin``'s ground row (a step made with
        :data:`~vjm_ros.core.kernels.THEN_EVALUATE`); False: evaluate here.

    Returns
    -------
    int
        0, or 1 when the mass matrix was exactly singular.
    """
    _, _, cint, _, gains, par, _ = model
    kin, _, _, _, crow, _, cpts = data[:7]
    o_q, o_qd, o_qdd, o_theta, o_points, o_force, o_error, o_cpoints = out[:8]
    o_energy, o_power, o_diss, o_loss, o_seg = out[8:]
    n = q.shape[0]
    status = 0
    if not evaluated:
        status = _step(K.EVALUATE, q, qd, tau, 0.0, K.ONE_STEP, 0.0, model, data, o_qdd[row],
                       o_qd[row], o_qdd, K.NO_ROW)
    power = 0.0
    for j in range(n):
        o_q[row, j] = q[j]
        o_qd[row, j] = qd[j]
        o_theta[row, j] = kin[j, layout.K_THETA]
        power += tau[j] * qd[j]
        o_seg[row, j, 0, 0] = kin[j, layout.K_OX]
        o_seg[row, j, 0, 1] = kin[j, layout.K_OY]
        o_seg[row, j, 1, 0] = kin[j, layout.K_OX] + lengths[j] * kin[j, layout.K_COS]
        o_seg[row, j, 1, 1] = kin[j, layout.K_OY] + lengths[j] * kin[j, layout.K_SIN]
    for p in range(plink.shape[0]):
        px, py, _, _, _, _ = point_motion(kin, plink[p], plocal[p, 0], plocal[p, 1])
        o_points[row, p, 0] = px
        o_points[row, p, 1] = py
    k = cint.shape[0]
    r = crow.shape[0]
    dissipation = 0.0
    for c in range(k):
        first = cint[c, 3]
        last = cint[c + 1, 3] if c + 1 < k else r
        sq = 0.0
        fx = fy = fz = 0.0
        for i in range(first, last):
            res = crow[i, layout.R_RES]
            sq += res * res  # x * x, not x ** 2: plain Python's pow may differ by an ulp
            f = crow[i, layout.R_FORCE]
            fx += crow[i, layout.R_DX] * f
            fy += crow[i, layout.R_DY] * f
            fz += crow[i, layout.R_DZ] * f
        o_error[row, c] = math.sqrt(sq)
        o_force[row, c, 0] = fx
        o_force[row, c, 1] = fy
        o_force[row, c, 2] = fz
        o_cpoints[row, c, 0] = cpts[c, 0]
        o_cpoints[row, c, 1] = cpts[c, 1]
    if par[layout.P_METHOD] == layout.PENALTY:
        for i in range(r):
            rate = crow[i, layout.R_RATE]
            dissipation += gains[i, 1] * (rate * rate)
    if par[layout.P_PLANT] != 0.0:
        lflt = model[1]
        for j in range(n):  # viscous joint damping, c qd^2, and smooth friction
            dissipation += lflt[j, layout.F_DAMPING] * (qd[j] * qd[j])
            if lflt[j, layout.F_FRICTION_SCALE] > 0.0:
                dissipation += lflt[j, layout.F_FRICTION] * math.tanh(
                    qd[j] / lflt[j, layout.F_FRICTION_SCALE]) * qd[j]
    o_loss[row] = 0.0
    if par[layout.P_JOINT_EFFORTS] != 0.0:
        o_loss[row] = data[25][n]  # joint friction and stops: energy over the last tick
        observe_stops(row, model, data, k, o_force, o_cpoints)
    kinetic = kin[n, layout.K_PCOS]
    potential = kin[n, layout.K_PSIN]
    spring = kin[n, layout.K_SLIDE]
    o_energy[row, 0] = kinetic
    o_energy[row, 1] = potential
    o_energy[row, 2] = spring
    o_energy[row, 3] = kinetic + potential + spring
    o_power[row] = power
    o_diss[row] = dissipation
    return status


@_jit(allocates=False, inline="always")
def observe_stops(row: int, model: tuple, data: tuple, first: int, o_force: np.ndarray,
                  o_cpoints: np.ndarray) -> None:
    """The force of every joint's stop, from row ``first`` of ``o_force[row]`` and
    ``o_cpoints[row]`` on, in joint order (module docstring)."""
    lint, lflt = model[0], model[1]
    kin, stop = data[0], data[26]
    c = first
    for j in range(lint.shape[0]):
        if has_stop(lflt, j):
            s = stop[j]
            if lint[j, layout.L_REV] == 1:
                o_force[row, c, 0] = 0.0
                o_force[row, c, 1] = 0.0
                o_force[row, c, 2] = s
            else:  # along n(theta_pred) = (-sin, cos) of the link before
                o_force[row, c, 0] = -kin[j, layout.K_PSIN] * s
                o_force[row, c, 1] = kin[j, layout.K_PCOS] * s
                o_force[row, c, 2] = 0.0
            o_cpoints[row, c, 0] = kin[j, layout.K_OX]
            o_cpoints[row, c, 1] = kin[j, layout.K_OY]
            c += 1


def tick_state(n: int) -> tuple[np.ndarray, ...]:
    """Scratch state vectors of :func:`advance_ticks` for ``n`` coordinates (built once per
    mechanism, so the compiled call creates no arrays)."""
    return tuple(np.empty(n) for _ in range(5))


@_jit(allocates=False)
def advance_ticks(method: int, q0: np.ndarray, qd0: np.ndarray, tau: np.ndarray, h: float,
                  substeps: int, ticks: int, project: bool, limit: float, model: tuple,
                  data: tuple, lengths: np.ndarray, plink: np.ndarray, plocal: np.ndarray,
                  out: tuple, state: tuple) -> tuple[int, int]:
    """``ticks`` control ticks of ``substeps`` steps of ``method``, each observed.

    Parameters
    ----------
    method : int
        :data:`~vjm_ros.core.kernels.EXPLICIT_EULER`, ``SEMI_IMPLICIT_EULER``, ``RK4`` or
        ``IMPLICIT_EULER``.
    q0, qd0 : ndarray, shape (n,)
        State at the start, not modified.
    tau : ndarray, shape (n,)
        Efforts held over every tick, N m or N.
    h : float
        Step, s (the tick over ``substeps``).
    substeps, ticks : int
    project : bool
        Project ``q`` and ``qd`` onto the closures after each tick (8 Gauss-Newton steps at
        most, tolerance 1e-12, as :meth:`vjm_ros.core.mechanism.Mechanism.project`).
    limit : float
        Largest accepted closure residual, m or rad (``inf``: no check).
    model, data, lengths, plink, plocal, out
        As in :func:`observe`.
    state : tuple
        Five scratch vectors of shape (n,) from :func:`tick_state`.

    Returns
    -------
    done : int
        Ticks that ran and were observed (rows ``0 .. done - 1`` of ``out`` are filled).
    code : int
        :data:`OK`, or why tick ``done`` failed: :data:`SINGULAR`, :data:`NOT_FINITE`,
        :data:`BEYOND_LIMIT`.
    """
    n = q0.shape[0]
    q, qd, qa, qb, zero = state
    for j in range(n):
        q[j] = q0[j]
        qd[j] = qd0[j]
        zero[j] = 0.0
    k = model[2].shape[0]  # closures: rows of cint
    o_qdd = out[2]
    o_error = out[6]
    # Without a projection, the step also evaluates at its end state (THEN_EVALUATE): the
    # observation's evaluation, without a second call.
    op = method if project else method + K.THEN_EVALUATE
    for t in range(ticks):
        # From the second tick on, the first stage (RK4) or the first step's evaluation is the
        # one observed at the last tick (the same state and efforts; the buffers still hold it).
        known = t - 1  # t = 0: NO_ROW
        status = _tick_step(op, q, qd, tau, h, substeps, 0.0, model, data, qa, qb, o_qdd, known)
        if status != 0:
            return t, SINGULAR
        if project:
            status = _step(K.PROJECT, qa, qb, zero, 0.0, K.PROJECTION_STEPS, 1e-12, model, data,
                           q, qd, o_qdd, K.NO_ROW)
            if status != 0:
                return t, SINGULAR
        else:
            for j in range(n):
                q[j] = qa[j]
                qd[j] = qb[j]
        for j in range(n):
            if not (math.isfinite(q[j]) and math.isfinite(qd[j])):
                return t, NOT_FINITE
        if observe(t, q, qd, tau, model, data, lengths, plink, plocal, out, not project) != 0:
            return t, SINGULAR
        for c in range(k):
            if o_error[t, c] > limit:
                return t, BEYOND_LIMIT
    return ticks, OK


observe_with_hub = _variant(observe, "observe_with_hub", _step=K.step_with_hub)
""":func:`observe` on :data:`vjm_ros.core.kernels.step_with_hub`."""


@_jit(allocates=False)
def observe_state(q: np.ndarray, qd: np.ndarray, tau: np.ndarray, model: tuple, data: tuple,
                  lengths: np.ndarray, plink: np.ndarray, plocal: np.ndarray, out: tuple) -> int:
    """Every observable at ``(q, qd)`` with efforts ``tau``, evaluated there, into row 0 of
    ``out``: one sample outside a block (:meth:`vjm_ros.sim.simulator.Simulator.sample`), the
    same numbers as :func:`advance_ticks` observes. Arguments as :func:`observe`; returns 0, or
    1 when the mass matrix was exactly singular."""
    return observe(0, q, qd, tau, model, data, lengths, plink, plocal, out, False)


observe_state_with_hub = _variant(observe_state, "observe_state_with_hub",
                                  observe=observe_with_hub)
""":func:`observe_state` on :data:`vjm_ros.core.kernels.step_with_hub`."""

advance_ticks_with_hub = _variant(advance_ticks, "advance_ticks_with_hub",
                                  _step=K.step_with_hub, _tick_step=K.step_with_hub_inline,
                                  observe=observe_with_hub)
""":func:`advance_ticks` on :data:`vjm_ros.core.kernels.step_with_hub`, for mechanisms with a
hub layout (:data:`vjm_ros.core.kernels.HUB_SOLVES`)."""
