"""Adaptive, error-controlled methods from ``scipy.integrate`` for offline accuracy.

A control tick holds the efforts constant. The scipy solver is kept between ticks while the
efforts stay the same (the ODE is then unchanged, so its cached derivative and step size remain
valid) and the state at each tick boundary is read from its dense output. When the efforts change,
or the state was changed from outside (reset, projection), the solver restarts at the tick
boundary: a fresh effort is never mixed into a step already begun.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import BDF as _BDF
from scipy.integrate import DOP853, LSODA, RK23, RK45, Radau

from vjm_ros.core.integrators.base import Integrator


class AdaptiveIntegrator(Integrator):
    """Wraps one ``scipy.integrate.OdeSolver`` class.

    Parameters
    ----------
    rtol, atol : float
        Relative and absolute tolerances of the local error estimate.
    """

    solver_class: type = RK45
    fixed_step = False

    def __init__(self, rtol: float = 1e-9, atol: float = 1e-12):
        self.rtol = rtol
        self.atol = atol
        self._solver = None
        self._tau = None
        self._y_end = None
        self.nfev = 0

    def reset(self) -> None:
        self._solver = None
        self._tau = None
        self._y_end = None

    def advance(self, system, t, q, qd, tau, dt, substeps=1):
        n = len(q)
        y = np.concatenate((q, qd))
        t_end = t + dt
        reuse = (
            self._solver is not None
            and self._tau is not None
            and np.array_equal(self._tau, tau)
            and self._y_end is not None
            and np.array_equal(self._y_end, y)
        )
        if not reuse:
            tau_fixed = np.array(tau, dtype=float)

            def rhs(_t, yy):
                return np.concatenate((yy[n:], system.accelerations(yy[:n], yy[n:], tau_fixed)))

            self._solver = self.solver_class(
                rhs, t, y, t_bound=np.inf, rtol=self.rtol, atol=self.atol
            )
            self._tau = tau_fixed
        solver = self._solver
        while solver.t < t_end:
            message = solver.step()
            if solver.status == "failed":
                self._solver = None
                raise FloatingPointError(f"{self.name} failed at t = {solver.t:.6g} s: {message}")
        self.nfev = solver.nfev
        y_end = solver.dense_output()(t_end) if solver.t != t_end else solver.y.copy()
        self._y_end = y_end
        return y_end[:n].copy(), y_end[n:].copy()


class Dop853(AdaptiveIntegrator):
    """Explicit Runge-Kutta of order 8 (Dormand-Prince), for smooth non-stiff runs."""

    name = "dop853"
    order = 8
    solver_class = DOP853


class Rk45(AdaptiveIntegrator):
    """Explicit Runge-Kutta 5(4) (Dormand-Prince)."""

    name = "rk45"
    order = 5
    solver_class = RK45


class Rk23(AdaptiveIntegrator):
    """Explicit Runge-Kutta 3(2) (Bogacki-Shampine)."""

    name = "rk23"
    order = 3
    solver_class = RK23


class RadauIIA(AdaptiveIntegrator):
    """Implicit Runge-Kutta Radau IIA of order 5, for stiff penalty gains."""

    name = "radau"
    order = 5
    solver_class = Radau


class Bdf(AdaptiveIntegrator):
    """Variable-order backward differentiation formulas, for stiff penalty gains."""

    name = "bdf"
    order = 5
    solver_class = _BDF


class Lsoda(AdaptiveIntegrator):
    """Adams/BDF switching (LSODA)."""

    name = "lsoda"
    order = 12
    solver_class = LSODA
