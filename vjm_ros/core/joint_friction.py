"""Coulomb friction in the joints with true sticking, solved with the closures once per step.

At the start of each step of a fixed-step method, once the accelerations (or, for
``implicit_euler``, the new rates) without friction are known, the friction of every joint
with a Coulomb bound ``mu_k`` (N m or N) is chosen as one effort ``f_k`` in ``[-mu_k, mu_k]``
per joint, held over the step (:func:`vjm_ros.core.kernels.step` adds it to the efforts of the
later stages):

* the rates predicted at the end of the step are ``u = qd + h qdd`` (the new rates themselves for
  ``implicit_euler``); an effort ``f`` changes them by ``h W f``, with ``W`` the inverse mass
  matrix of the closed mechanism: ``M^-1`` projected onto the closures ``A qd = 0`` in the metric
  of ``M`` when they are exact, ``M^-1`` for penalty closures (which act through forces), and
  ``(M + h A^T (h Kp + Kv) A)^-1`` for ``implicit_euler``'s penalty step;
* ``f`` solves the box-constrained problem ``u_k + h (W f)_k = 0`` where ``|f_k| < mu_k``, else
  ``f_k = -mu_k sign(u_k + h (W f)_k)``: a joint sticks while the effort that holds it stays
  within its bound and slides against the bound otherwise (projected Gauss-Seidel sweeps: exact
  for one joint, converged to :data:`SWEEP_TOLERANCE` for several);
* a joint at rest whose holding effort is within its bound then has no acceleration: it stays
  exactly where it is (the position moves with the rates, which stay 0).

This is the velocity-level friction of time-stepping schemes (Stewart and Trinkle, Anitescu;
MuJoCo's ``frictionloss``): one effort per step, so the friction is first-order accurate in the
step whatever the integrator (stick-slip is not smooth). The energy it takes,
``-h f . (qd_start + qd_end) / 2`` per step, is added up by the caller.
"""

from __future__ import annotations

from vjm_ros.core.layout import F_FRICTION, F_FRICTION_SCALE
from vjm_ros.core.small_linalg import (
    lu_factor_blocks,
    lu_factor_range,
    lu_solve_blocks,
    lu_solve_range,
    min_norm_correction,
)
from vjm_ros.jit import jit as _jit

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
def friction_efforts(acc, qd, h, implicit, exact, lflt, par, mm, jac, weights, lu, piv,
                     minv_at, g, v, vec, rhs, corr, wcols, force, blocks, touch):
    """Choose the friction efforts of a step and add their effect to ``acc`` in place.

    Parameters
    ----------
    acc : ndarray, shape (n,)
        Accelerations without friction (rad/s^2 or m/s^2), or the new rates for ``implicit``.
    qd : ndarray, shape (n,)
        Rates at the start of the step, rad/s or m/s.
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
        Receives row ``k`` of ``W`` for each joint ``k`` with sticking friction.
    force : ndarray, shape (n,)
        Receives ``f``, N m or N (0 for the other joints).

    Returns
    -------
    int
        0, or 1 when the matrix was exactly singular (no friction is applied then).
    """
    n = qd.shape[0]
    r = jac.shape[0]
    penalty_implicit = implicit and not exact
    for i in range(n):
        force[i] = 0.0
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
        if not _sticks(lflt, k):
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
    # predicted end rates u, kept in acc's units until the end
    scale = 1.0
    for j in range(n):
        scale = max(scale, abs(qd[j]), abs(acc[j]) * (1.0 if implicit else h))
    for _ in range(MAX_SWEEPS):
        change = 0.0
        for k in range(n):
            w = wcols[k, k]
            if not _sticks(lflt, k) or not w > 1e-12:
                continue
            u = acc[k] if implicit else qd[k] + h * acc[k]
            bound = lflt[k, F_FRICTION]
            target = min(bound, max(-bound, force[k] - u / (h * w)))
            d = target - force[k]
            if d != 0.0:
                force[k] = target
                gain = h * d if implicit else d  # rates (implicit) or accelerations change
                for j in range(n):
                    acc[j] += wcols[k, j] * gain
                change = max(change, abs(h * w * d))
        if change <= SWEEP_TOLERANCE * scale:
            break
    return 0
