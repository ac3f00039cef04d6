"""What keys numba's cache (``core.jit.COMPILED_SOURCES``): every source of compiled code, and not
the modules that only decide where and when it is compiled (``core.jit.UNCOMPILED_CORE``: the
tiers and the compile server), whose edits would otherwise recompile every kernel for nothing.

Oracle: the import graph of the compiled modules in a fresh process (what numba can reach when it
types them) and the sources themselves (which define compiled functions).
"""

from __future__ import annotations

import importlib
import types

from vjm_ros.core import jit

COMPILED_MODULES = ["vjm_ros.core.kernels", "vjm_ros.core.pipeline", "vjm_ros.core.float_text",
                    "vjm_ros.control.compiled"]
"""The modules whose functions numba compiles (with what they import)."""


def test_the_modules_that_place_the_compile_are_not_keyed():
    keyed = {p.name for p in jit.COMPILED_SOURCES}
    assert jit.UNCOMPILED_CORE == {"tiers.py", "compile_server.py"}
    assert not keyed & jit.UNCOMPILED_CORE
    core = jit._PACKAGE / "core"
    for name in jit.UNCOMPILED_CORE:
        text = (core / name).read_text()
        assert "@jit" not in text and "variant(" not in text, name  # no compiled function


def _origin(value) -> str | None:
    """The module a global of a compiled module comes from (None for plain values)."""
    if isinstance(value, types.ModuleType):
        return value.__name__
    value = getattr(value, "py_func", value)  # a dispatcher or a deferred compiled function
    return getattr(value, "__module__", None) if callable(value) else None


def test_the_key_covers_every_module_the_compiled_code_reads():
    """The globals of the compiled modules (the functions, modules and classes numba can reach
    when it types them), followed through every module of the package they lead to: each comes
    from a keyed file, and none from the tiers or the compile server."""
    keyed = {p.relative_to(jit._PACKAGE.parent).with_suffix("").as_posix().replace("/", ".")
             for p in jit.COMPILED_SOURCES}
    seen, todo = set(), list(COMPILED_MODULES)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        for value in vars(importlib.import_module(name)).values():
            origin = _origin(value)
            if origin and origin.startswith("vjm_ros.core.") and origin not in seen:
                todo.append(origin)
    reached = {m for m in seen if m.startswith("vjm_ros.")}
    assert {"vjm_ros.core.kernels", "vjm_ros.core.small_linalg", "vjm_ros.core.hub_linalg",
            "vjm_ros.core.jit"} <= reached  # the walk does follow the callees
    assert reached <= keyed, reached - keyed
