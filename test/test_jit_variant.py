"""``vjm_ros.jit.variant``: a compiled copy of a function that reads other module constants.

numba takes module globals as compile-time constants and drops the branches a constant condition
never takes before typing them; the kernels use it so that the plain ``kernels.step`` compiles
none of the hub solves (``kernels.HUB_SOLVES``). The oracle here is numba's own record of what it
compiled, in a fresh process with an empty cache (loaded from a cache, a function's callees are
part of its code and never compiled on their own): the function behind the dropped branch has
no compiled signature until the copy that takes the branch runs.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from vjm_ros.jit import variant

pytest.importorskip("numba")

TOY = textwrap.dedent('''
    import json
    import numpy as np
    from vjm_ros.jit import jit, variant

    FLAG = False

    @jit
    def behind_the_flag(x):
        s = 0.0
        for i in range(x.shape[0]):
            s += x[i] * x[i]
        return s

    @jit
    def guarded(x):
        out = 1.0
        if FLAG:
            out += behind_the_flag(x)
        return out

    guarded_with_flag = variant(guarded, "guarded_with_flag", FLAG=True)

    x = np.array([1.0, 2.0])
    seen = {"plain": guarded(x), "compiled_after_plain": len(behind_the_flag.signatures)}
    seen["copy"] = guarded_with_flag(x)
    seen["compiled_after_copy"] = len(behind_the_flag.signatures)
    seen["plain_again"] = guarded(x)
    seen["copy_name"] = guarded_with_flag.py_func.__qualname__
    seen["flag_in_module"] = FLAG
    print(json.dumps(seen))
''')


def test_only_the_copy_compiles_what_a_false_module_constant_guards(tmp_path):
    (tmp_path / "toy.py").write_text(TOY)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}
    done = subprocess.run([sys.executable, "-c", "import toy"], env=env, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["plain"] == 1.0 and seen["compiled_after_plain"] == 0  # branch dropped untyped
    assert seen["copy"] == 6.0 and seen["compiled_after_copy"] == 1  # the copy takes it
    assert seen["plain_again"] == 1.0 and seen["flag_in_module"] is False  # original unchanged
    assert seen["copy_name"] == "guarded_with_flag"


def test_a_copy_names_only_globals_the_module_has():
    from vjm_ros.core import kernels

    with pytest.raises(KeyError, match="NO_SUCH_FLAG"):
        variant(kernels.step, "_bad", NO_SUCH_FLAG=True)
