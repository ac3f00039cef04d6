"""Adaptive, error-controlled methods from ``scipy.integrate`` for offline accuracy.

A control tick holds the efforts constant. The scipy solver is kept between ticks while the
efforts stay the same (the ODE is then unchanged, so its cached derivative and step size remain
valid) and the state at each tick boundary is read from its dense output. When the efforts change,
or the state was changed from outside (reset, projection), the solver restarts at the tick
boundary: a fresh effort is never mixed into a step already begun.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

import numpy as np

from vjm_ros.core.integrators.base import Integrator

if TYPE_CHECKING:
    from vjm_ros.core.integrators.base import System


class AdaptiveIntegrator(Integrator):
    """Wraps one ``scipy.integrate.OdeSolver`` class.

    Parameters
    ----------
    rtol, atol : float
        Relative and absolute tolerances of the local error estimate.
    """

    solver_name: str = "RK45"
    """Name of the ``scipy.integrate`` solver class (imported on first use: scipy.integrate
    takes 0.4 s to import, which a run on a fixed-step method need not pay)."""
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

    def advance(self, system: System, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray,
                dt: float, substeps: int = 1) -> tuple[np.ndarray, np.ndarray]:
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

            solver_class = getattr(importlib.import_module("scipy.integrate"), self.solver_name)
            self._solver = solver_class(
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


def _method(cls_name: str, name: str, order: int, solver: str,
            doc: str) -> type[AdaptiveIntegrator]:
    """An adaptive integrator: scipy's ``solver`` (class name) under a registry ``name``."""
    return type(cls_name, (AdaptiveIntegrator,), {
        "__doc__": doc, "__module__": __name__, "name": name, "order": order,
        "solver_name": solver,
    })


Dop853 = _method("Dop853", "dop853", 8, "DOP853",
                 "Explicit Runge-Kutta of order 8 (Dormand-Prince), for smooth non-stiff runs.")
Rk45 = _method("Rk45", "rk45", 5, "RK45", "Explicit Runge-Kutta 5(4) (Dormand-Prince).")
Rk23 = _method("Rk23", "rk23", 3, "RK23", "Explicit Runge-Kutta 3(2) (Bogacki-Shampine).")
RadauIIA = _method("RadauIIA", "radau", 5, "Radau",
                   "Implicit Runge-Kutta Radau IIA of order 5, for stiff penalty gains.")
Bdf = _method("Bdf", "bdf", 5, "BDF",
              "Variable-order backward differentiation formulas, for stiff penalty gains.")
Lsoda = _method("Lsoda", "lsoda", 12, "LSODA", "Adams/BDF switching (LSODA).")
