"""Integrator contract.

An integrator advances a :class:`~vjm_ros.system.Mechanism` over one control tick of length
``dt`` with the efforts ``tau`` held constant (DESIGN section 3):

1. ``advance(system, t, q, qd, tau, dt, substeps)`` returns ``(q, qd)`` at ``t + dt``;
2. fixed-step methods take ``substeps`` equal steps ``h = dt / substeps``;
3. adaptive methods ignore ``substeps`` and control their own step; their state never carries
   a derivative computed with another tick's efforts;
4. ``stability_bound(zeta)`` is the largest ``omega_n h`` for which the method keeps a linear
   oscillator of damping ratio ``zeta`` from growing (``inf`` when unconditionally stable),
   used to refuse penalty gains the step cannot carry.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np


class Integrator(ABC):
    """Base class of all time-stepping methods.

    Attributes
    ----------
    name : str
        Registry key.
    order : int
        Global order of accuracy of the method on smooth problems.
    fixed_step : bool
        True for methods with a fixed step ``h = dt / substeps``.
    """

    name: str = ""
    order: int = 0
    fixed_step: bool = True

    @abstractmethod
    def advance(
        self,
        system,
        t: float,
        q: np.ndarray,
        qd: np.ndarray,
        tau: np.ndarray,
        dt: float,
        substeps: int = 1,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Advance one control tick; see the module docstring."""

    def stability_bound(self, zeta: float) -> float:
        """Largest stable ``omega_n h`` for a linear oscillator with damping ratio ``zeta``."""
        return np.inf

    def reset(self) -> None:  # noqa: B027 (optional hook: most methods keep no state)
        """Forget any state kept between ticks (after a jump of the state)."""


class FixedStepIntegrator(Integrator):
    """A method defined by one step ``step(system, q, qd, tau, h)``."""

    @abstractmethod
    def step(self, system, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, h: float):
        """One step of length ``h``; returns ``(q, qd)``."""

    def advance(self, system, t, q, qd, tau, dt, substeps=1):
        h = dt / substeps
        for _ in range(substeps):
            q, qd = self.step(system, q, qd, tau, h)
        return q, qd

    def amplification(self, x: float, zeta: float) -> float:
        """Spectral radius of one step on ``x'' + 2 zeta x' + x = 0`` with step ``h = x``."""
        osc = _Oscillator(zeta)
        cols = []
        for y0 in (np.array([1.0]), np.array([0.0])):
            q, qd = self.step(osc, y0, 1.0 - y0, np.zeros(1), x)
            cols.append([q[0], qd[0]])
        return float(np.max(np.abs(np.linalg.eigvals(np.array(cols).T))))

    def stability_bound(self, zeta: float) -> float:
        """Largest ``omega_n h`` with spectral radius <= 1, by scan and bisection (max 10)."""
        tol = 1e-12
        last_ok = 0.0
        for x in np.linspace(1e-3, 10.0, 1000):
            if self.amplification(x, zeta) > 1.0 + tol:
                lo, hi = last_ok, x
                for _ in range(60):
                    mid = 0.5 * (lo + hi)
                    if self.amplification(mid, zeta) > 1.0 + tol:
                        hi = mid
                    else:
                        lo = mid
                return lo
            last_ok = x
        return np.inf


class _Oscillator:
    """The scalar test problem ``x'' = -x - 2 zeta x'`` seen through the system interface."""

    def __init__(self, zeta: float):
        self.zeta = zeta

    def accelerations(self, q, qd, tau):
        return -q - 2.0 * self.zeta * qd
