"""Tiered start: the kernels run as plain Python while numba compiles them in another process.

On a machine whose numba cache does not hold the kernels yet (a first run after installing or
upgrading, a new ``NUMBA_CACHE_DIR``), compiling :func:`vjm_ros.core.kernels.step` and the block
pipeline (with its inlined copy of the step) takes 15-40 s on a 2-core machine. :class:`Tiered`
wraps such a compiled entry point:

1. its first call (after its first ``plain_calls``, which run the plain copy below: numba and
   the compiled code take longer to load than a few plain-Python calls take to run) looks into
   numba's cache, importing numba if no compiled function was needed before
   (:func:`vjm_ros.jit.deferred.activate`); when the compiled code is there (the usual case) it is
   loaded and every call goes to it, as without this module;
2. otherwise the entry point is handed to the compile server, a process of its own at a lower
   priority, on the other core (:mod:`vjm_ros.jit.compile_server`: one at a time on a machine,
   detached from the run), and calls run the function's plain-Python copy (:func:`interpreted`:
   the same source with every compiled callee replaced by its own plain copy) until the server
   has written the compiled code into numba's cache; the next call then loads it from there and
   runs compiled from then on.

The plain copy computes the same numbers, bit for bit: numba compiles without fast-math, so each
operation rounds as CPython's float arithmetic does (test/test_tiers.py holds both equal on the
thesis scenes and the hub solves). One rule keeps it so: kernels write ``x * x``, not ``x ** 2``,
which CPython computes with ``pow`` (an ulp off at times). A run that ends before the server has
finished leaves it to finish what it was asked for, and says so on stderr: the runs after it
find the compiled code in the cache.

``VJM_TIERED=0`` in the environment switches this off: the first call then compiles in the
calling process, as numba does on its own.
"""

from __future__ import annotations

import os
import threading
import time
import types
from typing import TYPE_CHECKING

from vjm_ros.jit import deferred as jit
from vjm_ros.jit import numba_internals
from vjm_ros.jit.compile_server import server

if TYPE_CHECKING:
    from collections.abc import Callable

ENVIRONMENT = "VJM_TIERED"
"""Environment variable: ``0`` compiles in the calling process (no plain-Python tier)."""


def enabled() -> bool:
    """Whether entry points missing from numba's cache start as plain Python."""
    return os.environ.get(ENVIRONMENT, "1") != "0"


def compile_first() -> None:
    """Compile in this process, and in the processes it starts, before the first call (sets
    ``VJM_TIERED=0``): for the benchmarks and studies, which time the compiled code."""
    os.environ[ENVIRONMENT] = "0"


# ---------------------------------------------------------------------------- plain copies
class _Namespace:
    """A module's globals, read by attribute (``K.EVALUATE``), in a plain copy's globals."""

    __slots__ = ("_names",)

    def __init__(self, names: dict):
        object.__setattr__(self, "_names", names)

    def __getattr__(self, name: str):
        try:
            return self._names[name]
        except KeyError:
            raise AttributeError(name) from None


_PLAIN: dict[int, types.FunctionType] = {}
_GLOBALS: dict[int, dict] = {}
_MODULES: dict[int, _Namespace] = {}


def _is_ours(module: types.ModuleType) -> bool:
    return getattr(module, "__name__", "").startswith("vjm_ros.")


def _plain_globals(names: dict) -> dict:
    """A copy of the globals ``names`` in which compiled functions are plain copies and this
    package's modules are namespaces of plain copies."""
    copy = _GLOBALS.get(id(names))
    if copy is not None:
        return copy
    copy = _GLOBALS[id(names)] = dict(names)
    for key, value in names.items():
        if jit.is_compiled(value):
            copy[key] = interpreted(value)
        elif isinstance(value, types.ModuleType) and _is_ours(value):
            space = _MODULES.get(id(value))
            if space is None:  # the module's plain globals, filled in full by the time of a call
                space = _MODULES[id(value)] = _Namespace(_plain_globals(vars(value)))
            copy[key] = space
    return copy


def interpreted(function: Callable[..., object]) -> Callable[..., object]:
    """The plain-Python copy of a compiled function: its source, with every compiled function it
    reaches (through its module's globals, a module, or a copy made by
    :func:`vjm_ros.jit.variant`) replaced by that function's plain copy. A function that is
    not compiled (numba missing, ``NUMBA_DISABLE_JIT``) is returned as it is."""
    if not jit.is_compiled(function):
        return function
    copy = _PLAIN.get(id(function))
    if copy is None:
        fn = function.py_func
        # the globals are registered before they are filled: functions that reach each other
        # share them
        copy = types.FunctionType(fn.__code__, _plain_globals(fn.__globals__), fn.__name__,
                                  fn.__defaults__, fn.__closure__)
        copy.__qualname__ = fn.__qualname__
        copy.__doc__ = fn.__doc__
        _PLAIN[id(function)] = copy
    return copy


# ---------------------------------------------------------------------------- numba's cache
def load_cached(dispatcher: Callable[..., object], args: tuple) -> bool:
    """Whether ``dispatcher`` can run ``args`` without compiling: compiled for their types in
    this process already, or loaded now from numba's cache (as numba's own first call does)."""
    return numba_internals.load_cached(jit.compiled(dispatcher), args)


# ---------------------------------------------------------------------------- entry points
class Tiered:
    """A compiled entry point that runs as plain Python until its compiled code is available.

    Parameters
    ----------
    module : module
        Module whose global ``name`` is the compiled function (a numba dispatcher).
    name : str
    plain_calls : int
        Calls that run as plain Python before the compiled code is loaded at all, while entry
        points start as plain Python (:func:`enabled`): loading a function from numba's cache
        takes 0.05-0.1 s, dozens of plain-Python evaluations of a kernel, so a process that calls
        it only a few times (a scene's checks, a first sample) is done sooner without it. The
        outputs are the same either way (the plain copy rounds as the compiled code does).
        :meth:`prepare` and :meth:`eager` end this at once.

    Attributes
    ----------
    compiled : callable
        The compiled function.
    """

    def __init__(self, module: types.ModuleType, name: str, plain_calls: int = 0):
        self.compiled = getattr(module, name)
        self.module = module.__name__
        self.name = name
        self._ready = not jit.is_compiled(self.compiled)
        self._request: int | None = None
        self._plain = None
        self._plain_left = max(int(plain_calls), 0)
        self._lock = threading.Lock()

    def __call__(self, *args):
        if self._ready:
            return self.compiled(*args)
        return self._call(args)

    def _resolve(self) -> None:
        """The dispatcher in place of the :class:`~vjm_ros.jit.deferred.Deferred` function (numba
        imported now if it was not)."""
        self.compiled = jit.compiled(self.compiled)

    def dispatcher(self) -> Callable[..., object]:
        """The compiled function itself (numba imported now if it was not), not called: what
        runs once :attr:`ready`."""
        self._resolve()
        return self.compiled

    @property
    def ready(self) -> bool:
        """Whether calls run the compiled code (loading it from numba's cache now if the compile
        server has written it)."""
        if not self._ready and self._request is not None and server().done(self._request):
            self._ready = True
        return self._ready

    @property
    def tier(self) -> str:
        """``"compiled"``, ``"plain"`` (plain Python while the compile server compiles) or ``"new"`` (not
        called yet, or only its first ``plain_calls``)."""
        if self.ready:
            return "compiled"
        return "new" if self._request is None else "plain"

    def eager(self) -> None:
        """Load the compiled code (or have it compiled) at the next call, with no more calls
        as plain Python before (``plain_calls`` spent)."""
        self._plain_left = 0

    def prepare(self, *args: object) -> None:
        """Load the compiled code for calls with arguments like ``args``, or have it compiled in
        the background, without calling the function."""
        self._plain_left = 0
        with self._lock:
            if self._ready or self._request is not None:
                return
            start = time.perf_counter()
            try:
                self._resolve()
                # a plain function where numba compiles nothing (NUMBA_DISABLE_JIT); with the
                # tiers off, loaded from the cache now too, else compiled at the first call
                if (not jit.is_compiled(self.compiled) or load_cached(self.compiled, args)
                        or not enabled()):
                    self._ready = True
                    return
                self._request = server().request(self.module, self.name, args)
            finally:
                _LOADING.seconds = loading_seconds() + time.perf_counter() - start

    def _call(self, args: tuple):
        if self._plain_left > 0 and self._request is None and enabled():
            self._plain_left -= 1  # a race between threads costs at most a call either way
        else:
            self.prepare(*args)
            if self.ready:
                return self.compiled(*args)
        if self._plain is None:
            self._plain = interpreted(self.compiled)
        return self._plain(*args)


_LOADING = threading.local()


def loading_seconds() -> float:
    """Wall time the calling thread has spent in :meth:`Tiered.prepare` so far, s: importing
    numba, loading entry points from its cache, handing them to the compile server. ``vjm run``
    leaves it out of a run's ``wall_time``, as it did when the loading came before its clock."""
    return getattr(_LOADING, "seconds", 0.0)


_ENTRIES: dict[tuple[str, str], Tiered] = {}


def entry(module: types.ModuleType, name: str, plain_calls: int = 0) -> Tiered:
    """The process's one :class:`Tiered` of ``module.name`` (shared by every caller;
    ``plain_calls`` is the first caller's)."""
    key = (module.__name__, name)
    found = _ENTRIES.get(key)
    if found is None:
        found = _ENTRIES.setdefault(key, Tiered(module, name, plain_calls))
    return found
