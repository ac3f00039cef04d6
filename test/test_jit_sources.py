"""What keys numba's cache (``vjm_ros.jit.sources.COMPILED_SOURCES``): every source of compiled
code, and not the modules that only decide where and when it is compiled
(``vjm_ros.jit.sources.UNCOMPILED``: the tiers and the compile server), whose edits would otherwise
recompile every kernel for nothing.

Oracle: the import graph of the compiled modules in a fresh process (what numba can reach when it
types them) and the sources themselves (which define compiled functions).
"""

from __future__ import annotations

import importlib
import types

from vjm_ros.jit import sources

COMPILED_MODULES = ["vjm_ros.core.kernels", "vjm_ros.core.pipeline", "vjm_ros.sim.float_text",
                    "vjm_ros.control.compiled"]
"""The modules whose functions numba compiles (with what they import)."""

FOLLOWED = ("vjm_ros.core.", "vjm_ros.jit.")
"""The packages whose modules the walk follows from the globals of the compiled ones."""


def test_the_modules_that_place_the_compile_are_not_keyed():
    folder = sources.PACKAGE / "jit"
    unkeyed = {folder / name for name in sources.UNCOMPILED}
    assert sources.UNCOMPILED == {"tiers.py", "compile_server.py"}
    assert all(path.is_file() for path in unkeyed)
    assert not set(sources.COMPILED_SOURCES) & unkeyed
    for path in unkeyed:
        text = path.read_text()
        assert "@jit" not in text and "variant(" not in text, path  # no compiled function


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
    keyed = {p.relative_to(sources.PACKAGE.parent).with_suffix("").as_posix().replace("/", ".")
             for p in sources.COMPILED_SOURCES}
    keyed |= {name.removesuffix(".__init__") for name in keyed}  # a package is its __init__.py
    seen, todo = set(), list(COMPILED_MODULES)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        for value in vars(importlib.import_module(name)).values():
            origin = _origin(value)
            if origin and origin.startswith(FOLLOWED) and origin not in seen:
                todo.append(origin)
    reached = {m for m in seen if m.startswith("vjm_ros.")}
    assert {"vjm_ros.core.kernels", "vjm_ros.core.small_linalg", "vjm_ros.core.hub_linalg",
            "vjm_ros.jit.deferred"} <= reached  # the walk does follow the callees
    assert reached <= keyed, reached - keyed
