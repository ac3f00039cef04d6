"""The kernel choice.

The physics lives in one place, the compiled kernels behind :class:`~vjm_ros.core.mechanism.Mechanism`
(:mod:`vjm_ros.core.kernels`, :mod:`vjm_ros.core.pipeline`); the fixed-step integrators run whole
control ticks there (:meth:`~vjm_ros.core.mechanism.Mechanism.advance_fixed`). This module keeps
:func:`make_mechanism`, the mechanism for a ``kernel`` setting (``"auto"`` or ``"numba"``).

Without numba the kernels run as plain Python (correct, but slow).
"""

from __future__ import annotations

from vjm_ros.core import kernels as K
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.mechanism import Mechanism
from vjm_ros.core.model import Model

KERNELS = ("auto", "numba")
"""Accepted values of the ``kernel`` choice: the compiled kernels (machine code with numba, plain
Python without), or the same with numba required."""

HAVE_NUMBA = K.HAVE_NUMBA
"""True when numba is importable (the compiled kernels are then machine code)."""


def make_mechanism(
    model: Model, method: PenaltyClosure | ExactClosure, kernel: str = "auto"
) -> Mechanism:
    """The mechanism for a kernel choice.

    Parameters
    ----------
    model : Model
    method : PenaltyClosure or ExactClosure
    kernel : str
        ``"auto"`` (the compiled kernels; plain Python where numba is missing) or ``"numba"``
        (an error without numba).

    Returns
    -------
    Mechanism

    Raises
    ------
    ValueError
        For an unknown ``kernel``, or ``"numba"`` without numba installed (the settings refuse
        the former ``"numpy"`` with an explanation: :mod:`vjm_ros.sim.settings`).
    """
    if kernel not in KERNELS:
        raise ValueError(f"kernel: expected one of {', '.join(KERNELS)}, found {kernel!r}")
    if kernel == "numba" and not HAVE_NUMBA:
        raise ValueError("kernel: 'numba' needs the numba package (pip install 'numba>=0.64')")
    return Mechanism(model, method)
