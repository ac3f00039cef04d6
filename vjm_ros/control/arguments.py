"""Checks of the numbers a controller passes to the closed-chain model.

Each refuses what it cannot use with an error that names the argument, what was expected and
what was found: :class:`~vjm_ros.control.errors.ArgumentTypeError` (a ``TypeError``) for
something that is not a number (text, booleans, objects), a
:class:`~vjm_ros.core.errors.ConfigurationError` (a ``ValueError``) for the wrong count or a
non-finite value.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from vjm_ros.control.errors import ArgumentTypeError
from vjm_ros.core.errors import ConfigurationError

NUMERIC_KINDS = "iuf"
"""numpy dtype kinds accepted as numbers: signed and unsigned integers and floats (not booleans,
text, complex or objects)."""


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 120 else text[:117] + "..."


def _is_number(value: object) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def number_array(values: object, name: str, expected: str) -> np.ndarray:
    """``values`` as a flat float array, or an :class:`ArgumentTypeError` naming ``name``.

    Parameters
    ----------
    values : array_like
        Numbers (a sequence, an array or one number).
    name : str
        The argument's name, for the message.
    expected : str
        What it should hold, for the message (e.g. ``"2 numbers (rad/s^2 or m/s^2)"``).

    Returns
    -------
    ndarray, shape (k,)
    """
    try:
        arr = np.asarray(values)
    except (TypeError, ValueError):  # ragged nesting
        raise ArgumentTypeError(f"{name}: expected {expected}, found {_shown(values)}") from None
    if arr.dtype.kind == "O" and all(_is_number(v) for v in arr.reshape(-1)):
        arr = arr.astype(float)  # a sequence mixing Python and numpy numbers
    if arr.dtype.kind not in NUMERIC_KINDS:
        raise ArgumentTypeError(f"{name}: expected {expected}, found {_shown(values)}")
    return np.asarray(arr, dtype=float).reshape(-1)


def vector(values: object, size: int, name: str, unit: str = "") -> np.ndarray:
    """``size`` finite numbers as a float array, shape (size,).

    Raises
    ------
    ArgumentTypeError
        Not numbers.
    ConfigurationError
        Another count, or NaN or infinite values.
    """
    what = f"{size} values" + (f" ({unit})" if unit else "")
    out = number_array(values, name, what)
    if out.shape != (size,):
        raise ConfigurationError(f"{name}: expected {what}, found {out.size}")
    if not np.all(np.isfinite(out)):
        raise ConfigurationError(f"{name}: expected finite values, found {out.tolist()}")
    return out


def real(value: object, name: str, unit: str = "") -> float:
    """One finite real number (a Python or numpy number, or a 0-d array).

    Raises
    ------
    ArgumentTypeError
        Not a number (text, a boolean, a sequence, ...).
    ConfigurationError
        NaN or infinite.
    """
    if type(value) is float or type(value) is int:  # the common case, without the checks below
        if math.isfinite(value):
            return float(value)
    what = "a finite number" + (f" ({unit})" if unit else "")
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in NUMERIC_KINDS:
        value = value.item()
    if not _is_number(value):
        raise ArgumentTypeError(
            f"{name}: expected {what}, found {_shown(value)} ({type(value).__name__})")
    out = float(value)
    if not math.isfinite(out):
        raise ConfigurationError(f"{name}: expected {what}, found {out}")
    return out
