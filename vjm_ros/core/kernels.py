"""Compiled kernels behind :class:`vjm_ros.core.mechanism.Mechanism`: the package's one source of the physics.

Kinematics, dynamics, closure rows, their enforcement and the fixed-step methods (checked against
the independent numpy formulation in ``test/oracle/``), written as scalar loops over the links so that numba compiles them to
machine code (``cache=True``: compiled once per machine, then loaded from the cache). Without numba
the same functions run as plain Python, which is correct but slow.

Recursions (docs/design.md section 1), link ``i`` after link ``i - 1`` of its chain, or after the chain's
ground link when it is the first one:

* ``theta_pred_i = theta_(i-1)`` and ``theta_i = theta_pred_i + phi_i``;
* ``d_i = a_pred u(theta_pred_i) + B_i n(theta_pred_i)`` and ``O_i = O_(i-1) + d_i``;
* ``v_i = v_(i-1) + omega_pred e_z x d_i + Bdot_i n(theta_pred_i)``;
* ``a_i = a_(i-1) - omega_pred^2 d_i - 2 omega_pred Bdot_i u(theta_pred_i)`` (at ``qdd = 0``).

A point ``P`` on link ``i`` moves with joint ``k`` of the same chain (``k <= i``) as
``e_z x (P - O_k)`` (revolute) or ``n(theta_pred_k)`` (prismatic). The mass matrix is
``sum_i m_i J_i^T J_i + I_i Jw_i^T Jw_i``, the bias ``sum_i J_i^T m_i (Jdot_i qdot - g)``.

The entry points are named for what they compute (:func:`evaluate`, :func:`residual`,
:func:`implicit_velocity`, :func:`advance`, :func:`project`); each takes the packed model
(:class:`PackedModel`, read-only, shareable between threads) and a workspace (:class:`Data`, one
per thread) and calls the one compiled kernel, :func:`step`, so that numba compiles the physics
once (a few seconds on first use, then loaded from its cache in a fraction of a second).

Model and method arrays (fields of :class:`PackedModel`, built by
:func:`vjm_ros.core.packing.pack_model`):

* ``lint`` int64 (n, 3): revolute flag, first-of-chain flag, index of the chain's first link;
* ``lflt`` float64 (n, 10): base angle (rad), base origin x, y (m), predecessor length (m), locked
  angle (rad), locked slide (m), mass (kg), inertia (kg m^2), mass-centre offsets ``p``, ``q`` (m);
* ``cint`` int64 (k, 4): closure kind (:data:`HINGE`, :data:`SLIDER`, :data:`ANGLE`), link of
  ``Pa``, link of the target (``-1``: ground), first row;
* ``cflt`` float64 (k, 7): local ``(s, w)`` of ``Pa`` and of the target (m), line direction,
  angle offset (rad);
* ``gains`` float64 (r, 2): penalty ``Kp``, ``Kv`` per row (ignored by the exact method);
* ``par`` float64 (6,): method (0 penalty, 1 exact), Baumgarte ``alpha``, ``beta`` (1/s),
  ``rcond``, gravity ``gx``, ``gy`` (m/s^2).

Output buffers (fields of :class:`Data`; columns named by the ``K_*``, ``C_*`` and ``R_*``
constants):

* ``kin`` (n + 1, 15): per link ``theta``, ``cos``, ``sin``, origin, ``omega``, origin velocity and
  bias acceleration, then ``cos``/``sin`` of the predecessor angle, the slide ``B``, the
  predecessor's ``omega`` and the slide rate; the last row is the ground;
* ``mm`` (n, n), ``bias`` (n,): ``M`` and ``b`` with ``M qdd + b = tau``;
* ``cm`` (n, 4): mass centres (m) and their velocities (m/s);
* ``crow`` (r, 7): ``C``, ``Cdot``, ``Adot qd``, row force (N or N m), world-frame force direction
  ``(Fx, Fy, Mz)`` of a unit row force;
* ``jac`` (r, n): ``A``; ``points`` (k, 2): application point ``Pa`` of each closure, m.

The entry points return a status: 0 on success, 1 when a matrix was exactly singular (the case in which
``numpy.linalg.solve`` raises ``LinAlgError``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from vjm_ros.core.hub_linalg import N_HUB_COLUMNS, hub_correction, hub_implicit_solve
from vjm_ros.core.small_linalg import (
    lu_factor_blocks,
    lu_factor_range,
    lu_solve_blocks,
    lu_solve_range,
    min_norm_correction,
)
from vjm_ros.jit import HAVE_NUMBA  # noqa: F401  (HAVE_NUMBA: part of this module's interface)
from vjm_ros.jit import jit as _jit
from vjm_ros.jit import variant as _variant

HINGE = 0
SLIDER = 1
ANGLE = 2

PENALTY = 0
EXACT = 1

# operations of step()
EXPLICIT_EULER = 0
SEMI_IMPLICIT_EULER = 1
RK4 = 2
IMPLICIT_EULER = 3
EVALUATE = 4
IMPLICIT_VELOCITY = 5
RESIDUAL = 6
PROJECT = 7
THEN_EVALUATE = 16
"""Added to a fixed-step method's ``op`` in :func:`step`: after the last step, one evaluation at
the end state, as :data:`EVALUATE` would make it in a call of its own (the same numbers; the
acceleration into ``known[row + 1]``, the terms in the buffers, the energies in ``kin``'s ground
row), saving a second call per observed tick (for a one-link chain, a call costs as much as the
step's arithmetic: some 35 arrays are passed field by field)."""

B16 = 1.0 / 6.0
B13 = 1.0 / 3.0

# columns of lint
L_REV, L_FIRST, L_START = 0, 1, 2
# columns of lflt
F_BASE_ANGLE, F_BASE_X, F_BASE_Y, F_PRED_LEN, F_LOCK_ANGLE, F_LOCK_SLIDE = 0, 1, 2, 3, 4, 5
F_MASS, F_INERTIA, F_COM_P, F_COM_Q = 6, 7, 8, 9
N_LFLT = 10
# entries of par
P_METHOD, P_ALPHA, P_BETA, P_RCOND, P_GX, P_GY = 0, 1, 2, 3, 4, 5
N_PAR = 6
# columns of kin
K_THETA, K_COS, K_SIN, K_OX, K_OY, K_OMEGA, K_VX, K_VY, K_AX, K_AY = range(10)
K_PCOS, K_PSIN, K_SLIDE, K_POMEGA, K_SLIDE_RATE = range(10, 15)
N_KIN = 15
# columns of cm
C_X, C_Y, C_VX, C_VY = range(4)
N_CM = 4
# columns of crow
R_RES, R_RATE, R_BIAS, R_FORCE, R_DX, R_DY, R_DZ = range(7)
N_CROW = 7


# ---------------------------------------------------------------------------------- geometry
@_jit(allocates=False)
def point_motion(kin, link, s, w):
    """Position, velocity and bias acceleration of the point ``(s, w)`` of ``link``.

    Returns
    -------
    tuple of float
        ``px, py`` (m), ``vx, vy`` (m/s), ``ax, ay`` (m/s^2). ``link = -1`` is the ground:
        ``(s, w)`` is then the world position.
    """
    if link < 0:
        return s, w, 0.0, 0.0, 0.0, 0.0
    c = kin[link, K_COS]
    sn = kin[link, K_SIN]
    rx = c * s - sn * w
    ry = sn * s + c * w
    om = kin[link, K_OMEGA]
    return (
        kin[link, K_OX] + rx,
        kin[link, K_OY] + ry,
        kin[link, K_VX] - om * ry,
        kin[link, K_VY] + om * rx,
        kin[link, K_AX] - om * om * rx,
        kin[link, K_AY] - om * om * ry,
    )


@_jit(allocates=False)
def add_point_jacobian(jac, row, cx, cy, link, px, py, lint, kin):
    """Add ``cx dPx/dq + cy dPy/dq`` of the point ``P = (px, py)`` of ``link`` to ``jac[row]``.

    Nothing is added for the ground (``link = -1``).
    """
    if link < 0:
        return
    for k in range(lint[link, L_START], link + 1):
        if lint[k, L_REV] == 1:
            jx = -(py - kin[k, K_OY])
            jy = px - kin[k, K_OX]
        else:
            jx = -kin[k, K_PSIN]
            jy = kin[k, K_PCOS]
        jac[row, k] += cx * jx + cy * jy


@_jit(allocates=False)
def add_angle_jacobian(jac, row, sign, link, lint):
    """Add ``sign * d theta_link / dq`` to ``jac[row]`` (nothing for the ground)."""
    if link < 0:
        return
    for k in range(lint[link, L_START], link + 1):
        if lint[k, L_REV] == 1:
            jac[row, k] += sign


@_jit(allocates=False)
def _com_column(lint, kin, k, cx, cy):
    """Column ``k`` of a point's translational Jacobian at ``(cx, cy)``: ``z x (P - O_k)`` for a
    revolute coordinate, the slide direction for a prismatic one."""
    if lint[k, L_REV] == 1:
        return -(cy - kin[k, K_OY]), cx - kin[k, K_OX]
    return -kin[k, K_PSIN], kin[k, K_PCOS]


@_jit(allocates=False)
def terms(q, qd, lint, lflt, cint, cflt, par, with_dynamics, kin, mm, bias, cm, crow, jac,
          points):
    """Kinematics, dynamics and closure rows at ``(q, qd)`` into the output buffers.

    With ``with_dynamics`` False only ``kin`` and the residual, rate and direction columns of
    ``crow`` are filled (``M``, ``b``, ``A`` and ``Adot qd`` are skipped).
    """
    n = q.shape[0]
    # chain recursion
    for i in range(n):
        if lint[i, L_FIRST] == 1:
            tp = lflt[i, F_BASE_ANGLE]
            ox = lflt[i, F_BASE_X]
            oy = lflt[i, F_BASE_Y]
            wp = 0.0
            vx = 0.0
            vy = 0.0
            ax = 0.0
            ay = 0.0
        else:
            tp = kin[i - 1, K_THETA]
            ox = kin[i - 1, K_OX]
            oy = kin[i - 1, K_OY]
            wp = kin[i - 1, K_OMEGA]
            vx = kin[i - 1, K_VX]
            vy = kin[i - 1, K_VY]
            ax = kin[i - 1, K_AX]
            ay = kin[i - 1, K_AY]
        if lint[i, L_REV] == 1:
            phi = q[i]
            b = lflt[i, F_LOCK_SLIDE]
            phid = qd[i]
            bd = 0.0
        else:
            phi = lflt[i, F_LOCK_ANGLE]
            b = q[i]
            phid = 0.0
            bd = qd[i]
        cp = math.cos(tp)
        sp = math.sin(tp)
        a = lflt[i, F_PRED_LEN]
        dx = a * cp - b * sp
        dy = a * sp + b * cp
        t = tp + phi
        kin[i, K_THETA] = t
        kin[i, K_COS] = math.cos(t)
        kin[i, K_SIN] = math.sin(t)
        kin[i, K_OX] = ox + dx
        kin[i, K_OY] = oy + dy
        kin[i, K_OMEGA] = wp + phid
        kin[i, K_VX] = vx - wp * dy - bd * sp
        kin[i, K_VY] = vy + wp * dx + bd * cp
        kin[i, K_AX] = ax - wp * wp * dx - 2.0 * wp * bd * cp
        kin[i, K_AY] = ay - wp * wp * dy - 2.0 * wp * bd * sp
        kin[i, K_PCOS] = cp
        kin[i, K_PSIN] = sp
        kin[i, K_SLIDE] = b
        kin[i, K_POMEGA] = wp
        kin[i, K_SLIDE_RATE] = bd
    for j in range(N_KIN):
        kin[n, j] = 0.0
    kin[n, K_COS] = 1.0

    # mass matrix and bias: sum over links of m J^T J + I Jw^T Jw and J^T m (Jdot qd - g)
    if with_dynamics:
        for k in range(n):
            bias[k] = 0.0
            for j in range(n):
                mm[k, j] = 0.0
        for i in range(n):
            cx, cy, vcx, vcy, acx, acy = point_motion(kin, i, lflt[i, F_COM_P], lflt[i, F_COM_Q])
            cm[i, C_X] = cx
            cm[i, C_Y] = cy
            cm[i, C_VX] = vcx
            cm[i, C_VY] = vcy
            m = lflt[i, F_MASS]
            inertia = lflt[i, F_INERTIA]
            fx = m * (acx - par[P_GX])
            fy = m * (acy - par[P_GY])
            start = lint[i, L_START]
            for k in range(start, i + 1):
                jxk, jyk = _com_column(lint, kin, k, cx, cy)
                bias[k] += jxk * fx + jyk * fy
                for j in range(start, k + 1):
                    jxj, jyj = _com_column(lint, kin, j, cx, cy)
                    v = m * (jxk * jxj + jyk * jyj)
                    if lint[k, L_REV] == 1 and lint[j, L_REV] == 1:
                        v += inertia
                    mm[k, j] += v
        for k in range(n):
            for j in range(k + 1, n):
                mm[k, j] = mm[j, k]

    # closure rows
    r = crow.shape[0]
    for i in range(r):
        for j in range(N_CROW):
            crow[i, j] = 0.0
        for j in range(n):
            jac[i, j] = 0.0
    for c in range(cint.shape[0]):
        kind = cint[c, 0]
        la = cint[c, 1]
        lb = cint[c, 2]
        row = cint[c, 3]
        pax, pay, vax, vay, aax, aay = point_motion(kin, la, cflt[c, 0], cflt[c, 1])
        pbx, pby, vbx, vby, abx, aby = point_motion(kin, lb, cflt[c, 2], cflt[c, 3])
        points[c, 0] = pax
        points[c, 1] = pay
        if kind == HINGE:
            crow[row, R_RES] = pax - pbx
            crow[row + 1, R_RES] = pay - pby
            crow[row, R_RATE] = vax - vbx
            crow[row + 1, R_RATE] = vay - vby
            crow[row, R_DX] = 1.0
            crow[row + 1, R_DY] = 1.0
            if with_dynamics:
                add_point_jacobian(jac, row, 1.0, 0.0, la, pax, pay, lint, kin)
                add_point_jacobian(jac, row, -1.0, 0.0, lb, pbx, pby, lint, kin)
                add_point_jacobian(jac, row + 1, 0.0, 1.0, la, pax, pay, lint, kin)
                add_point_jacobian(jac, row + 1, 0.0, -1.0, lb, pbx, pby, lint, kin)
                crow[row, R_BIAS] = aax - abx
                crow[row + 1, R_BIAS] = aay - aby
        elif kind == SLIDER:
            # line through Pb with direction d (turning with link lb), normal nd = e_z x d
            if lb < 0:
                c0 = 1.0
                s0 = 0.0
                w = 0.0
            else:
                c0 = kin[lb, K_COS]
                s0 = kin[lb, K_SIN]
                w = kin[lb, K_OMEGA]
            dx = c0 * cflt[c, 4] - s0 * cflt[c, 5]
            dy = s0 * cflt[c, 4] + c0 * cflt[c, 5]
            nx = -dy
            ny = dx
            px = pax - pbx
            py = pay - pby
            vx = vax - vbx
            vy = vay - vby
            along = px * dx + py * dy
            res = px * nx + py * ny
            crow[row, R_RES] = res
            crow[row, R_RATE] = (vx * nx + vy * ny) - w * along
            crow[row, R_DX] = nx
            crow[row, R_DY] = ny
            if with_dynamics:
                add_point_jacobian(jac, row, nx, ny, la, pax, pay, lint, kin)
                add_point_jacobian(jac, row, -nx, -ny, lb, pbx, pby, lint, kin)
                add_angle_jacobian(jac, row, -along, lb, lint)
                crow[row, R_BIAS] = (
                    ((aax - abx) * nx + (aay - aby) * ny)
                    - 2.0 * w * (vx * dx + vy * dy)
                    - w * w * res
                )
        else:
            diff = kin[la, K_THETA] - kin[lb, K_THETA] - cflt[c, 6]
            crow[row, R_RES] = (diff + math.pi) % (2.0 * math.pi) - math.pi
            crow[row, R_RATE] = kin[la, K_OMEGA] - kin[lb, K_OMEGA]
            crow[row, R_DZ] = 1.0
            if with_dynamics:
                add_angle_jacobian(jac, row, 1.0, la, lint)
                add_angle_jacobian(jac, row, -1.0, lb, lint)


# ---------------------------------------------------------------------------------- model and data
class PackedModel(NamedTuple):
    """The model and its closure method as the kernels read them (layouts in the module
    docstring), built by :func:`vjm_ros.core.packing.pack_model`. The kernels never write it:
    one value serves every thread.

    Attributes
    ----------
    lint : ndarray of int64, shape (n, 3)
    lflt : ndarray, shape (n, 10)
    cint : ndarray of int64, shape (k, 4)
    cflt : ndarray, shape (k, 7)
    gains : ndarray, shape (r, 2)
    par : ndarray, shape (6,)
    blocks : ndarray of int64, shape (nb + 1,)
        Boundaries ``0, ..., n`` of the mass matrix's diagonal blocks, one per chain
        (:func:`vjm_ros.core.packing.chain_blocks`).
    """

    lint: np.ndarray
    lflt: np.ndarray
    cint: np.ndarray
    cflt: np.ndarray
    gains: np.ndarray
    par: np.ndarray
    blocks: np.ndarray


class Data(NamedTuple):
    """What the kernels write: the terms of the last evaluation and the scratch arrays of the
    solves (:func:`make_data`). One per thread; nothing is allocated per call.

    Attributes
    ----------
    kin, mm, bias, cm, crow, jac, points : ndarray
        The terms of the last evaluation, shapes (n + 1, 15), (n, n), (n,), (n, 4), (r, 7),
        (r, n), (k, 2) (module docstring).
    lu : ndarray, shape (n, n)
        LU factors of ``M`` (or of ``M + h A^T W A``).
    piv : ndarray of int64, shape (n,)
        Their pivots.
    minv_at : ndarray, shape (n, r)
        ``M^-1 A^T``.
    g, v : ndarray, shape (r, r)
        ``A M^-1 A^T`` and its eigenvectors.
    vec : ndarray, shape (3 + r + nh, max(n, r, nh + 1))
        Vectors of the solves (row 0: the multipliers; ``nh`` the hub chain's size).
    rhs : ndarray, shape (r,)
        Right-hand side of the closure solves.
    corr : ndarray, shape (n,)
        The correction they give.
    ks, vs : ndarray, shape (4, n)
        Stage accelerations and velocities of a step.
    qi : ndarray, shape (n,)
        Stage coordinates.
    scratch : ndarray, shape (n,)
        Accelerations of a step's stage.
    spare : ndarray, shape (n,)
        Unread second output of the entry points that have one output.
    zero : ndarray, shape (n,)
        Zeros (the rates of the evaluations without any).
    touch : ndarray of int64, shape (r, max(nb, 1))
        Diagonal blocks each closure row touches.
    layout : ndarray of int64, shape (r + 1, c)
        The closure layout (:func:`vjm_ros.core.packing.closure_layout`, a copy: the hub solves
        write its scratch columns).
    """

    kin: np.ndarray
    mm: np.ndarray
    bias: np.ndarray
    cm: np.ndarray
    crow: np.ndarray
    jac: np.ndarray
    points: np.ndarray
    lu: np.ndarray
    piv: np.ndarray
    minv_at: np.ndarray
    g: np.ndarray
    v: np.ndarray
    vec: np.ndarray
    rhs: np.ndarray
    corr: np.ndarray
    ks: np.ndarray
    vs: np.ndarray
    qi: np.ndarray
    scratch: np.ndarray
    spare: np.ndarray
    zero: np.ndarray
    touch: np.ndarray
    layout: np.ndarray


def output_shapes(model: PackedModel) -> tuple[tuple[int, ...], ...]:
    """Shapes of ``kin, mm, bias, cm, crow, jac, points`` for ``model``."""
    n, r, k = model.lint.shape[0], model.gains.shape[0], model.cint.shape[0]
    return ((n + 1, N_KIN), (n, n), (n,), (n, N_CM), (r, N_CROW), (r, n), (k, 2))


def make_data(model: PackedModel, layout: np.ndarray | None = None) -> Data:
    """A workspace of the kernels for ``model`` (built in Python once per mechanism and thread:
    compiled callers receive it, so nothing is allocated per call).

    Parameters
    ----------
    model : PackedModel
    layout : ndarray of int64, optional
        :func:`vjm_ros.core.packing.closure_layout` (copied); omitted, no hub layout (the dense
        solves).
    """
    n, r = model.lint.shape[0], model.gains.shape[0]
    blocks = model.blocks
    if layout is None:
        layout = np.zeros((r + 1, N_HUB_COLUMNS), dtype=np.int64)
        layout[r, 0] = -1
    lay = np.array(layout, dtype=np.int64)
    hub = lay[r, 0]
    nh = int(blocks[hub + 1] - blocks[hub]) if hub >= 0 else 0
    m = max(n, r, nh + 1)
    outputs = [np.empty(shape) for shape in output_shapes(model)]
    return Data(*outputs, lu=np.empty((n, n)), piv=np.empty(n, dtype=np.int64),
                minv_at=np.empty((n, r)), g=np.empty((r, r)), v=np.empty((r, r)),
                vec=np.zeros((3 + r + nh, m)), rhs=np.empty(r), corr=np.empty(n),
                ks=np.zeros((4, n)), vs=np.zeros((4, n)), qi=np.empty(n), scratch=np.empty(n),
                spare=np.empty(n), zero=np.zeros(n),
                touch=np.zeros((r, max(len(blocks) - 1, 1)), dtype=np.int64), layout=lay)


# ---------------------------------------------------------------------------------- entry points
NO_KNOWN = np.empty((0, 0))
"""``known`` argument of :func:`step` when no acceleration is known."""
NO_ROW = -1
"""``row`` argument of :func:`step` when no acceleration is known."""
ONE_STEP = 1
"""``steps`` argument of :func:`step` for one evaluation."""
PROJECTION_STEPS = 8
"""``steps`` argument of :func:`step` for a projection after a tick: Gauss-Newton steps at most.

Compiled callers pass the integer arguments of :func:`step` as attributes of this module
(``K.NO_ROW``), typed ``int64``, never as literals or as globals of their own module: numba types
those as ``Literal[int](-1)`` and compiles a whole extra copy of :func:`step` for each such
signature (seconds each on a cold cache)."""


def as_arguments(value: PackedModel | Data) -> tuple:
    """A :class:`PackedModel` or :class:`Data` as the plain tuple of its fields that the compiled
    functions take: numba types a plain tuple of arrays in its dispatcher's C code, a named one
    in Python (some 3 µs more per call of :func:`step` from Python, measured on the four-bar)."""
    return tuple(value)


def evaluate(model: PackedModel, data: Data, q: np.ndarray, qd: np.ndarray, tau: np.ndarray,
             qdd: np.ndarray, kernel=None) -> int:
    """Every term at ``(q, qd)`` into ``data`` and the accelerations with efforts ``tau``.

    Parameters
    ----------
    model : PackedModel
    data : Data
        Receives the terms; the ground row of ``kin`` the kinetic, potential and penalty energy
        (J) in columns :data:`K_PCOS`, :data:`K_PSIN`, :data:`K_SLIDE`.
    q, qd, tau : ndarray, shape (n,)
        State (rad or m, rad/s or m/s) and efforts (N m or N); not modified.
    qdd : ndarray, shape (n,)
        Receives the accelerations, rad/s^2 or m/s^2.
    kernel : callable, optional
        :func:`step` (the default) or a copy of it (:data:`step_with_hub`, a tiered entry).

    Returns
    -------
    int
        0, or 1 when a matrix was exactly singular.
    """
    return (kernel or step)(EVALUATE, q, qd, tau, 0.0, ONE_STEP, 0.0, tuple(model), tuple(data),
                            qdd, data.spare, NO_KNOWN, NO_ROW)


def residual(model: PackedModel, data: Data, q: np.ndarray, kernel=None) -> int:
    """Closure residuals at ``q`` with zero rates, without the dynamics or the Jacobian, into
    ``data.kin`` and ``data.crow`` (columns :data:`R_RES`, :data:`R_DX` .. :data:`R_DZ`)."""
    return (kernel or step)(RESIDUAL, q, q, q, 0.0, ONE_STEP, 0.0, tuple(model), tuple(data),
                            data.spare, data.spare, NO_KNOWN, NO_ROW)


def implicit_velocity(model: PackedModel, data: Data, q: np.ndarray, qd: np.ndarray,
                      tau: np.ndarray, h: float, v: np.ndarray, kernel=None) -> int:
    """``v``, the velocity after a step of length ``h`` (s) implicit in the penalty forces
    (``qd + h qdd`` for exact closures); arguments and status as :func:`evaluate`."""
    return (kernel or step)(IMPLICIT_VELOCITY, q, qd, tau, h, ONE_STEP, 0.0, tuple(model),
                            tuple(data), v, data.spare, NO_KNOWN, NO_ROW)


def advance(model: PackedModel, data: Data, method: int, q: np.ndarray, qd: np.ndarray,
            tau: np.ndarray, h: float, steps: int, q_out: np.ndarray, qd_out: np.ndarray,
            kernel=None) -> int:
    """``steps`` steps of length ``h`` (s) of a fixed-step method from ``(q, qd)``, efforts
    held, into ``(q_out, qd_out)``.

    ``method`` is :data:`EXPLICIT_EULER`, :data:`SEMI_IMPLICIT_EULER`, :data:`RK4` or
    :data:`IMPLICIT_EULER` (:mod:`vjm_ros.core.integrators.fixed`); ``data`` holds the terms of
    the last stage. Status as :func:`evaluate`.
    """
    return (kernel or step)(method, q, qd, tau, h, steps, 0.0, tuple(model), tuple(data), q_out,
                            qd_out, NO_KNOWN, NO_ROW)


def project(model: PackedModel, data: Data, q: np.ndarray, qd: np.ndarray, steps: int,
            tol: float, q_out: np.ndarray, qd_out: np.ndarray, kernel=None) -> int:
    """``(q, qd)`` projected onto the closures, into ``(q_out, qd_out)``: at most ``steps``
    Gauss-Newton steps in the metric of ``M`` until ``max |C| <= tol`` (m or rad), then one
    velocity projection (``rcond = 1e-10``), as
    :meth:`vjm_ros.core.mechanism.Mechanism.project`. Status as :func:`evaluate`."""
    return (kernel or step)(PROJECT, q, qd, data.zero, 0.0, steps, tol, tuple(model),
                            tuple(data), q_out, qd_out, NO_KNOWN, NO_ROW)


HUB_SOLVES = False
"""Whether a compiled copy of :func:`step` holds the hub solves of :mod:`vjm_ros.core.hub_linalg`.

A module constant, so numba drops the branches it guards before typing them: :func:`step`
compiles none of the hub code (most mechanisms have no hub layout, and that code would add
about 4 s to a cold compile), :data:`step_with_hub` is the copy with it, for mechanisms whose
workspace has a hub layout (:meth:`vjm_ros.core.mechanism.Mechanism` picks). Given a hub layout,
:func:`step` solves densely: the same results to round-off."""


@_jit(allocates=False)
def step(op, q0, qd0, tau, h, steps, tol, model, data, out_a, out_b, known, row):
    """The one compiled kernel behind the entry points above: ``op`` says what it computes.

    numba compiles this one function (with its copies :data:`step_with_hub`, :data:`step_inline`)
    rather than one per entry point: each copy holds the whole physics and takes seconds to
    compile on a cold cache and tens of ms to load from it.

    Parameters
    ----------
    op : int
        * :data:`EVALUATE` (:func:`evaluate`): every term at ``(q0, qd0)``, ``out_a = qdd``;
        * :data:`IMPLICIT_VELOCITY` (:func:`implicit_velocity`): ``out_a = v``;
        * :data:`EXPLICIT_EULER`, :data:`SEMI_IMPLICIT_EULER`, :data:`RK4`,
          :data:`IMPLICIT_EULER` (:func:`advance`): ``steps`` steps of length ``h``;
          ``(out_a, out_b) = (q, qd)`` at the end; plus :data:`THEN_EVALUATE`, followed by an
          evaluation at the end state into ``known[row + 1]``;
        * :data:`RESIDUAL` (:func:`residual`): closure residuals at ``q0`` with zero rates;
        * :data:`PROJECT` (:func:`project`): ``(out_a, out_b)`` the projected ``(q, qd)``, at
          most ``steps`` Gauss-Newton steps, tolerance ``tol``.
    q0, qd0, tau : ndarray, shape (n,)
        Not modified.
    h : float
    steps : int
    tol : float
    model : tuple
        A :class:`PackedModel`'s fields, as a plain tuple (:func:`as_arguments`).
    data : tuple
        A :class:`Data`'s fields, as a plain tuple; it holds the terms of the last evaluation on
        return.
    out_a, out_b : ndarray, shape (n,)
    known : ndarray, shape (rows, n)
        ``known[row]``, for a fixed-step method and ``row >= 0``: the acceleration at
        ``(q0, qd0)`` with ``tau``, which the caller has just evaluated with :data:`EVALUATE`
        into the same ``data``: the first stage of the first step then reuses both, the same
        numbers with one evaluation fewer (:data:`IMPLICIT_EULER` builds its system from the
        buffers); ``row = -1`` (:data:`NO_ROW`, ``known`` :data:`NO_KNOWN`): nothing known.

    Returns
    -------
    int
        0, or 1 when a matrix was exactly singular.
    """
    lint, lflt, cint, cflt, gains, par, blocks = model
    (kin, mm, bias, cm, crow, jac, points, lu, piv, minv_at, g, v, vec, rhs, corr, ks, vs, qi,
     scratch, _, zero, touch, lay) = data
    n = q0.shape[0]
    r = crow.shape[0]
    then_evaluate = op >= THEN_EVALUATE
    if then_evaluate:
        op = op - THEN_EVALUATE
    q = out_a
    qd = out_b
    for j in range(n):
        q[j] = q0[j]
        qd[j] = qd0[j]
    exact = par[P_METHOD] == EXACT and r > 0
    full = op != RESIDUAL  # a run-time flag: one compiled copy of terms() serves every call
    status = 0

    if not full:
        terms(q, zero, lint, lflt, cint, cflt, par, full, kin, mm, bias, cm, crow, jac,
              points)
        return 0

    if op == PROJECT:
        for it in range(steps + 1):
            terms(q, zero, lint, lflt, cint, cflt, par, full, kin, mm, bias, cm, crow, jac,
                  points)
            worst = 0.0
            for i in range(r):
                worst = max(worst, abs(crow[i, R_RES]))
            position = it < steps and not worst <= tol
            for i in range(r):
                if position:
                    rhs[i] = crow[i, R_RES]
                else:
                    s = 0.0
                    for j in range(n):
                        s += jac[i, j] * qd0[j]
                    rhs[i] = s
            for i in range(n):
                for j in range(n):
                    lu[i, j] = mm[i, j]
            status = max(status, lu_factor_blocks(lu, piv, blocks))
            solved = False
            if HUB_SOLVES:
                solved = lay[r, 0] >= 0 and hub_correction(lu, piv, jac, rhs, 1e-10, corr,
                                                           minv_at, g, v, vec, blocks, lay)
            if not solved:
                min_norm_correction(lu, piv, jac, rhs, 1e-10, corr, minv_at, g, v, vec, blocks,
                                    touch)
            if position:
                for j in range(n):
                    q[j] = q[j] - corr[j]
            else:
                for j in range(n):
                    qd[j] = qd0[j] - corr[j]
                break
        return status

    reuse = row >= 0 and (op == RK4 or op == EXPLICIT_EULER or op == SEMI_IMPLICIT_EULER
                          or op == IMPLICIT_EULER)
    single = op == EVALUATE or op == IMPLICIT_VELOCITY
    stages = 4 if op == RK4 else 1
    total = 1 if single else steps * stages + (1 if then_evaluate else 0)
    # ks: stage accelerations, vs: stage velocities
    acc = out_a if single else scratch
    for it in range(total):
        last = then_evaluate and it == total - 1  # the evaluation at the end state
        stage = 0 if last else it % stages
        if last:
            acc = known[row + 1]
        if stage == 0:
            for j in range(n):
                qi[j] = q[j]
                vs[0, j] = qd[j]
        else:
            cst = 1.0 if stage == 3 else 0.5
            for j in range(n):
                qi[j] = q[j] + h * (cst * vs[stage - 1, j])
                vs[stage, j] = qd[j] + h * (cst * ks[stage - 1, j])
        if reuse and it == 0 and not last:
            for j in range(n):  # the caller evaluated this very state: the same numbers
                acc[j] = known[row, j]
        else:
            terms(qi, vs[stage], lint, lflt, cint, cflt, par, full, kin, mm, bias, cm, crow, jac,
                  points)

            # open-chain force Q = tau - b, plus A^T F for penalty closures; then qdd = M^-1 (...)
            for i in range(n):
                for j in range(n):
                    lu[i, j] = mm[i, j]
            status = max(status, lu_factor_blocks(lu, piv, blocks))
            if not exact:
                for i in range(r):
                    crow[i, R_FORCE] = -(gains[i, 0] * crow[i, R_RES] + gains[i, 1] * crow[i, R_RATE])
            for j in range(n):
                s = tau[j] - bias[j]
                if not exact:
                    t = 0.0
                    for i in range(r):
                        t += jac[i, j] * crow[i, R_FORCE]
                    s = s + t
                acc[j] = s
            lu_solve_blocks(lu, piv, acc, blocks)
            if exact:
                # A M^-1 A^T lambda = -(A M^-1 Q + Adot qd + 2 alpha Cdot + beta^2 C)
                two_alpha = 2.0 * par[P_ALPHA]
                beta2 = par[P_BETA] * par[P_BETA]
                for i in range(r):
                    s = 0.0
                    for j in range(n):
                        s += jac[i, j] * acc[j]
                    rhs[i] = -(s + crow[i, R_BIAS] + two_alpha * crow[i, R_RATE]
                               + beta2 * crow[i, R_RES])
                solved = False
                if HUB_SOLVES:
                    solved = lay[r, 0] >= 0 and hub_correction(lu, piv, jac, rhs, par[P_RCOND],
                                                               corr, minv_at, g, v, vec, blocks,
                                                               lay)
                if not solved:
                    min_norm_correction(lu, piv, jac, rhs, par[P_RCOND], corr, minv_at, g, v,
                                        vec, blocks, touch)
                for i in range(r):
                    crow[i, R_FORCE] = vec[0, i]
                for j in range(n):
                    acc[j] += corr[j]
        if op == EVALUATE or last:
            kinetic = 0.0
            potential = 0.0
            for i in range(n):
                mass = lflt[i, F_MASS]
                kinetic += mass * (cm[i, C_VX] * cm[i, C_VX] + cm[i, C_VY] * cm[i, C_VY])
                kinetic += lflt[i, F_INERTIA] * kin[i, K_OMEGA] * kin[i, K_OMEGA]
                potential -= mass * (cm[i, C_X] * par[P_GX] + cm[i, C_Y] * par[P_GY])
            spring = 0.0
            if par[P_METHOD] == PENALTY:
                for i in range(r):
                    spring += gains[i, 0] * crow[i, R_RES] * crow[i, R_RES]
            kin[n, K_PCOS] = 0.5 * kinetic
            kin[n, K_PSIN] = potential
            kin[n, K_SLIDE] = 0.5 * spring
            return status

        if op == IMPLICIT_VELOCITY or op == IMPLICIT_EULER:
            if exact or par[P_METHOD] == EXACT:
                for j in range(n):
                    acc[j] = qd[j] + h * acc[j]
            else:
                # (M + h A^T (h Kp + Kv) A) dv = h (Q + A^T (F - h Kp A v))
                for i in range(r):
                    s = 0.0
                    for j in range(n):
                        s += jac[i, j] * qd[j]
                    rhs[i] = crow[i, R_FORCE] - h * gains[i, 0] * s
                    vec[2, i] = h * gains[i, 0] + gains[i, 1]
                hub = False  # True: the block elimination of hub_implicit_solve
                if HUB_SOLVES:
                    hub = lay[r, 0] >= 0
                for k in range(n):
                    if not hub:
                        for j in range(n):
                            s = 0.0
                            for i in range(r):
                                s += jac[i, k] * vec[2, i] * jac[i, j]
                            lu[k, j] = mm[k, j] + h * s
                    s = 0.0
                    for i in range(r):
                        s += jac[i, k] * rhs[i]
                    acc[k] = h * (tau[k] - bias[k] + s)
                if HUB_SOLVES:
                    if hub:
                        status = max(status, hub_implicit_solve(mm, lu, piv, jac, vec[2], h, acc,
                                                                vec[1], blocks, lay))
                if not hub:
                    # blocks[0] = 0, typed int64: a literal 0 would compile another copy
                    status = max(status, lu_factor_range(lu, piv, blocks[0], n))
                    lu_solve_range(lu, piv, acc, blocks[0], n)
                for j in range(n):
                    acc[j] += qd[j]
            if op == IMPLICIT_VELOCITY:
                return status
            for j in range(n):
                qd[j] = acc[j]
                q[j] = q[j] + h * qd[j]
        elif op == EXPLICIT_EULER:
            for j in range(n):
                q[j] = q[j] + h * qd[j]
                qd[j] = qd[j] + h * acc[j]
        elif op == SEMI_IMPLICIT_EULER:
            for j in range(n):
                qd[j] = qd[j] + h * acc[j]
                q[j] = q[j] + h * qd[j]
        else:
            for j in range(n):
                ks[stage, j] = acc[j]
            if stage == 3:
                for j in range(n):
                    q[j] = q[j] + h * (
                        B16 * vs[0, j] + B13 * vs[1, j] + B13 * vs[2, j] + B16 * vs[3, j]
                    )
                    qd[j] = qd[j] + h * (
                        B16 * ks[0, j] + B13 * ks[1, j] + B13 * ks[2, j] + B16 * ks[3, j]
                    )
    return status


step_with_hub = _variant(step, "step_with_hub", HUB_SOLVES=True)
""":func:`step` with the hub solves compiled in (:data:`HUB_SOLVES`)."""

step_inline = _variant(step, "step_inline", inline="always")
""":func:`step` inlined into its compiled caller: the block pipeline's call once per tick.

A call of :func:`step` passes its some 35 arrays field by field (about 280 machine words) and
the callee reloads them; inlined, the tick's step works on the caller's arrays directly. Measured
in one sitting (per tick, blocks of 1000): one link with ``semi_implicit_euler`` 0.50 -> 0.23 µs
(the bare step in one call: 0.22), ``implicit_euler`` 0.50 -> 0.28, ``rk4`` exact 1.74 -> 1.44;
the four-bar with ``rk4`` exact 3.19 -> 2.83 µs; the same numbers to the bit. The cost: the
pipeline compiles a second copy of the step's code (seconds, once per machine, in the
background on a first run: :mod:`vjm_ros.jit.tiers`)."""

step_with_hub_inline = _variant(step, "step_with_hub_inline", inline="always", HUB_SOLVES=True)
""":data:`step_with_hub` inlined into its compiled caller (:data:`step_inline`)."""
