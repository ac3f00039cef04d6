"""Time integration: one registry of fixed-step and adaptive methods.

>>> make_integrator("rk4").order
4
"""

from __future__ import annotations

from vjm_ros.core.errors import ConfigurationError
from vjm_ros.core.integrators.adaptive import (
    AdaptiveIntegrator,
    Bdf,
    Dop853,
    Lsoda,
    RadauIIA,
    Rk23,
    Rk45,
)
from vjm_ros.core.integrators.base import FixedStepIntegrator, Integrator
from vjm_ros.core.integrators.fixed import (
    RK4,
    ExplicitEuler,
    ImplicitPenaltyEuler,
    SemiImplicitEuler,
)

INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls
    for cls in (
        ExplicitEuler,
        SemiImplicitEuler,
        RK4,
        ImplicitPenaltyEuler,
        Dop853,
        Rk45,
        Rk23,
        RadauIIA,
        Bdf,
        Lsoda,
    )
}
"""Every integrator by name."""

FIXED_STEP = tuple(k for k, v in INTEGRATORS.items() if issubclass(v, FixedStepIntegrator))
ADAPTIVE = tuple(k for k, v in INTEGRATORS.items() if issubclass(v, AdaptiveIntegrator))


def make_integrator(name: str, **options) -> Integrator:
    """Instantiate an integrator by registry name.

    Parameters
    ----------
    name : str
        One of :data:`INTEGRATORS`.
    **options
        ``rtol``/``atol`` for adaptive methods.

    Raises
    ------
    ConfigurationError
        (a ``ValueError``) for an unknown name; the message lists the known ones.
    """
    try:
        cls = INTEGRATORS[name]
    except KeyError:
        raise ConfigurationError(
            f"integrator: unknown name {name!r}; known: {', '.join(INTEGRATORS)}"
        ) from None
    if issubclass(cls, AdaptiveIntegrator):
        return cls(**options)
    return cls()


__all__ = [
    "ADAPTIVE",
    "FIXED_STEP",
    "INTEGRATORS",
    "AdaptiveIntegrator",
    "FixedStepIntegrator",
    "Integrator",
    "make_integrator",
]
