"""Reading a scene document's values: each check raises an error that names the file and key.

:class:`KeyReader` holds the primitives (mappings, lists, numbers, angles, names, choices) that
:class:`~vjm_ros.scene.builder.SceneBuilder` validates a document with; every error is a
:class:`~vjm_ros.core.errors.SceneError` naming the file, the key path (``chains[0].links[1].mass``),
what was expected and what was found.
"""

from __future__ import annotations

import math
import re
import reprlib
from collections.abc import Collection

from vjm_ros.core.errors import SceneError
from vjm_ros.scene.limits import MAX_LINKS, MAX_MAGNITUDE, MAX_STRING, TOP_KEY

_SHORT = reprlib.Repr()
_SHORT.maxlevel = 3
_SHORT.maxlist = _SHORT.maxdict = _SHORT.maxset = _SHORT.maxtuple = 4
_SHORT.maxstring = _SHORT.maxother = 60


def _shown(value: object) -> object:
    """``value`` itself, or a stand-in with a bounded ``repr`` for collections.

    YAML aliases can make a small file hold a collection whose full ``repr`` is astronomically long
    (or self-referencing); error messages print this stand-in instead.
    """
    if isinstance(value, (list, dict, set, tuple)):
        return _Excerpt(_SHORT.repr(value))
    return value


class _Excerpt:
    """Prints as the excerpt it was made with (see :func:`_shown`)."""

    def __init__(self, text: str):
        self.text = text

    def __repr__(self) -> str:
        return self.text


def _key(parent: str, child: str) -> str:
    """Key path of ``child`` under ``parent``: ``a.b``, or ``a['b c']`` for an unusual key."""
    if re.fullmatch(r"[A-Za-z_]\w*", child, re.ASCII):
        return f"{parent}.{child}" if parent else child
    return f"{parent}[{child!r}]"


class KeyReader:
    """Values of a document, checked, with errors naming ``source`` and the key path.

    Parameters
    ----------
    source : str
        File name for error messages.

    Attributes
    ----------
    angle_scale : float
        Radians per unit of the document's angles (``units.angle``).
    """

    def __init__(self, source: str):
        self.source = source
        self.angle_scale = 1.0

    def fail(self, key: str, expected: str, found: object = ...) -> SceneError:
        """The error to raise for ``key``."""
        return SceneError(self.source, key, expected, _shown(found))

    def require(self, value: dict, name: str, key: str, expected: str = "a required key") -> object:
        """``value[name]``, or an error naming the missing key."""
        if name not in value:
            raise self.fail(_key(key, name), expected, "missing")
        return value[name]

    def mapping(self, value: object, key: str, allowed: set[str] | None = None) -> dict:
        """``value`` if it is a mapping with string keys out of ``allowed``."""
        if not isinstance(value, dict):
            raise self.fail(key or TOP_KEY, "a mapping", value)
        for k in value:
            if not isinstance(k, str):
                raise self.fail(key or TOP_KEY, "string keys", k)
            if allowed is not None and k not in allowed:
                raise self.fail(_key(key, k), f"one of the keys {sorted(allowed)}", k)
        return value

    def section(self, doc: dict, name: str) -> object:
        """An optional top-level list or mapping; empty (``null``) counts as absent."""
        value = doc.get(name)
        if value is None:
            return {} if name in ("closure_method", "defaults", "units") else []
        return value

    def sequence(self, value: object, key: str, min_len: int = 0, max_len: int = MAX_LINKS) -> list:
        """``value`` if it is a list of ``min_len`` to ``max_len`` entries."""
        if not isinstance(value, list):
            raise self.fail(key, "a list", value)
        if len(value) < min_len:
            raise self.fail(key, f"a list of at least {min_len} entries", value)
        if len(value) > max_len:
            raise self.fail(key, f"a list of at most {max_len} entries", f"{len(value)} entries")
        return value

    def number(
        self, value: object, key: str, minimum: float | None = None, positive: bool = False
    ) -> float:
        """``value`` as a finite float within :data:`MAX_MAGNITUDE` and the given bounds."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(key, "a number", value)
        if isinstance(value, int) and abs(value) > MAX_MAGNITUDE:  # float() could overflow
            raise self.fail(key, f"a finite number of magnitude at most {MAX_MAGNITUDE:g}", value)
        v = float(value)
        if not math.isfinite(v) or abs(v) > MAX_MAGNITUDE:
            raise self.fail(key, f"a finite number of magnitude at most {MAX_MAGNITUDE:g}", value)
        if positive and v <= 0:
            raise self.fail(key, "a number > 0", value)
        if minimum is not None and v < minimum:
            raise self.fail(key, f"a number >= {minimum:g}", value)
        return v

    def angle(self, value: object, key: str) -> float:
        """An angle in the scene's unit, in radians."""
        return self.number(value, key) * self.angle_scale

    def vector(self, value: object, key: str) -> tuple[float, float]:
        """A planar vector ``[x, y]``."""
        if not isinstance(value, list) or len(value) != 2:
            raise self.fail(key, "a list of two numbers [x, y]", value)
        return (self.number(value[0], f"{key}[0]"), self.number(value[1], f"{key}[1]"))

    def string(self, value: object, key: str) -> str:
        """A non-empty string of at most :data:`MAX_STRING` characters."""
        if not isinstance(value, str) or not value.strip():
            raise self.fail(key, "a non-empty string", value)
        if len(value) > MAX_STRING:
            raise self.fail(key, f"a string of at most {MAX_STRING} characters", value)
        return value

    def name(self, value: object, key: str) -> str:
        """An identifier: letters, digits and ``_``, not starting with a digit."""
        s = self.string(value, key)
        if not all(ch.isalnum() or ch == "_" for ch in s) or s[0].isdigit():
            raise self.fail(key, "a name of letters, digits and '_' (not starting with a digit)", s)
        return s

    def choice(self, value: object, key: str, options: Collection[str]) -> str:
        """One of the strings ``options``."""
        if not isinstance(value, str) or value not in options:
            raise self.fail(key, f"one of {list(options)}", value)
        return value
