"""The terms of a state: kinematics, mass matrix and bias, closure rows, as compiled loops.

Written as scalar loops over the links so that numba compiles them to machine code; called by
:func:`vjm_ros.core.kernels.step` (the one compiled kernel), never from Python.

Recursions (docs/design.md section 1), link ``i`` after link ``i - 1`` of its chain, or after the chain's
ground link when it is the first one:

* ``theta_pred_i = theta_(i-1)`` and ``theta_i = theta_pred_i + phi_i``;
* ``d_i = a_pred u(theta_pred_i) + B_i n(theta_pred_i)`` and ``O_i = O_(i-1) + d_i``;
* ``v_i = v_(i-1) + omega_pred e_z x d_i + Bdot_i n(theta_pred_i)``;
* ``a_i = a_(i-1) - omega_pred^2 d_i - 2 omega_pred Bdot_i u(theta_pred_i)`` (at ``qdd = 0``).

A point ``P`` on link ``i`` moves with joint ``k`` of the same chain (``k <= i``) as
``e_z x (P - O_k)`` (revolute) or ``n(theta_pred_k)`` (prismatic). The mass matrix is
``sum_i m_i J_i^T J_i + I_i Jw_i^T Jw_i``, the bias ``sum_i J_i^T m_i (Jdot_i qdot - g)``.

Layouts of the arrays read and written: :mod:`vjm_ros.core.layout`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from vjm_ros.core.layout import (
    C_VX,
    C_VY,
    C_X,
    C_Y,
    F_ARMATURE,
    F_BASE_ANGLE,
    F_BASE_X,
    F_BASE_Y,
    F_COM_P,
    F_COM_Q,
    F_DAMPING,
    F_FRICTION,
    F_FRICTION_SCALE,
    F_INERTIA,
    F_LOAD_A,
    F_LOAD_B,
    F_LOAD_FX,
    F_LOAD_FY,
    F_LOAD_TZ,
    F_LOCK_ANGLE,
    F_LOCK_SLIDE,
    F_MASS,
    F_PRED_LEN,
    HINGE,
    K_AX,
    K_AY,
    K_COS,
    K_OMEGA,
    K_OX,
    K_OY,
    K_PCOS,
    K_POMEGA,
    K_PSIN,
    K_SIN,
    K_SLIDE,
    K_SLIDE_RATE,
    K_THETA,
    K_VX,
    K_VY,
    L_FIRST,
    L_REV,
    L_START,
    N_CROW,
    N_KIN,
    P_GX,
    P_GY,
    P_PLANT,
    R_BIAS,
    R_DX,
    R_DY,
    R_DZ,
    R_RATE,
    R_RES,
    SLIDER,
)
from vjm_ros.jit import jit as _jit

if TYPE_CHECKING:
    import numpy as np


@_jit(allocates=False)
def point_motion(kin: np.ndarray, link: int, s: float, w: float
                 ) -> tuple[float, float, float, float, float, float]:
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
def add_point_jacobian(jac: np.ndarray, row: int, cx: float, cy: float, link: int, px: float,
                       py: float, lint: np.ndarray, kin: np.ndarray) -> None:
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
def add_angle_jacobian(jac: np.ndarray, row: int, sign: float, link: int,
                       lint: np.ndarray) -> None:
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
def plant_terms(qd: np.ndarray, lint: np.ndarray, lflt: np.ndarray, kin: np.ndarray,
                mm: np.ndarray, bias: np.ndarray) -> None:
    """Add the joints' armature to ``M``'s diagonal, their viscous damping (``b += c qd``) and
    smooth friction (``b += mu tanh(qd / v_s)``) to ``b``, and the generalized forces of the links' loads to ``b`` (``b -= Q``).

    The loads of link ``i`` act as the world force ``F`` at its origin ``O_i`` and the moment
    ``M_i = A cos(theta_i) + B sin(theta_i) + Tz`` (layout of ``lflt``): on a revolute
    coordinate ``k`` of the same chain, ``Q_k = (O_i - O_k) x F + M_i``; on a prismatic one,
    ``Q_k = n(theta_pred_k) . F``.
    """
    n = qd.shape[0]
    for k in range(n):
        mm[k, k] += lflt[k, F_ARMATURE]
        bias[k] += lflt[k, F_DAMPING] * qd[k]
        if lflt[k, F_FRICTION_SCALE] > 0.0:  # smooth Coulomb friction
            bias[k] += lflt[k, F_FRICTION] * math.tanh(qd[k] / lflt[k, F_FRICTION_SCALE])
    for i in range(n):
        fx = lflt[i, F_LOAD_FX]
        fy = lflt[i, F_LOAD_FY]
        moment = (lflt[i, F_LOAD_A] * kin[i, K_COS] + lflt[i, F_LOAD_B] * kin[i, K_SIN]
                  + lflt[i, F_LOAD_TZ])
        if fx == 0.0 and fy == 0.0 and moment == 0.0:
            continue
        for k in range(lint[i, L_START], i + 1):
            if lint[k, L_REV] == 1:
                dx = kin[i, K_OX] - kin[k, K_OX]
                dy = kin[i, K_OY] - kin[k, K_OY]
                bias[k] -= dx * fy - dy * fx + moment
            else:
                bias[k] -= -kin[k, K_PSIN] * fx + kin[k, K_PCOS] * fy


@_jit(allocates=False)
def load_potential(lflt: np.ndarray, kin: np.ndarray) -> float:
    """Potential energy of the links' loads, ``-sum(F . P + Tz theta)``, J."""
    potential = 0.0
    for i in range(lflt.shape[0]):
        fx = lflt[i, F_LOAD_FX]
        fy = lflt[i, F_LOAD_FY]
        c = kin[i, K_COS]
        s = kin[i, K_SIN]
        potential -= fx * kin[i, K_OX] + fy * kin[i, K_OY]
        potential -= -lflt[i, F_LOAD_B] * c + lflt[i, F_LOAD_A] * s
        potential -= lflt[i, F_LOAD_TZ] * kin[i, K_THETA]
    return potential


@_jit(allocates=False)
def terms(q: np.ndarray, qd: np.ndarray, lint: np.ndarray, lflt: np.ndarray, cint: np.ndarray,
          cflt: np.ndarray, par: np.ndarray, with_dynamics: bool, kin: np.ndarray,
          mm: np.ndarray, bias: np.ndarray, cm: np.ndarray, crow: np.ndarray, jac: np.ndarray,
          points: np.ndarray) -> None:
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
        if par[P_PLANT] != 0.0:
            plant_terms(qd, lint, lflt, kin, mm, bias)
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
