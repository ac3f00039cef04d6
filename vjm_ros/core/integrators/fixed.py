"""Fixed-step methods for the live node.

Each class's ``step`` defines its method on any system with ``accelerations``: the stability
analysis (:mod:`vjm_ros.core.integrators.base`) applies it to linear test systems. A
:class:`~vjm_ros.core.mechanism.Mechanism` is advanced by the same method inside the compiled
kernel (:func:`vjm_ros.core.compiled.fuse_integrator`, :func:`vjm_ros.core.kernels.step`), which
the test suite checks against these steps on the numpy oracle.

* ``explicit_euler``: ``q+ = q + h v``, ``v+ = v + h a(q, v)`` (baseline, order 1);
* ``semi_implicit_euler``: ``v+ = v + h a(q, v)``, ``q+ = q + h v+`` (symplectic, order 1);
* ``rk4``: the classical Runge-Kutta method, written as its Butcher table (order 4);
* ``implicit_euler``: semi-implicit Euler whose penalty forces are taken at the end of the step
  (linearized), which keeps stiff closures stable at any step (order 1).

Stability bounds (``omega_n h`` for the test oscillator ``x'' + 2 zeta w x' + w^2 x = 0``) are
computed from each method's own step (:meth:`FixedStepIntegrator.stability_bound`): explicit Euler
needs ``omega h < 2 zeta`` (it amplifies every undamped oscillation), semi-implicit Euler
``omega h < 2`` undamped, RK4 ``2 sqrt(2)`` undamped; implicit Euler in the penalty forces is
unconditionally stable.
"""

from __future__ import annotations

import numpy as np

from vjm_ros.core.integrators.base import FixedStepIntegrator


class ExplicitEuler(FixedStepIntegrator):
    """Forward Euler on ``(q, qd)``."""

    name = "explicit_euler"
    order = 1

    def step(self, system, q, qd, tau, h):
        qdd = system.accelerations(q, qd, tau)
        return q + h * qd, qd + h * qdd


class SemiImplicitEuler(FixedStepIntegrator):
    """Symplectic (semi-implicit) Euler: velocity first, then position with the new velocity."""

    name = "semi_implicit_euler"
    order = 1

    def step(self, system, q, qd, tau, h):
        qd = qd + h * system.accelerations(q, qd, tau)
        return q + h * qd, qd


class ExplicitRungeKutta(FixedStepIntegrator):
    """An explicit Runge-Kutta method given by its Butcher table on ``y = (q, qd)``.

    Subclasses set ``A`` (strictly lower triangular), ``B`` and ``C``.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray

    def step(self, system, q, qd, tau, h):
        s = len(self.B)
        kq = np.zeros((s, len(q)))
        kv = np.zeros((s, len(q)))
        for i in range(s):
            qi = q + h * (self.A[i, :i] @ kq[:i]) if i else q
            vi = qd + h * (self.A[i, :i] @ kv[:i]) if i else qd
            kq[i] = vi
            kv[i] = system.accelerations(qi, vi, tau)
        return q + h * (self.B @ kq), qd + h * (self.B @ kv)


class RK4(ExplicitRungeKutta):
    """The classical fourth-order Runge-Kutta method."""

    name = "rk4"
    order = 4
    A = np.array([[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1.0, 0]])
    B = np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6])
    C = np.array([0, 0.5, 0.5, 1.0])


class ImplicitPenaltyEuler(FixedStepIntegrator):
    """Semi-implicit Euler with the penalty closure forces linearized at the end of the step.

    See :meth:`vjm_ros.core.mechanism.Mechanism.implicit_penalty_velocity`. The stiff closure modes are
    damped numerically (the method is L-stable in them); the slow motion of the mechanism is
    integrated as by semi-implicit Euler.
    """

    name = "implicit_euler"
    order = 1

    def stability_bound(self, zeta: float) -> float:
        return np.inf

    def step(self, system, q, qd, tau, h):
        qd = system.implicit_penalty_velocity(q, qd, tau, h)
        return q + h * qd, qd
