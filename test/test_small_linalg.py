"""The compiled minimum-norm closure correction, both ways it solves, and the cache keys.

Oracle: numpy's least-squares solution with the same cut (``numpy.linalg.lstsq``'s ``rcond`` is
relative to the largest singular value, which for a symmetric positive semi-definite G is its
largest eigenvalue: the same rule as the kernel). Tolerance 1e-10 relative: both solve the same
well-posed system in double precision (condition numbers here below 1e4).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vjm_ros.core import jit, kernels, small_linalg

pytest.importorskip("numba")


def _correction(m, a, c, rcond=1e-10):
    n, r = a.shape[1], a.shape[0]
    lu, piv = m.copy(), np.empty(n, dtype=np.int64)
    small_linalg.lu_factor(lu, piv)
    out, vec = np.empty(n), np.empty((3, max(n, r)))
    small_linalg.min_norm_correction(lu, piv, a, c, rcond, out, np.empty((n, r)),
                                     np.empty((r, r)), np.empty((r, r)), vec)
    return out, vec[0, :r].copy()


@pytest.mark.parametrize("r", [1, 2, 4, 8, 30])
def test_well_conditioned_systems_take_the_plain_solution(r):
    rng = np.random.default_rng(r)
    n = r + 3
    q = rng.normal(size=(n, n))
    m = q @ q.T + n * np.eye(n)  # a mass matrix: symmetric positive definite
    a = rng.normal(size=(r, n))
    c = rng.normal(size=r)
    out, lam = _correction(m, a, c)
    g = a @ np.linalg.solve(m, a.T)
    np.testing.assert_allclose(lam, np.linalg.solve(g, c), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(out, np.linalg.solve(m, a.T @ lam), rtol=1e-10, atol=1e-12)


def test_rank_deficient_systems_drop_the_unconstrained_directions():
    """Two identical rows (a redundant closure): the Cholesky test must refuse, and the Jacobi
    path returns the minimum-norm multipliers."""
    rng = np.random.default_rng(7)
    n = 5
    m = np.diag(rng.uniform(1.0, 3.0, n))
    row = rng.normal(size=n)
    a = np.vstack([row, row, rng.normal(size=n)])
    c = np.array([1.0, 1.0, 0.5])  # consistent: the repeated rows ask the same
    g = a @ np.linalg.solve(m, a.T)
    out, lam = _correction(m, a, c)
    expected = np.linalg.lstsq(g, c, rcond=1e-10)[0]
    np.testing.assert_allclose(lam, expected, rtol=1e-9, atol=1e-12)
    assert lam[0] == pytest.approx(lam[1], rel=1e-9)  # the split between the twins is even


def test_compiled_functions_are_keyed_on_every_compiled_source():
    """An edit of small_linalg.py must recompile kernels.step, which calls it (numba alone keys a
    cache on the defining file only)."""
    assert Path(small_linalg.__file__).resolve() in jit.COMPILED_SOURCES
    assert Path(kernels.__file__).resolve() in jit.COMPILED_SOURCES
    if jit.LOCATORS_INSTALLED:
        locator = kernels.step._cache._impl.locator
        assert locator.get_source_stamp() == jit.sources_stamp()
