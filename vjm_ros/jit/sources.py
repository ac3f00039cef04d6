"""The files that key numba's cache of every compiled function of the package.

numba keys each cached function on the source file that defines it, and does not notice when a
function it calls from another file changes: a kernel in ``pipeline.py`` would keep running the
old ``kernels.step`` after an edit of ``kernels.py``. So every function compiled by
:func:`vjm_ros.jit.jit` is keyed on the contents of all of the package's compiled sources
(:data:`COMPILED_SOURCES`): any change to one of them recompiles them all.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1]
"""The folder of the package ``vjm_ros``."""

UNCOMPILED = frozenset({"tiers.py", "compile_server.py"})
"""Files of ``jit/`` that decide where and when the compiled code is built, never what it is:
an edit of them recompiles nothing."""

COMPILED_SOURCES = tuple(sorted(
    [*(PACKAGE / "core").rglob("*.py"),
     *(p for p in (PACKAGE / "jit").glob("*.py") if p.name not in UNCOMPILED),
     PACKAGE / "control" / "compiled.py",
     PACKAGE / "sim" / "float_text.py"]))
"""Files whose contents key every compiled function's cache: all of ``core/`` (the kernels and
what they are built from), ``jit/`` but :data:`UNCOMPILED` (numba's options), the controllers'
compiled algebra and the CSV's number formatting."""


@functools.lru_cache(maxsize=1)
def sources_stamp() -> bytes:
    """SHA-256 over the contents of :data:`COMPILED_SOURCES` (read once per process)."""
    digest = hashlib.sha256()
    for path in COMPILED_SOURCES:
        digest.update(path.relative_to(PACKAGE).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.digest()
