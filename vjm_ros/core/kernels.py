"""Compiled kernels behind :class:`vjm_ros.core.mechanism.Mechanism`: the package's one source of the physics.

Kinematics, dynamics, closure rows, their enforcement and the fixed-step methods (checked against
the independent numpy formulation in ``test/oracle/``), written as scalar loops over the links so that numba compiles them to
machine code (``cache=True``: compiled once per machine, then loaded from the cache). Without numba
the same functions run as plain Python, which is correct but slow.

The terms (kinematics, dynamics, closure rows) are computed by :func:`vjm_ros.core.terms.terms`.

The entry points are named for what they compute (:func:`evaluate`, :func:`residual`,
:func:`implicit_velocity`, :func:`advance`, :func:`project`); each takes the packed model
(:class:`PackedModel`, read-only, shareable between threads) and a workspace (:class:`Data`, one
per thread) and calls the one compiled kernel, :func:`step`, so that numba compiles the physics
once (a few seconds on first use, then loaded from its cache in a fraction of a second).

The layouts of the packed model and of the workspace are in :mod:`vjm_ros.core.layout`.

The entry points return a status: 0 on success, 1 when a matrix was exactly singular (the case in which
``numpy.linalg.solve`` raises ``LinAlgError``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from vjm_ros.core.hub_linalg import hub_correction, hub_implicit_solve
from vjm_ros.core.joint_efforts import joint_efforts, stop_impacts
from vjm_ros.core.layout import (
    C_VX,
    C_VY,
    C_X,
    C_Y,
    EXACT,
    F_ARMATURE,
    F_INERTIA,
    F_MASS,
    K_OMEGA,
    K_PCOS,
    K_POMEGA,
    K_PSIN,
    K_SLIDE,
    K_SLIDE_RATE,
    L_REV,
    P_ALPHA,
    P_BETA,
    P_GX,
    P_GY,
    P_JOINT_EFFORTS,
    P_METHOD,
    P_PLANT,
    P_RCOND,
    PENALTY,
    R_BIAS,
    R_FORCE,
    R_RATE,
    R_RES,
    Data,
    PackedModel,
    as_arguments,
)
from vjm_ros.core.small_linalg import (
    lu_factor_blocks,
    lu_factor_range,
    lu_solve_blocks,
    lu_solve_range,
    min_norm_correction,
)
from vjm_ros.core.terms import load_potential, terms
from vjm_ros.jit import HAVE_NUMBA  # noqa: F401  (HAVE_NUMBA: part of this module's interface)
from vjm_ros.jit import jit as _jit
from vjm_ros.jit import variant as _variant

if TYPE_CHECKING:
    from collections.abc import Callable

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


def evaluate(model: PackedModel, data: Data, q: np.ndarray, qd: np.ndarray, tau: np.ndarray,
             qdd: np.ndarray, kernel: Callable[..., int] | None = None) -> int:
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
    return (kernel or step)(EVALUATE, q, qd, tau, 0.0, ONE_STEP, 0.0, as_arguments(model), as_arguments(data),
                            qdd, data.spare, NO_KNOWN, NO_ROW)


def residual(model: PackedModel, data: Data, q: np.ndarray,
             kernel: Callable[..., int] | None = None) -> int:
    """Closure residuals at ``q`` with zero rates, without the dynamics or the Jacobian, into
    ``data.kin`` and ``data.crow`` (columns :data:`R_RES`, :data:`R_DX` .. :data:`R_DZ`)."""
    return (kernel or step)(RESIDUAL, q, q, q, 0.0, ONE_STEP, 0.0, as_arguments(model), as_arguments(data),
                            data.spare, data.spare, NO_KNOWN, NO_ROW)


def implicit_velocity(model: PackedModel, data: Data, q: np.ndarray, qd: np.ndarray,
                      tau: np.ndarray, h: float, v: np.ndarray,
                      kernel: Callable[..., int] | None = None) -> int:
    """``v``, the velocity after a step of length ``h`` (s) implicit in the penalty forces
    (``qd + h qdd`` for exact closures); arguments and status as :func:`evaluate`."""
    return (kernel or step)(IMPLICIT_VELOCITY, q, qd, tau, h, ONE_STEP, 0.0, as_arguments(model),
                            as_arguments(data), v, data.spare, NO_KNOWN, NO_ROW)


def advance(model: PackedModel, data: Data, method: int, q: np.ndarray, qd: np.ndarray,
            tau: np.ndarray, h: float, steps: int, q_out: np.ndarray, qd_out: np.ndarray,
            kernel: Callable[..., int] | None = None) -> int:
    """``steps`` steps of length ``h`` (s) of a fixed-step method from ``(q, qd)``, efforts
    held, into ``(q_out, qd_out)``.

    ``method`` is :data:`EXPLICIT_EULER`, :data:`SEMI_IMPLICIT_EULER`, :data:`RK4` or
    :data:`IMPLICIT_EULER` (:mod:`vjm_ros.core.integrators.fixed`); ``data`` holds the terms of
    the last stage. Status as :func:`evaluate`.
    """
    return (kernel or step)(method, q, qd, tau, h, steps, 0.0, as_arguments(model), as_arguments(data), q_out,
                            qd_out, NO_KNOWN, NO_ROW)


def project(model: PackedModel, data: Data, q: np.ndarray, qd: np.ndarray, steps: int,
            tol: float, q_out: np.ndarray, qd_out: np.ndarray,
            kernel: Callable[..., int] | None = None) -> int:
    """``(q, qd)`` projected onto the closures, into ``(q_out, qd_out)``: at most ``steps``
    Gauss-Newton steps in the metric of ``M`` until ``max |C| <= tol`` (m or rad), then one
    velocity projection (``rcond = 1e-10``), as
    :meth:`vjm_ros.core.mechanism.Mechanism.project`. Status as :func:`evaluate`."""
    return (kernel or step)(PROJECT, q, qd, data.zero, 0.0, steps, tol, as_arguments(model),
                            as_arguments(data), q_out, qd_out, NO_KNOWN, NO_ROW)


HUB_SOLVES = False
"""Whether a compiled copy of :func:`step` holds the hub solves of :mod:`vjm_ros.core.hub_linalg`.

A module constant, so numba drops the branches it guards before typing them: :func:`step`
compiles none of the hub code (most mechanisms have no hub layout, and that code would add
about 4 s to a cold compile), :data:`step_with_hub` is the copy with it, for mechanisms whose
workspace has a hub layout (:meth:`vjm_ros.core.mechanism.Mechanism` picks). Given a hub layout,
:func:`step` solves densely: the same results to round-off."""


@_jit(allocates=False)
def step(op: int, q0: np.ndarray, qd0: np.ndarray, tau: np.ndarray, h: float, steps: int,
         tol: float, model: tuple, data: tuple, out_a: np.ndarray, out_b: np.ndarray,
         known: np.ndarray, row: int) -> int:
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
     scratch, _, zero, touch, lay, wcols, column, impulse, stop) = data
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
    friction = par[P_JOINT_EFFORTS] != 0.0 and not single  # joint friction and stops
    if friction:
        impulse[n] = 0.0
    for it in range(total):
        last = then_evaluate and it == total - 1  # the evaluation at the end state
        stage = 0 if last else it % stages
        if last:
            acc = known[row + 1]
        if stage == 0:
            for j in range(n):
                qi[j] = q[j]
                vs[0, j] = qd[j]
            if friction and not last:
                for j in range(n):
                    impulse[j] = 0.0  # chosen once this stage's accelerations are known
                    stop[j] = 0.0
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
                if friction and not last:
                    s = s + (impulse[j] + stop[j])  # the step's joint efforts, held
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
            if par[P_PLANT] != 0.0:
                for i in range(n):  # the evaluated state's rates, as the terms saw them
                    rate = (kin[i, K_OMEGA] - kin[i, K_POMEGA] if lint[i, L_REV] == 1
                            else kin[i, K_SLIDE_RATE])
                    kinetic += lflt[i, F_ARMATURE] * rate * rate
                potential += load_potential(lflt, kin)
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
        if friction and not last and stage == 0:
            for j in range(n):
                column[j] = qd[j]  # the rates at the start of the step
            status = max(status, joint_efforts(
                acc, q, qd, h, op == IMPLICIT_EULER, exact, lflt, par, mm, jac, vec[2], lu,
                piv, minv_at, g, v, vec, rhs, corr, wcols, impulse, stop, blocks, touch))
        if op == IMPLICIT_EULER:
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
        if friction and not last and stage == stages - 1:
            removed = 0.0  # the joint efforts' work over the step, trapezoid in the rates
            for j in range(n):
                removed -= h * (impulse[j] + stop[j]) * 0.5 * (column[j] + qd[j])
            impulse[n] += removed + stop_impacts(q, qd, lflt, wcols, column)
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
