"""Small dense linear algebra for the compiled kernels: LU with partial pivoting and the
minimum-norm closure correction, written as loops so that numba compiles them without LAPACK
calls (matrices here are a few rows: a call into LAPACK would cost more than the arithmetic).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from vjm_ros.jit import jit as _jit

if TYPE_CHECKING:
    import numpy as np


@_jit(allocates=False)
def lu_factor_blocks(a: np.ndarray, piv: np.ndarray, blocks: np.ndarray) -> int:
    """LU factorization with partial pivoting, in place (as LAPACK ``dgetrf``), of a
    block-diagonal ``a`` (blocks ``blocks[b] .. blocks[b + 1] - 1``), one block at a time.

    The mass matrix of independent open chains is block-diagonal by chain: factoring block by
    block costs the sum of the blocks' cubes instead of ``n^3`` and gives the same factors as a
    dense factorization (a pivot never leaves its block; the skipped entries are zeros). A
    general matrix is one block, ``blocks = [0, n]``.

    Returns
    -------
    int
        0, or 1 when a pivot is exactly zero (singular matrix).
    """
    status = 0
    for b in range(blocks.shape[0] - 1):
        status = max(status, lu_factor_range(a, piv, blocks[b], blocks[b + 1]))
    return status


@_jit(allocates=False)
def lu_factor_range(a: np.ndarray, piv: np.ndarray, lo: int, hi: int) -> int:
    """:func:`lu_factor_blocks` of the one diagonal block ``lo .. hi - 1`` of ``a``."""
    status = 0
    for k in range(lo, hi):
        p = k
        big = abs(a[k, k])
        for i in range(k + 1, hi):
            v = abs(a[i, k])
            if v > big:
                big = v
                p = i
        piv[k] = p
        if p != k:
            for j in range(lo, hi):
                t = a[k, j]
                a[k, j] = a[p, j]
                a[p, j] = t
        d = a[k, k]
        if d == 0.0:
            status = 1
            continue
        inv = 1.0 / d
        for i in range(k + 1, hi):
            a[i, k] *= inv
            f = a[i, k]
            if f != 0.0:
                for j in range(k + 1, hi):
                    a[i, j] -= f * a[k, j]
    return status


@_jit(allocates=False)
def lu_solve_range(a: np.ndarray, piv: np.ndarray, b: np.ndarray, lo: int, hi: int) -> None:
    """Solve the diagonal block ``lo .. hi - 1`` of :func:`lu_factor_blocks`'s output in place
    in ``b[lo:hi]``."""
    for k in range(lo, hi):
        p = piv[k]
        if p != k:
            t = b[k]
            b[k] = b[p]
            b[p] = t
    for i in range(lo, hi):
        s = b[i]
        for j in range(lo, i):
            s -= a[i, j] * b[j]
        b[i] = s
    for i in range(hi - 1, lo - 1, -1):
        s = b[i]
        for j in range(i + 1, hi):
            s -= a[i, j] * b[j]
        b[i] = s / a[i, i]


@_jit(allocates=False)
def lu_solve_blocks(a: np.ndarray, piv: np.ndarray, b: np.ndarray, blocks: np.ndarray) -> None:
    """Solve ``A x = b`` in place in ``b`` (shape (n,)) from :func:`lu_factor_blocks`'s output."""
    for k in range(blocks.shape[0] - 1):
        lu_solve_range(a, piv, b, blocks[k], blocks[k + 1])


@_jit(allocates=False)
def min_norm_correction(lu: np.ndarray, piv: np.ndarray, jac: np.ndarray, c: np.ndarray,
                        rcond: float, out: np.ndarray, minv_at: np.ndarray, g: np.ndarray,
                        v: np.ndarray, vec: np.ndarray, blocks: np.ndarray,
                        touch: np.ndarray) -> None:
    """``M^-1 A^T lambda`` with ``lambda`` the minimum-norm solution of ``A M^-1 A^T lambda = c``.

    When ``A M^-1 A^T`` is provably far from singular (no eigenvalue can fall below the cut
    below), ``lambda`` is its plain solution by Cholesky (:func:`_solve_if_well_conditioned`).
    Otherwise ``A M^-1 A^T`` (symmetric positive semi-definite) is diagonalized by cyclic Jacobi rotations
    (its lower triangle is read, as LAPACK's ``dsyevd`` with ``UPLO='L'``); eigenvalues below
    ``rcond * max eigenvalue`` count as zero, as in the numpy oracle's ``solve_multipliers`` (``test/oracle/constraints.py``),
    so a rank-deficient ``A`` gets no multiplier along the directions it does not constrain.

    ``M`` is block-diagonal (``blocks``, one block per chain) and each closure row touches a
    few chains, so ``M^-1 A^T`` is solved only in the blocks a row touches and ``A M^-1 A^T``
    summed only over the blocks two rows share: the same sums in the same order as dense loops,
    without their ``r n^2`` cost.

    Parameters
    ----------
    lu, piv : ndarray
        LU factors of ``M`` (:func:`lu_factor_blocks`).
    jac : ndarray, shape (r, n)
    c : ndarray, shape (r,)
    rcond : float
    out : ndarray, shape (n,)
        Out: ``M^-1 A^T lambda``.
    minv_at : ndarray, shape (n, r)
        Scratch: ``M^-1 A^T``.
    g, v : ndarray, shape (r, r)
        Scratch: ``G``, eigenvectors.
    vec : ndarray, shape (3, max(n, r))
        Scratch; on return ``vec[0, :r]`` holds ``lambda``.
    blocks : ndarray of int64, shape (nb + 1,)
        Block boundaries of ``M``: ``0, ..., n``.
    touch : ndarray of int64, shape (r, >= nb)
        Scratch: 1 where row ``i`` of ``A`` has a non-zero in block ``b``.
    """
    n = lu.shape[0]
    r = c.shape[0]
    nb = blocks.shape[0] - 1
    col = vec[1]
    for i in range(r):
        for b in range(nb):
            lo = blocks[b]
            hi = blocks[b + 1]
            hit = 0
            for j in range(lo, hi):
                col[j] = jac[i, j]
                if jac[i, j] != 0.0:
                    hit = 1
            touch[i, b] = hit
            if hit:
                lu_solve_range(lu, piv, col, lo, hi)
            for j in range(lo, hi):
                minv_at[j, i] = col[j] if hit else 0.0
    for i in range(r):
        for k in range(i + 1):
            s = 0.0
            for b in range(nb):
                if touch[i, b] and touch[k, b]:
                    for j in range(blocks[b], blocks[b + 1]):
                        s += jac[i, j] * minv_at[j, k]
            g[i, k] = s
            g[k, i] = s
    if _solve_if_well_conditioned(g, c, rcond, v, vec):
        _apply(minv_at, vec[0], out, n, r)
        return
    for i in range(r):
        for k in range(r):
            v[i, k] = 0.0
        v[i, i] = 1.0
    # cyclic Jacobi; an off-diagonal entry below eps ||G||_F is set to zero (a change within the
    # round-off of G itself), so the sweeps end once every entry is at that level
    for _sweep in range(50):
        fro = 0.0
        for i in range(r):
            for j in range(r):
                fro += g[i, j] * g[i, j]
        tiny = 2.220446049250313e-16 * math.sqrt(fro)
        rotated = False
        for p in range(r - 1):
            for qq in range(p + 1, r):
                apq = g[p, qq]
                if not abs(apq) > tiny:
                    g[p, qq] = 0.0
                    g[qq, p] = 0.0
                    continue
                rotated = True
                tau = (g[qq, qq] - g[p, p]) / (2.0 * apq)
                if tau >= 0.0:
                    t = 1.0 / (tau + math.sqrt(1.0 + tau * tau))
                else:
                    t = -1.0 / (-tau + math.sqrt(1.0 + tau * tau))
                cr = 1.0 / math.sqrt(1.0 + t * t)
                sr = t * cr
                for k in range(r):
                    gkp = g[k, p]
                    gkq = g[k, qq]
                    g[k, p] = cr * gkp - sr * gkq
                    g[k, qq] = sr * gkp + cr * gkq
                for k in range(r):
                    gpk = g[p, k]
                    gqk = g[qq, k]
                    g[p, k] = cr * gpk - sr * gqk
                    g[qq, k] = sr * gpk + cr * gqk
                g[p, qq] = 0.0
                g[qq, p] = 0.0
                for k in range(r):
                    vkp = v[k, p]
                    vkq = v[k, qq]
                    v[k, p] = cr * vkp - sr * vkq
                    v[k, qq] = sr * vkp + cr * vkq
        if not rotated:
            break
    wmax = g[0, 0]
    for i in range(1, r):
        wmax = max(wmax, g[i, i])
    cut = rcond * max(wmax, 1e-300)
    coef = vec[2]
    for i in range(r):
        if g[i, i] > cut:
            s = 0.0
            for k in range(r):
                s += v[k, i] * c[k]
            coef[i] = s / g[i, i]
        else:
            coef[i] = 0.0
    lam = vec[0]
    for k in range(r):
        s = 0.0
        for i in range(r):
            s += v[k, i] * coef[i]
        lam[k] = s
    _apply(minv_at, lam, out, n, r)


@_jit(allocates=False)
def _apply(minv_at, lam, out, n, r):
    """``out = M^-1 A^T lambda``."""
    for j in range(n):
        s = 0.0
        for i in range(r):
            s += minv_at[j, i] * lam[i]
        out[j] = s


@_jit(allocates=False)
def _solve_if_well_conditioned(g, c, rcond, low, vec):
    """``vec[0, :r] = G^-1 c`` by Cholesky when no eigenvalue of ``G`` can fall below
    ``rcond * max eigenvalue`` (then the minimum-norm solution is the plain solution); False,
    with ``vec[0]`` untouched, otherwise.

    The test is rigorous: ``lambda_min >= 1 / ||G^-1||_F >= 1 / ||L^-1||_F^2`` (``G = L L^T``) and
    ``lambda_max <= trace G``; the bound must clear ``rcond trace G`` tenfold, for round-off. It
    costs ``r^3 / 3`` multiplications, against tens of Jacobi sweeps of ``r^3`` each. ``low``
    (r, r) receives ``L``; ``vec[2]`` is scratch.
    """
    r = c.shape[0]
    trace = 0.0
    for i in range(r):
        trace += g[i, i]
    if not trace > 0.0:
        return False
    for j in range(r):
        d = g[j, j]
        for k in range(j):
            d -= low[j, k] * low[j, k]
        if not d > 0.0:
            return False
        ljj = math.sqrt(d)
        low[j, j] = ljj
        for i in range(j + 1, r):
            s = g[i, j]
            for k in range(j):
                s -= low[i, k] * low[j, k]
            low[i, j] = s / ljj
    x = vec[2]
    inv_fro2 = 0.0  # ||L^-1||_F^2, column by column: L x = e_j
    for j in range(r):
        for i in range(r):
            if i < j:
                x[i] = 0.0
            else:
                s = 1.0 if i == j else 0.0
                for k in range(j, i):
                    s -= low[i, k] * x[k]
                x[i] = s / low[i, i]
                inv_fro2 += x[i] * x[i]
    if not 1.0 / inv_fro2 > 10.0 * rcond * trace:
        return False
    lam = vec[0]
    for i in range(r):  # L y = c
        s = c[i]
        for k in range(i):
            s -= low[i, k] * lam[k]
        lam[i] = s / low[i, i]
    for i in range(r - 1, -1, -1):  # L^T lambda = y
        s = lam[i]
        for k in range(i + 1, r):
            s -= low[k, i] * lam[k]
        lam[i] = s / low[i, i]
    return True
