"""Everything the package does with numba's private internals, and nothing else.

The rest of the package uses numba's public ``njit`` only (through :mod:`vjm_ros.jit.deferred`);
what it needs beyond that goes through the functions here, each written for the numba of
``requirements/lock.txt``:

- :func:`install_locators`: numba's cache keyed on all of the compiled sources
  (:mod:`vjm_ros.jit.sources`) instead of each function's own file;
- :data:`REFCOUNT_FREE_OPTIONS`: numba's ``_nrt`` option (compile without reference counting);
- :func:`loads_lazily`: a cached function loaded without numba's refresh of its typing and
  lowering registries;
- :func:`is_dispatcher`, :func:`argument_types`, :func:`load_cached`, :func:`cache_directory`:
  what the tiered start (:mod:`vjm_ros.jit.tiers`) and the compile server
  (:mod:`vjm_ros.jit.compile_server`) ask of a dispatcher and its cache.

:data:`PRIVATE_NAMES` lists every private name used here; test/test_numba_internals.py checks
them all against the installed numba, and that numba against the lock, so that an upgrade of
numba fails there, in one place.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numba.core.dispatcher import Dispatcher

PRIVATE_NAMES = (
    "numba.core.caching.UserProvidedCacheLocator",
    "numba.core.caching.InTreeCacheLocator",
    "numba.core.caching.UserWideCacheLocator",
    "numba.core.caching._CacheLocator.get_source_stamp",
    "numba.core.caching._CacheLocator.from_function",
    "numba.core.caching.CacheImpl._locator_classes",
    "numba.core.caching.Cache.load_overload",
    "numba.core.caching.Cache._load_overload",
    "numba.core.caching.Cache._guard_against_spurious_io_errors",
    "numba.core.cpu.CPUTargetOptions._nrt",
    "numba.core.runtime.rtsys.initialize",
    "numba.core.compiler_lock.global_compiler_lock",
    "numba.core.dispatcher.Dispatcher",
    "numba.core.dispatcher.Dispatcher.typeof_pyval",
    "numba.core.dispatcher.Dispatcher.add_overload",
    "numba.core.base.BaseContext.insert_user_function",
)
"""The private classes, functions and attributes of numba used here (module path, then
attributes); a dispatcher's instance attributes are listed in :data:`DISPATCHER_ATTRIBUTES`."""

DISPATCHER_ATTRIBUTES = ("_cache", "targetctx", "overloads")
"""Instance attributes of a numba dispatcher used here (``_cache._cache_path`` besides, for a
function cached on disk)."""


# ---------------------------------------------------------------------------- cache keys
def _keyed_on(base: type, stamp: Callable[[], bytes], package: Path) -> type:
    """A numba cache locator like ``base`` whose source stamp is ``stamp()``, for the functions
    defined under ``package`` only (others fall through to numba's own locators)."""

    class Locator(base):
        def get_source_stamp(self):
            return stamp()

        @classmethod
        def from_function(cls, py_func, py_file):
            if not str(Path(py_file).resolve()).startswith(str(package)):
                return None
            return super().from_function(py_func, py_file)

    Locator.__name__ = Locator.__qualname__ = f"VjmSources{base.__name__}"
    return Locator


def install_locators(stamp: Callable[[], bytes], package: Path) -> None:
    """Put locators that key the cache of the functions defined under ``package`` on ``stamp()``
    first in numba's list."""
    from numba.core import caching

    classes = caching.CacheImpl._locator_classes
    if not any(c.__name__.startswith("VjmSources") for c in classes):
        bases = (caching.UserProvidedCacheLocator, caching.InTreeCacheLocator,
                 caching.UserWideCacheLocator)
        classes[:0] = [_keyed_on(b, stamp, package) for b in bases]


# ---------------------------------------------------------------------------- options
REFCOUNT_FREE_OPTIONS = {"_nrt": False}
"""numba's options that compile a function without reference counting (``_nrt``)."""


# ---------------------------------------------------------------------------- loading
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


def loads_lazily(dispatcher: Dispatcher) -> None:
    """Make ``dispatcher``'s cache load with :func:`_load_without_registries` (nothing to do
    where numba compiles nothing, ``NUMBA_DISABLE_JIT``)."""
    cache = getattr(dispatcher, "_cache", None)
    if cache is not None:
        cache.load_overload = functools.partial(_load_without_registries, cache)


# ---------------------------------------------------------------------------- dispatchers
def is_dispatcher(obj: object) -> bool:
    """Whether ``obj`` is a numba dispatcher (False while numba is not imported)."""
    dispatcher = sys.modules.get("numba.core.dispatcher")
    return dispatcher is not None and isinstance(obj, dispatcher.Dispatcher)


def argument_types(dispatcher: Dispatcher, args: tuple) -> tuple:
    """numba's argument types for a call of ``dispatcher`` with ``args`` (what the dispatcher
    itself computes)."""
    return tuple(dispatcher.typeof_pyval(a) for a in args)


def load_cached(dispatcher: Dispatcher, args: tuple) -> bool:
    """Whether ``dispatcher`` can run ``args`` without compiling: compiled for their types in
    this process already, or loaded now from numba's cache (as numba's own first call does)."""
    sig = argument_types(dispatcher, args)
    if sig in dispatcher.overloads:
        return True
    from numba.core.compiler_lock import global_compiler_lock

    context = dispatcher.targetctx
    with global_compiler_lock:
        result = dispatcher._cache.load_overload(sig, context)
        if result is None:
            return False
        if not result.objectmode:
            context.insert_user_function(result.entry_point, result.fndesc, [result.library])
        dispatcher.add_overload(result)
    return True


def _probe() -> float:  # pragma: no cover - never called: its dispatcher locates the cache
    return 0.0


def cache_directory() -> Path | None:
    """numba's cache directory of the package's compiled functions (``NUMBA_CACHE_DIR``, or next
    to the package, or the user's cache directory where the package is read-only), as numba
    chooses it for a function of this package, compiled nowhere; None where nothing is cached
    (``NUMBA_DISABLE_JIT``). Imports numba."""
    from numba import njit

    dispatcher = njit(cache=True)(_probe)
    path = getattr(getattr(dispatcher, "_cache", None), "_cache_path", None)
    return None if path is None else Path(path)
