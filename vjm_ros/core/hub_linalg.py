"""Closure solves in time linear in the number of chains, for rows laid out around a hub chain
(:func:`vjm_ros.core.packing.closure_layout`): ``N`` chains whose tips meet at one pin, joined by
``N - 1`` hinges from the first tip.

Each closure row touches the hub and one other chain, so ``G = A M^-1 A^T`` is block-diagonal by
that other chain plus a term of rank at most the hub's size, and ``M + h A^T W A`` couples each
chain only to itself and to the hub. :func:`hub_correction` solves the first by Woodbury's
identity and :func:`hub_implicit_solve` the second by block elimination, the hub last; the dense
solves of :mod:`vjm_ros.core.small_linalg` cost ``r^3`` and ``n^2 r``. They give the same
numbers to round-off (not bit for bit: the sums run in another order), and
:func:`hub_correction` refuses, for the dense solve to take over, wherever it cannot prove that
``G`` is far from singular (a stretched chain besides the hub).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from vjm_ros.core.small_linalg import lu_factor_range, lu_solve_range
from vjm_ros.jit import jit as _jit

if TYPE_CHECKING:
    import numpy as np

# columns of a row of the closure layout (:func:`vjm_ros.core.packing.closure_layout`)
H_OTHER, H_HUB, H_HIT_OTHER, H_HIT_HUB, H_ORDER = range(5)
N_HUB_COLUMNS = 5


@_jit(allocates=False)
def hub_correction(lu: np.ndarray, piv: np.ndarray, jac: np.ndarray, c: np.ndarray,
                   rcond: float, out: np.ndarray, minv_at: np.ndarray, g: np.ndarray,
                   v: np.ndarray, vec: np.ndarray, blocks: np.ndarray, lay: np.ndarray) -> bool:
    """``M^-1 A^T lambda`` with ``A M^-1 A^T lambda = c``, by the hub solve (:func:`_hub_solve`),
    when it can prove ``A M^-1 A^T`` far from singular (its plain solution is then the
    minimum-norm one of :func:`vjm_ros.core.small_linalg.min_norm_correction`); False, with
    ``out`` untouched, otherwise.

    Parameters
    ----------
    lu, piv : ndarray
        LU factors of ``M`` (:func:`vjm_ros.core.small_linalg.lu_factor_blocks`).
    jac : ndarray, shape (r, n)
        ``A``.
    c : ndarray, shape (r,)
    rcond : float
        Relative eigenvalue cut of the minimum-norm solve.
    out : ndarray, shape (n,)
        Out: ``M^-1 A^T lambda``.
    minv_at : ndarray, shape (n, r)
        Scratch: ``M^-1 A^T`` in the blocks each row touches.
    g, v : ndarray, shape (r, r)
        Scratch.
    vec : ndarray, shape (3 + r + nh, max(n, r, nh + 1))
        Scratch (``nh``: the hub's size; rows from 3 on hold the Woodbury terms); on return
        ``vec[0, :r]`` holds ``lambda``.
    blocks : ndarray of int64, shape (nb + 1,)
        Block boundaries of ``M``, one block per chain.
    lay : ndarray of int64, shape (r + 1, >= 5)
        The closure layout (:func:`vjm_ros.core.packing.closure_layout`); its columns
        :data:`H_HIT_OTHER` and :data:`H_HIT_HUB` are scratch.

    Returns
    -------
    bool
    """
    r = c.shape[0]
    col = vec[1]
    for i in range(r):
        for s in range(2):
            b = lay[i, H_OTHER + s]
            lay[i, H_HIT_OTHER + s] = 0
            if b < 0:
                continue
            lo = blocks[b]
            hi = blocks[b + 1]
            touched = 0
            for j in range(lo, hi):
                col[j] = jac[i, j]
                if jac[i, j] != 0.0:
                    touched = 1
            lay[i, H_HIT_OTHER + s] = touched
            if touched:
                lu_solve_range(lu, piv, col, lo, hi)
            for j in range(lo, hi):
                minv_at[j, i] = col[j] if touched else 0.0
    if not _hub_solve(jac, c, rcond, minv_at, g, v, vec, blocks, lay):
        return False
    lam = vec[0]
    for j in range(out.shape[0]):
        out[j] = 0.0
    for i in range(r):  # out = M^-1 A^T lambda over the blocks each row touches
        for s in range(2):
            if lay[i, H_HIT_OTHER + s]:
                b = lay[i, H_OTHER + s]
                for j in range(blocks[b], blocks[b + 1]):
                    out[j] += minv_at[j, i] * lam[i]
    return True


@_jit(allocates=False)
def hub_implicit_solve(mm: np.ndarray, lu: np.ndarray, piv: np.ndarray, jac: np.ndarray,
                       wgt: np.ndarray, h: float, x: np.ndarray, col: np.ndarray,
                       blocks: np.ndarray, lay: np.ndarray) -> int:
    """Solve ``(M + h A^T diag(wgt) A) dx = x`` in place in ``x`` for rows with a hub layout, in
    time linear in the number of chains.

    Each row touches one chain besides the hub (:func:`vjm_ros.core.packing.closure_layout`), so
    the matrix couples each chain only to itself and to the hub: block elimination of every
    other chain first (``K_bb`` is symmetric positive definite, ``M_b`` plus a semi-definite
    term: LU with partial pivoting within the block), then the hub's Schur complement
    ``K_hh - sum_b K_hb K_bb^-1 K_bh``. No fill-in falls outside those blocks.

    Parameters
    ----------
    mm : ndarray, shape (n, n)
        ``M``, block-diagonal by ``blocks``.
    lu : ndarray, shape (n, n)
        Scratch: the blocks of the matrix and their factors.
    piv : ndarray of int64, shape (n,)
    jac : ndarray, shape (r, n)
        ``A``.
    wgt : ndarray, shape (>= r,)
        Row weights (``h Kp + Kv``, N s/m or N m s/rad).
    h : float
        Step, s.
    x : ndarray, shape (n,)
        In: right-hand side; out: solution.
    col : ndarray, shape (>= n,)
        Scratch.
    blocks, lay : ndarray of int64
        :func:`vjm_ros.core.packing.chain_blocks` and
        :func:`vjm_ros.core.packing.closure_layout`.

    Returns
    -------
    int
        0, or 1 when a pivot is exactly zero.
    """
    nb = blocks.shape[0] - 1
    hb = lay[jac.shape[0], 0]
    hlo = blocks[hb]
    hhi = blocks[hb + 1]
    for b in range(nb):
        lo = blocks[b]
        hi = blocks[b + 1]
        for i in range(lo, hi):
            for j in range(lo, hi):
                lu[i, j] = mm[i, j]
            if b != hb:
                for j in range(hlo, hhi):
                    lu[i, j] = 0.0
                    lu[j, i] = 0.0
    for i in range(jac.shape[0]):
        wi = h * wgt[i]
        for s1 in range(2):
            b1 = lay[i, H_OTHER + s1]
            if b1 < 0:
                continue
            for k in range(blocks[b1], blocks[b1 + 1]):
                f = wi * jac[i, k]
                if f == 0.0:
                    continue
                for s2 in range(2):
                    b2 = lay[i, H_OTHER + s2]
                    if b2 < 0:
                        continue
                    for j in range(blocks[b2], blocks[b2 + 1]):
                        lu[k, j] += f * jac[i, j]
    status = 0
    for b in range(nb):
        if b == hb:
            continue
        lo = blocks[b]
        hi = blocks[b + 1]
        status = max(status, lu_factor_range(lu, piv, lo, hi))
        lu_solve_range(lu, piv, x, lo, hi)
        for cc in range(hlo, hhi):  # K_bb^-1 K_bh in place of K_bh
            for j in range(lo, hi):
                col[j] = lu[j, cc]
            lu_solve_range(lu, piv, col, lo, hi)
            for j in range(lo, hi):
                lu[j, cc] = col[j]
        for a in range(hlo, hhi):
            for cc in range(hlo, hhi):
                s = 0.0
                for j in range(lo, hi):
                    s += lu[a, j] * lu[j, cc]
                lu[a, cc] -= s
            s = 0.0
            for j in range(lo, hi):
                s += lu[a, j] * x[j]
            x[a] -= s
    status = max(status, lu_factor_range(lu, piv, hlo, hhi))
    lu_solve_range(lu, piv, x, hlo, hhi)
    for b in range(nb):
        if b == hb:
            continue
        for j in range(blocks[b], blocks[b + 1]):
            s = 0.0
            for cc in range(hlo, hhi):
                s += lu[j, cc] * x[cc]
            x[j] -= s
    return status


@_jit(allocates=False)
def _hub_solve(jac, c, rcond, minv_at, g, low, vec, blocks, lay):
    """``vec[0, :r] = G^-1 c`` for ``G = A M^-1 A^T`` of rows with a hub layout, in time linear
    in the number of rows, when no eigenvalue of ``G`` can fall below ``rcond * max
    eigenvalue``; False, with ``vec[0]`` untouched, otherwise (the caller then solves densely).

    With ``A_h`` the hub's columns of ``A`` and ``M_h`` its block of ``M``,
    ``G = R + A_h M_h^-1 A_h^T``, where ``R`` sums the other chains and is block-diagonal by row
    group (each row touches one chain besides the hub). By Woodbury's identity, with
    ``Z = M_h^-1 A_h^T`` (read off ``minv_at``), ``X = R^-1 [A_h, c]`` and
    ``(I + Z X_A) y = Z x_c``: ``lambda = x_c - X_A y``. ``I + Z X_A`` is similar to
    ``I + M_h^-1/2 A_h^T R^-1 A_h M_h^-1/2``, whose eigenvalues are at least 1: the hub's own
    term may be singular (a stretched hub chain) at no cost. ``R`` may not: a stretched chain
    besides the hub makes its group singular, and the bound below then refuses.

    The bound is rigorous: ``lambda_min(G) >= lambda_min(R)`` (the hub term is positive
    semi-definite), the smallest eigenvalue of a group of ``s`` rows is at least
    ``det / (tr / (s - 1))^(s - 1)`` (the product of the others is at most their mean to the
    power ``s - 1``, and ``det = prod L_jj^2`` from its Cholesky factor ``L``; for two rows at
    least half of it), and ``lambda_max(G) <= trace G``; it must clear ``rcond trace G``
    tenfold, as the dense test does. ``g`` and ``low`` receive ``R`` and ``L`` in the places of the hub order; ``vec[2]`` is
    scratch, ``vec[3:3 + r]`` receives ``X`` and ``vec[3 + r:]`` the small system.
    """
    r = c.shape[0]
    hb = lay[r, 0]
    groups = lay[r, 1]
    hlo = blocks[hb]
    nh = blocks[hb + 1] - hlo
    trace = 0.0
    for gi in range(groups):  # R group by group, and trace G
        p0 = lay[r, 2 + gi]
        p1 = lay[r, 3 + gi]
        for p in range(p0, p1):
            i = lay[p, H_ORDER]
            b = lay[i, H_OTHER]
            for pk in range(p0, p + 1):
                k = lay[pk, H_ORDER]
                s = 0.0
                if lay[i, H_HIT_OTHER] and lay[k, H_HIT_OTHER]:
                    for j in range(blocks[b], blocks[b + 1]):
                        s += jac[i, j] * minv_at[j, k]
                g[p, pk] = s
            trace += g[p, p]
            if lay[i, H_HIT_HUB]:
                for j in range(hlo, hlo + nh):
                    trace += jac[i, j] * minv_at[j, i]
    if not trace > 0.0:
        return False
    x = vec[2]
    floor = 10.0 * rcond * trace
    for gi in range(groups):
        p0 = lay[r, 2 + gi]
        p1 = lay[r, 3 + gi]
        det = 1.0
        tr = 0.0
        for pj in range(p0, p1):  # Cholesky R_group = L L^T
            d = g[pj, pj]
            tr += d
            for pk in range(p0, pj):
                d -= low[pj, pk] * low[pj, pk]
            if not d > 0.0:
                return False
            det *= d
            ljj = math.sqrt(d)
            low[pj, pj] = ljj
            for p in range(pj + 1, p1):
                s = g[p, pj]
                for pk in range(p0, pj):
                    s -= low[p, pk] * low[pj, pk]
                low[p, pj] = s / ljj
        # lambda_min >= det / (mean of the other eigenvalues)^(s - 1) >= det / (tr / (s - 1))^(s - 1)
        for _ in range(p1 - p0 - 1):
            det /= tr / (p1 - p0 - 1)
        if not det > floor:
            return False
    xa = 3  # X = R^-1 [A_h, c] in vec[3 + i, :nh + 1]
    for gi in range(groups):
        p0 = lay[r, 2 + gi]
        p1 = lay[r, 3 + gi]
        for a in range(nh + 1):
            for p in range(p0, p1):  # L y = column a
                i = lay[p, H_ORDER]
                if a == nh:
                    s = c[i]
                elif lay[i, H_HIT_HUB]:
                    s = jac[i, hlo + a]
                else:
                    s = 0.0
                for pk in range(p0, p):
                    s -= low[p, pk] * x[pk]
                x[p] = s / low[p, p]
            for p in range(p1 - 1, p0 - 1, -1):  # L^T x = y
                s = x[p]
                for pk in range(p + 1, p1):
                    s -= low[pk, p] * x[pk]
                x[p] = s / low[p, p]
                vec[xa + lay[p, H_ORDER], a] = x[p]
    sa = xa + r  # (I + Z X_A) y = Z x_c in vec[3 + r + a, :nh + 1], by elimination
    for a in range(nh):
        for b in range(nh + 1):
            vec[sa + a, b] = 1.0 if a == b else 0.0
    for i in range(r):
        if lay[i, H_HIT_HUB]:
            for a in range(nh):
                z = minv_at[hlo + a, i]
                for b in range(nh + 1):
                    vec[sa + a, b] += z * vec[xa + i, b]
    for k in range(nh):
        p = k
        for i in range(k + 1, nh):
            if abs(vec[sa + i, k]) > abs(vec[sa + p, k]):
                p = i
        if p != k:
            for b in range(nh + 1):
                t = vec[sa + k, b]
                vec[sa + k, b] = vec[sa + p, b]
                vec[sa + p, b] = t
        if vec[sa + k, k] == 0.0:
            return False
        for i in range(k + 1, nh):
            f = vec[sa + i, k] / vec[sa + k, k]
            for b in range(k, nh + 1):
                vec[sa + i, b] -= f * vec[sa + k, b]
    for k in range(nh - 1, -1, -1):  # y into column nh
        s = vec[sa + k, nh]
        for b in range(k + 1, nh):
            s -= vec[sa + k, b] * vec[sa + b, nh]
        vec[sa + k, nh] = s / vec[sa + k, k]
    lam = vec[0]
    for i in range(r):
        s = vec[xa + i, nh]
        for b in range(nh):
            s -= vec[xa + i, b] * vec[sa + b, nh]
        lam[i] = s
    return True
