"""Efforts the joints make on their own: Coulomb friction and hard stops, solved with the closures
once per step.

At the start of each step of a fixed-step method, once the accelerations (or, for
``implicit_euler``, the new rates) without them are known, these efforts are chosen together and
held over the step (:func:`vjm_ros.core.kernels.step` adds them to the efforts of the later
stages):

* the rates predicted at the end of the step are ``u = qd + h qdd`` (the new rates themselves for
  ``implicit_euler``); efforts ``f`` change them by ``h W f``, with ``W`` the inverse mass matrix
  of the closed mechanism: ``M^-1`` projected onto the closures ``A qd = 0`` in the metric of
  ``M`` when they are exact, ``M^-1`` for penalty closures (which act through forces), and
  ``(M + h A^T (h Kp + Kv) A)^-1`` for ``implicit_euler``'s penalty step;
* **friction** of joint ``k`` with Coulomb bound ``mu_k`` (N m or N): ``f_k`` in
  ``[-mu_k, mu_k]`` with ``u_k + h (W f)_k = 0`` where ``|f_k| < mu_k``: the joint sticks while
  the effort that holds it stays within its bound and slides against the bound otherwise; a
  joint at rest whose holding effort is within its bound has no acceleration and stays;
* a **stop** at ``lo`` (``hi`` alike, signs reversed) with restitution ``e``: a joint on its
  stop (``q_k <= lo``) gets an effort ``s_k >= 0`` that keeps ``u_k >= 0`` (it rests there or
  leaves); a step that carries the joint past its stop ends with the **impact**
  (:func:`stop_impacts`): the coordinate is set on the stop and the rate reversed to
  ``-e qd_k`` by an impulse through ``W``; a rebound that what pushes the joint into its stop
  would undo within two steps (``e |qd_k| < 2 |qd_k - qd_k(start)|``, the step's change of
  rate) is below what a first-order step resolves (explicit Euler's position lags its rate by
  a step): the joint rests instead (``e = 0``), as a bouncing body comes to rest after its
  shrinking bounces. Without the threshold a joint never came to rest: it chattered, leaving
  the stop and hitting it again every few steps (engines threshold bounces by speed alike);
* the problem is solved by projected Gauss-Seidel sweeps (exact for one joint, converged to
  :data:`SWEEP_TOLERANCE` for several).

This is the velocity-level treatment of friction and contact of time-stepping schemes (Stewart
and Trinkle, Anitescu; MuJoCo's ``frictionloss`` and joint limits): one effort per step, so
friction and impacts are first-order accurate in the step whatever the integrator. The energy
they take, ``-h (f + s) . (qd_start + qd_end) / 2`` per step plus the impacts' (exact for
``W = M^-1``), is added up by the caller. A coordinate set back on its stop moves the rest of a
closed chain along ``W``'s row, which keeps the closures to first order in the distance (about
``h |qd|`` at an impact).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from vjm_ros.core.layout import (
    F_FRICTION,
    F_FRICTION_SCALE,
    F_RANGE_HI,
    F_RANGE_LO,
    F_RESTITUTION,
)
from vjm_ros.core.small_linalg import (
    lu_factor_blocks,
    lu_factor_range,
    lu_solve_blocks,
    lu_solve_range,
    min_norm_correction,
)
from vjm_ros.jit import jit as _jit

if TYPE_CHECKING:
    import numpy as np

MAX_SWEEPS = 100
"""Projected Gauss-Seidel sweeps at most per step."""

SWEEP_TOLERANCE = 1e-13
"""A sweep that changes no predicted rate by more than this (relative to the largest rate plus
1, rad/s or m/s) ends the iteration."""


@_jit(allocates=False)
def _sticks(lflt, k):
    """Whether joint ``k`` has sticking (not smooth) Coulomb friction."""
    return lflt[k, F_FRICTION] > 0.0 and not lflt[k, F_FRICTION_SCALE] > 0.0


@_jit(allocates=False)
def has_stop(lflt: np.ndarray, k: int) -> bool:
    """Whether joint ``k`` has a finite stop."""
    return lflt[k, F_RANGE_LO] > -1e300 or lflt[k, F_RANGE_HI] < 1e300


@_jit(allocates=False)
def _needed(lflt, k, q, qd, acc, h, implicit):
    """Whether joint ``k`` needs its row of ``W`` this step: it has sticking friction, or it is
    on a stop or within twice the step's travel of one (``h`` times the larger of its rate now
    and its rate predicted at the end of the step), where the step may end with an impact."""
    if _sticks(lflt, k):
        return True
    if not has_stop(lflt, k):
        return False
    u = acc[k] if implicit else qd[k] + h * acc[k]
    reach = 2.0 * h * max(abs(qd[k]), abs(u))
    return q[k] - lflt[k, F_RANGE_LO] <= reach or lflt[k, F_RANGE_HI] - q[k] <= reach


@_jit(allocates=False)
def joint_efforts(acc: np.ndarray, q: np.ndarray, qd: np.ndarray, h: float, implicit: bool,
                  exact: bool, lflt: np.ndarray, par: np.ndarray, mm: np.ndarray,
                  jac: np.ndarray, weights: np.ndarray, lu: np.ndarray, piv: np.ndarray,
                  minv_at: np.ndarray, g: np.ndarray, v: np.ndarray, vec: np.ndarray,
                  rhs: np.ndarray, corr: np.ndarray, wcols: np.ndarray, force: np.ndarray,
                  stop: np.ndarray, blocks: np.ndarray, touch: np.ndarray) -> int:
    """Choose the friction and stop efforts of a step and add their effect to ``acc`` in place.

    Parameters
    ----------
    acc : ndarray, shape (n,)
        Accelerations without them (rad/s^2 or m/s^2), or the new rates for ``implicit``.
    q, qd : ndarray, shape (n,)
        Coordinates and rates at the start of the step, rad or m, rad/s or m/s.
    h : float
        Step, s.
    implicit, exact : bool
        ``acc`` holds ``implicit_euler``'s new rates; the closures are exact.
    mm, jac, weights : ndarray
        ``M`` (n, n), ``A`` (r, n) at the start of the step, and the row weights
        ``h Kp + Kv`` (r,) of the implicit penalty step (read only when ``implicit`` and not
        ``exact``).
    lu, piv, minv_at, g, v, vec, rhs, corr : ndarray
        Scratch of the solves (overwritten).
    wcols : ndarray, shape (n, n)
        Receives row ``k`` of ``W`` for each joint ``k`` with friction or a stop.
    force, stop : ndarray, shape (n,)
        Receive the friction efforts ``f`` and the stop efforts ``s``, N m or N.

    Returns
    -------
    int
        0, or 1 when the matrix was exactly singular (no effort is applied then).
    """
    n = qd.shape[0]
    r = jac.shape[0]
    penalty_implicit = implicit and not exact
    any_joint = False
    for k in range(n):
        force[k] = 0.0
        stop[k] = 0.0
        wcols[k, k] = 0.0  # no row of W for this joint this step (set below when needed)
        any_joint = any_joint or _needed(lflt, k, q, qd, acc, h, implicit)
    if not any_joint:
        return 0
    for i in range(n):
        for j in range(n):
            s = mm[i, j]
            if penalty_implicit:
                for k in range(r):
                    s += h * jac[k, i] * weights[k] * jac[k, j]
            lu[i, j] = s
    if penalty_implicit:  # the closures couple the chains: one dense factorization
        status = lu_factor_range(lu, piv, blocks[0], n)
    else:
        status = lu_factor_blocks(lu, piv, blocks)
    if status != 0:
        return status
    for k in range(n):
        if not _needed(lflt, k, q, qd, acc, h, implicit):
            continue
        x = wcols[k]  # W is symmetric: its row k is its column k
        for j in range(n):
            x[j] = 0.0
        x[k] = 1.0
        if penalty_implicit:
            lu_solve_range(lu, piv, x, blocks[0], n)
        else:
            lu_solve_blocks(lu, piv, x, blocks)
        if exact and r > 0:
            for i in range(r):
                s = 0.0
                for j in range(n):
                    s += jac[i, j] * x[j]
                rhs[i] = s
            min_norm_correction(lu, piv, jac, rhs, par[3], corr, minv_at, g, v, vec, blocks,
                                touch)
            for j in range(n):
                x[j] -= corr[j]
    scale = 1.0
    for j in range(n):
        scale = max(scale, abs(qd[j]), abs(acc[j]) * (1.0 if implicit else h))
    for _ in range(MAX_SWEEPS):
        change = 0.0
        for k in range(n):
            w = wcols[k, k]
            if not w > 1e-12:
                continue
            for row in range(2):  # the stop, then the friction
                u = acc[k] if implicit else qd[k] + h * acc[k]
                if row == 0:
                    if not has_stop(lflt, k):
                        continue
                    old = stop[k]  # on a stop (touching it), the joint may only leave it
                    new = 0.0
                    if q[k] <= lflt[k, F_RANGE_LO] or old > 0.0:
                        new = max(0.0, old - u / (h * w))
                    elif q[k] >= lflt[k, F_RANGE_HI] or old < 0.0:
                        new = min(0.0, old - u / (h * w))
                    stop[k] = new
                else:
                    if not _sticks(lflt, k):
                        continue
                    old = force[k]
                    bound = lflt[k, F_FRICTION]
                    new = min(bound, max(-bound, old - u / (h * w)))
                    force[k] = new
                d = new - old
                if d != 0.0:
                    gain = h * d if implicit else d  # rates (implicit) or accelerations change
                    for j in range(n):
                        acc[j] += wcols[k, j] * gain
                    change = max(change, abs(h * w * d))
        if change <= SWEEP_TOLERANCE * scale:
            break
    return 0


@_jit(allocates=False)
def stop_impacts(q: np.ndarray, qd: np.ndarray, lflt: np.ndarray, wcols: np.ndarray,
                 start: np.ndarray) -> float:
    """Set every coordinate carried past a stop over the step back on it, moving the others by
    ``W``'s row so that the closures hold to first order, and reverse its rate to ``-e qd_k`` by
    an impulse through ``W`` (the rows :func:`joint_efforts` left in ``wcols``); ``e = 0`` for
    a rebound smaller than the step's change of rate (module docstring; ``start``: the rates
    at the start of the step).

    Returns
    -------
    float
        The kinetic energy the impulses took, J (``-p (qd_k + qd_k^+) / 2`` per impulse ``p``,
        exact for ``W = M^-1``).
    """
    n = q.shape[0]
    removed = 0.0
    for k in range(n):
        if not has_stop(lflt, k):
            continue
        lo = lflt[k, F_RANGE_LO]
        hi = lflt[k, F_RANGE_HI]
        past = 0.0
        if q[k] < lo:
            past = lo - q[k]
        elif q[k] > hi:
            past = hi - q[k]
        if past == 0.0:
            continue
        w = wcols[k, k]
        sign = 1.0 if past > 0.0 else -1.0
        before = qd[k]
        e = lflt[k, F_RESTITUTION]
        if e * abs(before) < 2.0 * abs(before - start[k]):  # a rebound no step resolves
            e = 0.0
        if not w > 1e-12:
            # no row of W: _needed saw the joint beyond twice this step's reach of its stop, so
            # this does not happen on a step that ends past it; should it, this joint alone
            # (its kinetic energy then not in the ledger)
            q[k] = lo if past > 0.0 else hi
            if sign * qd[k] < 0.0:
                qd[k] = -e * qd[k]
            continue
        for j in range(n):  # back on the stop, the closures kept to first order (W's row)
            q[j] += wcols[k, j] * (past / w)
        q[k] = lo if past > 0.0 else hi
        if sign * qd[k] >= 0.0:
            continue
        before = qd[k]  # as changed by the impulses of the joints before k
        p = -(1.0 + e) * before / w
        for j in range(n):
            qd[j] += wcols[k, j] * p
        removed -= p * 0.5 * (before + qd[k])
    return removed
