"""``core.jit.variant``: a compiled copy of a function that reads other module constants.

numba takes module globals as compile-time constants and drops the branches a constant condition
never takes before typing them; the kernels use it so that the plain ``kernels.step`` compiles
none of the hub solves (``kernels.HUB_SOLVES``). The oracle here is numba's own record of what it
compiled: the function behind the dropped branch has no compiled signature until the copy that
takes the branch runs.
"""

from __future__ import annotations

import numpy as np
import pytest

from vjm_ros.core.jit import jit, variant

pytest.importorskip("numba")

FLAG = False


@jit
def _behind_the_flag(x):
    s = 0.0
    for i in range(x.shape[0]):
        s += x[i] * x[i]
    return s


@jit
def _guarded(x):
    out = 1.0
    if FLAG:
        out += _behind_the_flag(x)
    return out


_guarded_with_flag = variant(_guarded, "_guarded_with_flag", FLAG=True)


def test_the_plain_function_compiles_nothing_behind_a_false_constant():
    x = np.array([1.0, 2.0])
    assert _guarded(x) == 1.0
    assert _behind_the_flag.signatures == []  # the branch was dropped before typing
    assert _guarded_with_flag(x) == 6.0  # the copy takes it, and compiles the callee
    assert len(_behind_the_flag.signatures) == 1
    assert _guarded(x) == 1.0  # the original is unchanged by the copy


def test_a_copy_is_a_function_of_its_own_with_its_own_name():
    assert _guarded_with_flag.py_func.__qualname__ == "_guarded_with_flag"
    assert _guarded_with_flag.py_func.__code__ is _guarded.py_func.__code__
    assert _guarded_with_flag.py_func.__globals__["FLAG"] is True
    assert FLAG is False


def test_a_copy_names_only_globals_the_module_has():
    with pytest.raises(KeyError, match="NO_SUCH_FLAG"):
        variant(_guarded, "_bad", NO_SUCH_FLAG=True)
