"""numba's ``njit`` with the project's options, or the plain function where numba is missing.

numba keys each cached function on the source file that defines it, and does not notice when a
function it calls from another file changes: a kernel in ``pipeline.py`` would keep running the
old ``kernels.step`` after an edit of ``kernels.py``. So every function compiled here is keyed on
the contents of all of the package's compiled sources (:data:`COMPILED_SOURCES`): any change to
one of them recompiles them all.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.machinery
import importlib.util
import sys
import types
from pathlib import Path


def _load_blas_wrappers() -> bool:
    """Load ``scipy.linalg.cython_blas`` alone, without the rest of ``scipy.linalg``.

    numba checks that BLAS is there before it loads or compiles its first function, by importing
    ``scipy.linalg.cython_blas``; the import of its package ``scipy.linalg`` takes 0.1-0.2 s
    (``scipy._lib`` imports ``numpy.f2py`` and ``numpy.testing``), a quarter of a warm
    ``vjm run``, for a module none of the kernels uses. Loaded from its file first, the module
    is the same (numba finds it in ``sys.modules``), and ``import scipy.linalg`` later still
    loads the rest. Does nothing, and returns False, where ``scipy.linalg`` is imported already
    or the module is not found as a file of the installed scipy (numba then imports it itself).
    """
    name = "scipy.linalg.cython_blas"
    if "scipy.linalg" in sys.modules or name in sys.modules:
        return False
    try:
        scipy_spec = importlib.util.find_spec("scipy")
        folder = Path(next(iter(scipy_spec.submodule_search_locations))) / "linalg"
        path = next(folder / f"cython_blas{s}" for s in importlib.machinery.EXTENSION_SUFFIXES
                    if (folder / f"cython_blas{s}").is_file())
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    except Exception:  # noqa: BLE001 - any other layout: numba imports the module itself
        sys.modules.pop(name, None)
        return False
    return True


try:  # numba is optional: without it the kernels run as plain Python
    from numba import njit as _njit

    HAVE_NUMBA = True
    _load_blas_wrappers()
except ImportError:  # pragma: no cover - exercised only where numba is missing
    HAVE_NUMBA = False

_PACKAGE = Path(__file__).resolve().parents[1]

COMPILED_SOURCES = tuple(sorted(
    [*(_PACKAGE / "core").glob("*.py"), _PACKAGE / "control" / "compiled.py"]))
"""Files whose contents key every compiled function's cache: all of ``core/`` (the kernels and
what they are built from) and the controllers' compiled algebra."""


@functools.lru_cache(maxsize=1)
def sources_stamp() -> bytes:
    """SHA-256 over the contents of :data:`COMPILED_SOURCES` (read once per process)."""
    digest = hashlib.sha256()
    for path in COMPILED_SOURCES:
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.digest()


def _keyed_on_sources(base: type) -> type:
    """A numba cache locator like ``base`` whose source stamp is :func:`sources_stamp`, for the
    functions of this package only (others fall through to numba's own locators)."""

    class Locator(base):
        def get_source_stamp(self):
            return sources_stamp()

        @classmethod
        def from_function(cls, py_func, py_file):
            if not str(Path(py_file).resolve()).startswith(str(_PACKAGE)):
                return None
            return super().from_function(py_func, py_file)

    Locator.__name__ = Locator.__qualname__ = f"VjmSources{base.__name__}"
    return Locator


def _install_locators() -> bool:
    """Put the source-keyed locators first in numba's list; False where numba's caching layout
    is not the one expected (numba's own per-file keys then apply)."""
    try:
        from numba.core import caching

        bases = (caching.UserProvidedCacheLocator, caching.InTreeCacheLocator,
                 caching.UserWideCacheLocator)
        impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
        classes = impl._locator_classes
    except (ImportError, AttributeError):  # pragma: no cover - another numba layout
        return False
    if not any(c.__name__.startswith("VjmSources") for c in classes):
        classes[:0] = [_keyed_on_sources(b) for b in bases]
    return True


LOCATORS_INSTALLED = HAVE_NUMBA and _install_locators()
"""Whether compiled functions are keyed on :func:`sources_stamp`."""


def _refcount_free_supported() -> bool:
    """Whether this numba takes the ``_nrt`` option (compile without reference counting)."""
    try:
        from numba.core.cpu import CPUTargetOptions

        return hasattr(CPUTargetOptions, "_nrt")
    except ImportError:  # pragma: no cover - another numba layout
        return False


REFCOUNT_FREE = HAVE_NUMBA and _refcount_free_supported()
"""Whether functions that create no arrays are compiled without numba's reference counting."""


def _load_without_registries(cache, sig, target_context):
    """numba's ``Cache.load_overload`` without its refresh of ``target_context``.

    numba refreshes the target context before it looks into a function's cache: that imports and
    installs every typing and lowering registry it has (about 0.1 s, a fifth of a warm
    ``vjm run``), which only compiling needs. Rebuilding a cached function needs its code and the
    runtime, which is initialized here as the refresh would; on a miss numba compiles, and its
    compiler refreshes the context itself.
    """
    from numba.core.runtime import rtsys

    rtsys.initialize(target_context)
    with cache._guard_against_spurious_io_errors():
        return cache._load_overload(sig, target_context)


def _loads_lazily(dispatcher) -> None:
    """Make ``dispatcher``'s cache load with :func:`_load_without_registries` where numba's
    cache has the layout it is written for (otherwise numba's own loading stays)."""
    cache = getattr(dispatcher, "_cache", None)
    if all(hasattr(cache, name) for name in ("_load_overload", "_guard_against_spurious_io_errors",
                                             "load_overload")):
        cache.load_overload = functools.partial(_load_without_registries, cache)


def jit(fn=None, *, allocates: bool = True, inline: str = "never"):
    """Compile ``fn`` with numba (no Python objects, cached on disk), or return it unchanged.

    ``allocates=False`` declares that ``fn`` (and everything it calls) creates no arrays, only
    reads and writes the ones it is given: it is then compiled without numba's reference
    counting (numba's ``_nrt`` option). Every array argument, tuple member and view otherwise
    costs an atomic increment and decrement per call; in the block pipeline, which makes three
    kernel calls per tick with some 25 arrays each, that was a third of a four-bar's tick
    (rk4, exact closure: 4.3 -> 2.9 us, the same numbers). numba refuses to compile such a
    function if it does create an array, so the declaration cannot silently be wrong. Usable
    as ``@jit`` or ``@jit(allocates=False)``.

    ``inline="always"``: numba inlines the function's body into each compiled caller instead of
    compiling it as a function of its own; for a function with one compiled caller, that saves
    compiling (and optimizing and emitting machine code for) a second copy of everything it
    calls.
    """
    if fn is None:
        return functools.partial(jit, allocates=allocates, inline=inline)
    if not HAVE_NUMBA:
        return fn
    options = {"cache": True, "nogil": True, "error_model": "numpy", "inline": inline}
    if not allocates and REFCOUNT_FREE:
        options["_nrt"] = False
    dispatcher = _njit(**options)(fn)
    _loads_lazily(dispatcher)
    dispatcher.vjm_options = options
    return dispatcher


def variant(compiled, name: str, *, inline: str | None = None, **constants):
    """A second compiled copy of ``compiled`` (made by :func:`jit`) that reads ``constants`` in
    place of its module's globals of those names, under the name ``name``; ``inline``, when
    given, replaces its ``inline`` option (``"always"``: a copy that numba inlines into each
    compiled caller, see :func:`jit`).

    numba takes a module's globals as compile-time constants and drops the branches that a
    constant condition never takes before it types anything: code guarded by ``if FLAG:`` with
    ``FLAG = False`` is not compiled at all in the original, and is in a copy made with
    ``FLAG=True``. Each copy has its own entry in numba's cache (``name`` is its qualified
    name). Globals are read when the copy is made: make it at the end of the module.
    Without numba, the copy is the plain function with those globals.
    """
    fn = getattr(compiled, "py_func", compiled)
    missing = [k for k in constants if k not in fn.__globals__]
    if missing:
        raise KeyError(f"{fn.__qualname__}: no module global named {missing}")
    namespace = dict(fn.__globals__)
    namespace.update(constants)
    copy = types.FunctionType(fn.__code__, namespace, name, fn.__defaults__, fn.__closure__)
    copy.__qualname__ = name
    copy.__doc__ = fn.__doc__
    copy.__module__ = fn.__module__
    if not HAVE_NUMBA:
        return copy
    options = dict(compiled.vjm_options)
    if inline is not None:
        options["inline"] = inline
    dispatcher = _njit(**options)(copy)
    _loads_lazily(dispatcher)
    dispatcher.vjm_options = options
    return dispatcher
