"""The compiled minimum-norm closure correction, both ways it solves, and the cache keys.

Oracle: numpy's least-squares solution with the same cut (``numpy.linalg.lstsq``'s ``rcond`` is
relative to the largest singular value, which for a symmetric positive semi-definite G is its
largest eigenvalue: the same rule as the kernel). Tolerance 1e-10 relative: both solve the same
well-posed system in double precision (condition numbers here below 1e4).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vjm_ros.core import kernels, small_linalg
from vjm_ros.jit import deferred as jit
from vjm_ros.jit.sources import COMPILED_SOURCES, sources_stamp

pytest.importorskip("numba")


def _correction(m, a, c, rcond=1e-10, blocks=None):
    n, r = a.shape[1], a.shape[0]
    blocks = np.array([0, n] if blocks is None else blocks, dtype=np.int64)
    lu, piv = m.copy(), np.empty(n, dtype=np.int64)
    assert small_linalg.lu_factor_blocks(lu, piv, blocks) == 0
    out, vec = np.empty(n), np.empty((3, max(n, r)))
    small_linalg.min_norm_correction(lu, piv, a, c, rcond, out, np.empty((n, r)),
                                     np.empty((r, r)), np.empty((r, r)), vec, blocks,
                                     np.empty((r, len(blocks) - 1), dtype=np.int64))
    return out, vec[0, :r].copy()


def _block_diagonal(rng, sizes):
    n = sum(sizes)
    m = np.zeros((n, n))
    start = 0
    for k in sizes:
        q = rng.normal(size=(k, k))
        m[start:start + k, start:start + k] = q @ q.T + k * np.eye(k)
        start += k
    return m, np.cumsum([0, *sizes])


@pytest.mark.parametrize("sizes", [(1,), (2, 2, 2), (3, 1, 2, 4), (2,) * 16])
def test_block_factors_equal_the_dense_ones(sizes):
    """A mass matrix of independent chains factored block by block: the same numbers as the
    dense factorization (the skipped entries are zeros), and solves agree with numpy."""
    rng = np.random.default_rng(len(sizes))
    m, blocks = _block_diagonal(rng, sizes)
    n = m.shape[0]
    dense, dpiv = m.copy(), np.empty(n, dtype=np.int64)
    small_linalg.lu_factor_blocks(dense, dpiv, np.array([0, n], dtype=np.int64))
    lu, piv = m.copy(), np.empty(n, dtype=np.int64)
    small_linalg.lu_factor_blocks(lu, piv, blocks)
    assert np.array_equal(piv, dpiv)
    for b in range(len(blocks) - 1):  # within each block bit for bit (outside: zeros of any sign)
        sl = slice(blocks[b], blocks[b + 1])
        assert np.array_equal(lu[sl, sl], dense[sl, sl])
    x = rng.normal(size=n)
    y = x.copy()
    small_linalg.lu_solve_blocks(lu, piv, y, blocks)
    np.testing.assert_allclose(y, np.linalg.solve(m, x), rtol=1e-12, atol=1e-14)


def test_correction_on_blocks_touching_few_chains():
    """Rows joining the first chain to each other one (a star of hinges), as the closures of
    chains meeting at one pin: the blockwise correction against numpy's dense solution."""
    rng = np.random.default_rng(3)
    sizes = (2,) * 8
    m, blocks = _block_diagonal(rng, sizes)
    n, rows = m.shape[0], []
    for k in range(1, len(sizes)):
        for _ in range(2):
            row = np.zeros(n)
            row[0:2] = rng.normal(size=2)
            row[2 * k:2 * k + 2] = rng.normal(size=2)
            rows.append(row)
    a = np.array(rows)
    c = rng.normal(size=len(rows))
    out, lam = _correction(m, a, c, blocks=blocks)
    dense_out, dense_lam = _correction(m, a, c)  # one block: the dense loops
    g = a @ np.linalg.solve(m, a.T)
    # tolerance: a well-posed 14x14 system in double precision (condition number below 1e4)
    np.testing.assert_allclose(lam, np.linalg.solve(g, c), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out, np.linalg.solve(m, a.T @ lam), rtol=1e-9, atol=1e-12)
    # the same sums in the same order as the dense loops: equal to the last bit
    assert np.array_equal(lam, dense_lam) and np.array_equal(out, dense_out)


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
    assert Path(small_linalg.__file__).resolve() in COMPILED_SOURCES
    assert Path(kernels.__file__).resolve() in COMPILED_SOURCES
    jit.activate()  # numba is imported when a compiled function is first needed
    if jit.LOCATORS_INSTALLED:
        locator = kernels.step._cache._impl.locator
        assert locator.get_source_stamp() == sources_stamp()


def test_numba_starts_without_importing_scipy_linalg():
    """numba's BLAS check finds scipy.linalg.cython_blas loaded alone (jit/deferred.py), so a start
    does not import all of scipy.linalg; numba's BLAS and scipy.linalg still work after it."""
    code = "\n".join([
        "import sys",
        "import numpy as np",
        "from vjm_ros.jit import deferred as jit",
        "jit.activate()",  # imports numba, as the first compiled function needed does
        "from numba import njit",
        "from numba.core.registry import cpu_target",
        "cpu_target.target_context.refresh()",  # what numba does before its first load
        "print('scipy.linalg' in sys.modules, 'scipy.linalg.cython_blas' in sys.modules)",
        "print(njit(lambda a, b: np.dot(a, b))(np.eye(2) * 2.0, np.ones(2)).tolist())",
        "import scipy.linalg",
        "print(scipy.linalg.solve(np.eye(2) * 4.0, np.ones(2)).tolist())",
    ])
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)  # a hang guard: the check takes ~2 s
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[:3] == ["False True", "[2.0, 2.0]", "[0.25, 0.25]"]


def test_compiled_callers_pass_no_literal_arguments_to_the_kernel():
    """A literal argument (``8``, ``-1``) of kernels.step in a compiled caller makes numba compile
    a whole further copy of the kernel for that signature; the block pipeline passes names
    (``K.NO_ROW``), so every signature of step is of plain types."""
    from vjm_ros.scene.loader import load_scene
    from vjm_ros.sim.samples import SampleBlock
    from vjm_ros.sim.settings import SimulationSettings
    from vjm_ros.sim.simulator import Simulator

    sc = load_scene("four_bar")
    sim = Simulator(sc.model, SimulationSettings(integrator="rk4", closure="exact",
                                                 projection=True), sc.gains)
    assert sim.blocks_compiled()
    sim.advance_block(SampleBlock(sc.model, 2), 2)  # projection and observation included
    assert kernels.step.signatures
    literal = [s for s in kernels.step.signatures if any("Literal" in str(t) for t in s)]
    assert not literal, literal
