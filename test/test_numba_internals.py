"""numba's private internals, used in one module only (:mod:`vjm_ros.jit.numba_internals`) and
pinned to the numba of ``requirements/lock.txt``.

The module keys numba's cache on all of the compiled sources, compiles without reference
counting, loads cached functions without numba's registry refresh and asks dispatchers about
their cache, through names numba does not publish, with no fallback for another numba's
layout: a numba upgrade that moved one would break a run, or silently slow it down or (the
cache keys) let a kernel run stale code. These tests make the upgrade fail here instead:
the installed numba is the locked one, every private name the module lists exists in it, the
workarounds are in place after numba's import, and no other module of the package touches
numba's internals.

Oracles: the lock file's pins, numba's own modules (the names resolved by import and
``getattr``), and the package's sources.
"""

from __future__ import annotations

import functools
import importlib
import re
from pathlib import Path

import pytest

numba = pytest.importorskip("numba")
llvmlite = pytest.importorskip("llvmlite")

from vjm_ros.jit import deferred, numba_internals, sources  # noqa: E402

LOCK = Path(__file__).resolve().parents[1] / "requirements" / "lock.txt"

INTERNALS = re.compile(r"numba\.core|numba\._|\._cache\b|_locator_classes|targetctx|add_overload"
                       r"|typeof_pyval|insert_user_function|\.overloads\b|[\"']_nrt[\"']|rtsys")
"""What a use of numba's internals looks like in a source file (imports from ``numba.core``,
dispatcher and cache internals, the ``_nrt`` option)."""


def locked_version(package: str) -> str:
    """The version ``requirements/lock.txt`` pins ``package`` to."""
    found = re.search(rf"^{re.escape(package)}==(\S+)", LOCK.read_text(), re.MULTILINE)
    assert found, f"{LOCK}: no pin of {package}"
    return found.group(1)


@pytest.mark.parametrize("module", [numba, llvmlite], ids=["numba", "llvmlite"])
def test_the_installed_numba_is_the_locked_one(module):
    locked = locked_version(module.__name__)
    assert module.__version__ == locked, (
        f"{module.__name__} {module.__version__} is installed, requirements/lock.txt pins {locked}: "
        "vjm_ros/jit/numba_internals.py uses numba's private internals; check each of them "
        "against the new version (this file) before changing the pin")


def _resolve(dotted: str):
    """The object a dotted name stands for: the longest importable module, then attributes."""
    parts = dotted.split(".")
    for end in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:end]))
        except ImportError:
            continue
        for attribute in parts[end:]:
            obj = getattr(obj, attribute)  # AttributeError names what is missing
        return obj
    raise ImportError(dotted)


@pytest.mark.parametrize("name", numba_internals.PRIVATE_NAMES)
def test_every_private_name_the_module_uses_exists(name):
    assert _resolve(name) is not None


def test_a_dispatcher_has_the_attributes_the_module_reads():
    dispatcher = numba.njit(cache=True)(numba_internals._probe)
    missing = [a for a in numba_internals.DISPATCHER_ATTRIBUTES if not hasattr(dispatcher, a)]
    assert missing == []
    assert isinstance(dispatcher._cache._cache_path, str)
    assert numba_internals.cache_directory() == Path(dispatcher._cache._cache_path)
    assert numba_internals.is_dispatcher(dispatcher)
    assert not numba_internals.is_dispatcher(numba_internals._probe)


def test_the_workarounds_are_in_place_once_numba_is_imported():
    """With the locked numba every fallback stays unused: the cache keyed on the sources, the
    functions without reference counting, the lazy loading of cached functions."""
    assert deferred.activate()
    assert deferred.LOCATORS_INSTALLED and deferred.REFCOUNT_FREE
    from numba.core import caching

    assert [c.__name__ for c in caching.CacheImpl._locator_classes[:3]] == [
        "VjmSourcesUserProvidedCacheLocator", "VjmSourcesInTreeCacheLocator",
        "VjmSourcesUserWideCacheLocator"]

    @deferred.jit(allocates=False)
    def add(a, b):
        return a + b

    dispatcher = deferred.compiled(add)
    assert dispatcher.targetoptions.get("_nrt") is False
    assert isinstance(dispatcher._cache.load_overload, functools.partial)


def test_no_other_module_uses_numba_internals():
    uses = [f"{path.relative_to(sources.PACKAGE.parent)}:{number}: {line.strip()}"
            for path in sorted(sources.PACKAGE.rglob("*.py"))
            if path != Path(numba_internals.__file__).resolve()
            for number, line in enumerate(path.read_text().splitlines(), 1)
            if INTERNALS.search(line)]
    assert uses == []
