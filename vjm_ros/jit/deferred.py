"""numba's ``njit`` with the project's options, or the plain function where numba is missing.

numba is imported when the first compiled function is needed, not when the package is: until
then :func:`jit` and :func:`variant` give :class:`Deferred` functions, and :func:`activate`
(run by the first call of one of them, or by the tiers' loading,
:mod:`vjm_ros.jit.tiers`) imports numba, makes every deferred function's dispatcher and puts
the dispatchers in the modules' places of the deferred functions. Importing numba and loading the
kernels from its cache takes 0.3-0.4 s, more than half of a warm ``vjm run``; a run whose first
ticks run as plain Python (:mod:`vjm_ros.jit.tiers`) has its first tick without it, and a
command that needs a few kernel evaluations only (a one-tick run, a scene's checks) never loads
numba at all.

Every function compiled here is keyed in numba's cache on the contents of all of the package's
compiled sources (:mod:`vjm_ros.jit.sources`), not on its own file only. What this needs of
numba's private internals is in :mod:`vjm_ros.jit.numba_internals`, and only there.
"""

from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
import sys
import threading
import types
from pathlib import Path
from typing import TYPE_CHECKING

from vjm_ros.jit import numba_internals
from vjm_ros.jit.sources import PACKAGE, sources_stamp

if TYPE_CHECKING:
    from collections.abc import Callable


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


def _numba_installed() -> bool:
    """Whether numba can be imported (looked up without importing it)."""
    if "numba" in sys.modules:
        return sys.modules["numba"] is not None
    try:
        return importlib.util.find_spec("numba") is not None
    except (ImportError, ValueError):  # pragma: no cover - a broken installation
        return False


HAVE_NUMBA = _numba_installed()
"""Whether numba is installed: compiled functions then run as machine code once it is imported
(:func:`activate`); otherwise they are the plain functions."""

LOCATORS_INSTALLED = False
"""Whether compiled functions are keyed on :func:`~vjm_ros.jit.sources.sources_stamp` (set by
:func:`activate`)."""

REFCOUNT_FREE = False
"""Whether functions that create no arrays are compiled without numba's reference counting (set
by :func:`activate`)."""


# ---------------------------------------------------------------------------- deferred numba
class Deferred:
    """A function to be compiled by numba, before numba is imported.

    Called, or asked for anything a numba dispatcher has (``signatures``, ``compile``...), it
    imports numba (:func:`activate`) and hands over to its dispatcher. ``py_func`` is the plain
    function, as a dispatcher's is.
    """

    def __init__(self, fn: Callable[..., object], options: dict):
        self.py_func = fn
        self.vjm_options = options
        self.dispatcher = None
        for name in ("__name__", "__qualname__", "__doc__", "__module__"):
            setattr(self, name, getattr(fn, name, None))

    def __call__(self, *args):
        return compiled(self)(*args)

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(compiled(self), name)

    def __repr__(self) -> str:
        return f"<deferred compiled function {self.__qualname__}>"


_DEFERRED: list[Deferred] = []
_ACTIVE = False
_ACTIVATING = threading.RLock()


def is_compiled(obj: object) -> bool:
    """Whether ``obj`` is a compiled function: a numba dispatcher or a :class:`Deferred`."""
    return isinstance(obj, Deferred) or numba_internals.is_dispatcher(obj)


def compiled(obj: Callable[..., object]) -> Callable[..., object]:
    """The dispatcher of a :class:`Deferred` (importing numba now if need be), ``obj`` itself
    for anything else."""
    if not isinstance(obj, Deferred):
        return obj
    if obj.dispatcher is None:
        activate()
    return obj.dispatcher


def active() -> bool:
    """Whether :func:`activate` has run (numba imported, where it is installed)."""
    return _ACTIVE


def _options(options: dict) -> dict:
    """numba's options for the project's (``allocates``, ``inline``)."""
    numba_options = {"cache": True, "nogil": True, "error_model": "numpy",
                     "inline": options["inline"]}
    if not options["allocates"]:
        numba_options.update(numba_internals.REFCOUNT_FREE_OPTIONS)
    return numba_options


def _make(fn, options: dict):
    """The dispatcher of ``fn``, or ``fn`` itself where numba is missing."""
    if not HAVE_NUMBA:
        return fn
    from numba import njit

    dispatcher = njit(**_options(options))(fn)
    numba_internals.loads_lazily(dispatcher)
    dispatcher.vjm_options = options
    return dispatcher


def _rebind(names: dict) -> None:
    """Put dispatchers in the places of the deferred functions among ``names`` (globals)."""
    for key, value in list(names.items()):
        if isinstance(value, Deferred) and value.dispatcher is not None:
            names[key] = value.dispatcher


def activate() -> bool:
    """Import numba, make the dispatcher of every :class:`Deferred` and put it in the deferred
    function's place in the modules' globals (and in the namespaces of :func:`variant` copies),
    so that numba, typing a function, finds its compiled callees. Functions made after this are
    compiled functions at once. Returns :data:`HAVE_NUMBA`; where numba fails to import, the
    plain functions take the deferred ones' places."""
    global _ACTIVE, HAVE_NUMBA, LOCATORS_INSTALLED, REFCOUNT_FREE
    with _ACTIVATING:
        if _ACTIVE:
            return HAVE_NUMBA
        if HAVE_NUMBA:
            _load_blas_wrappers()
            try:
                import numba  # noqa: F401
            except ImportError:  # pragma: no cover - installed but broken
                HAVE_NUMBA = False
        if HAVE_NUMBA:
            numba_internals.install_locators(sources_stamp, PACKAGE)
            LOCATORS_INSTALLED = REFCOUNT_FREE = True
        for deferred in _DEFERRED:
            deferred.dispatcher = _make(deferred.py_func, deferred.vjm_options)
        spaces = {id(d.py_func.__globals__): d.py_func.__globals__ for d in _DEFERRED}
        spaces.update((id(vars(m)), vars(m)) for name, m in list(sys.modules.items())
                      if m is not None and (name == "vjm_ros" or name.startswith("vjm_ros.")))
        for names in spaces.values():
            _rebind(names)
        _DEFERRED.clear()
        _ACTIVE = True
        return HAVE_NUMBA


def _new(fn, options: dict):
    """A compiled function of ``fn``: its dispatcher once numba is active, else deferred."""
    with _ACTIVATING:
        if _ACTIVE:
            return _make(fn, options)
        if not HAVE_NUMBA:
            return fn
        deferred = Deferred(fn, options)
        _DEFERRED.append(deferred)
        return deferred


def jit(fn: Callable[..., object] | None = None, *, allocates: bool = True,
        inline: str = "never") -> Callable[..., object]:
    """Compile ``fn`` with numba (no Python objects, cached on disk), or return it unchanged.

    Before numba is imported (:func:`activate`) the result is a :class:`Deferred` that stands for
    the compiled function until then.

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
    return _new(fn, {"allocates": allocates, "inline": inline})


def variant(compiled_fn: Callable[..., object], name: str, *, inline: str | None = None,
            **constants: object) -> Callable[..., object]:
    """A second compiled copy of ``compiled_fn`` (made by :func:`jit`) that reads ``constants``
    in place of its module's globals of those names, under the name ``name``; ``inline``, when
    given, replaces its ``inline`` option (``"always"``: a copy that numba inlines into each
    compiled caller, see :func:`jit`).

    numba takes a module's globals as compile-time constants and drops the branches that a
    constant condition never takes before it types anything: code guarded by ``if FLAG:`` with
    ``FLAG = False`` is not compiled at all in the original, and is in a copy made with
    ``FLAG=True``. Each copy has its own entry in numba's cache (``name`` is its qualified
    name). Globals are read when the copy is made: make it at the end of the module.
    Without numba, the copy is the plain function with those globals.
    """
    fn = getattr(compiled_fn, "py_func", compiled_fn)
    missing = [k for k in constants if k not in fn.__globals__]
    if missing:
        raise KeyError(f"{fn.__qualname__}: no module global named {missing}")
    namespace = dict(fn.__globals__)
    namespace.update(constants)
    copy = types.FunctionType(fn.__code__, namespace, name, fn.__defaults__, fn.__closure__)
    copy.__qualname__ = name
    copy.__doc__ = fn.__doc__
    copy.__module__ = fn.__module__
    if not is_compiled(compiled_fn):
        return copy
    options = dict(compiled_fn.vjm_options)
    if inline is not None:
        options["inline"] = inline
    return _new(copy, options)
