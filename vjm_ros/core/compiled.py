"""The kernel choice and the fixed-step integrators' compiled ticks.

The physics lives in one place, the compiled kernels behind :class:`~vjm_ros.core.mechanism.Mechanism`
(:mod:`vjm_ros.core.kernels`, :mod:`vjm_ros.core.pipeline`). This module keeps what chooses and
drives them:

* :func:`make_mechanism`: the mechanism for a ``kernel`` setting (``"auto"`` or ``"numba"``);
* :func:`fuse_integrator`: the registry's fixed-step integrators with an ``advance`` that runs a
  whole control tick in one compiled call (:meth:`~vjm_ros.core.mechanism.Mechanism.advance_fixed`).

Without numba the kernels run as plain Python (correct, but slow).
"""

from __future__ import annotations

from vjm_ros.core import kernels as K
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.integrators import Integrator
from vjm_ros.core.integrators.fixed import (
    RK4,
    ExplicitEuler,
    ImplicitPenaltyEuler,
    SemiImplicitEuler,
)
from vjm_ros.core.mechanism import Mechanism
from vjm_ros.core.model import Model

KERNELS = ("auto", "numba")
"""Accepted values of the ``kernel`` choice: the compiled kernels (machine code with numba, plain
Python without), or the same with numba required."""

HAVE_NUMBA = K.HAVE_NUMBA
"""True when numba is importable (the compiled kernels are then machine code)."""



# ---------------------------------------------------------------------------------- integrators
class _Fused:
    """Mixin: ``advance`` in one compiled call when the system is a :class:`Mechanism` (linear test
    systems of the stability analysis, which have only ``accelerations``, take the plain steps)."""

    kernel_method: int = -1

    def advance(self, system, t, q, qd, tau, dt, substeps=1):
        if isinstance(system, Mechanism):
            return system.advance_fixed(self.kernel_method, q, qd, tau, dt / substeps, substeps)
        return super().advance(system, t, q, qd, tau, dt, substeps)


class FusedExplicitEuler(_Fused, ExplicitEuler):
    """:class:`~vjm_ros.core.integrators.fixed.ExplicitEuler` with compiled ticks."""

    kernel_method = K.EXPLICIT_EULER


class FusedSemiImplicitEuler(_Fused, SemiImplicitEuler):
    """:class:`~vjm_ros.core.integrators.fixed.SemiImplicitEuler` with compiled ticks."""

    kernel_method = K.SEMI_IMPLICIT_EULER


class FusedRK4(_Fused, RK4):
    """:class:`~vjm_ros.core.integrators.fixed.RK4` with compiled ticks."""

    kernel_method = K.RK4


class FusedImplicitPenaltyEuler(_Fused, ImplicitPenaltyEuler):
    """:class:`~vjm_ros.core.integrators.fixed.ImplicitPenaltyEuler` with compiled ticks."""

    kernel_method = K.IMPLICIT_EULER


_FUSED: dict[type, type] = {
    ExplicitEuler: FusedExplicitEuler,
    SemiImplicitEuler: FusedSemiImplicitEuler,
    RK4: FusedRK4,
    ImplicitPenaltyEuler: FusedImplicitPenaltyEuler,
}


def fuse_integrator(integrator: Integrator, mechanism: Mechanism) -> Integrator:
    """The integrator with compiled ticks when both it and the mechanism allow it.

    Parameters
    ----------
    integrator : Integrator
        From :func:`vjm_ros.core.integrators.make_integrator`.
    mechanism : Mechanism
        The system it will advance.

    Returns
    -------
    Integrator
        A fused subclass instance (same ``name``, ``order``, ``step`` and stability bound) for the
        four fixed-step methods on a :class:`Mechanism`; ``integrator`` itself otherwise.
    """
    fused = _FUSED.get(type(integrator))
    if fused is None or not isinstance(mechanism, Mechanism):
        return integrator
    return fused()


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
