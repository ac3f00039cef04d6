"""Fixed-step methods for the live node, run by the compiled kernel.

Each class names its method in :func:`vjm_ros.core.kernels.step` (``kernel_method``) and gives the
method's one-step map on the linear system ``x'' = -K x - D x'`` in closed form
(``step_matrix``), from which the stiffness check takes its bounds:

* ``explicit_euler``: ``q+ = q + h v``, ``v+ = v + h a(q, v)`` (baseline, order 1); on a linear
  system ``I + h J``;
* ``semi_implicit_euler``: ``v+ = v + h a(q, v)``, ``q+ = q + h v+`` (symplectic, order 1);
* ``rk4``: the classical Runge-Kutta method (order 4); on a linear system ``R(h J)`` with
  ``R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24``;
* ``implicit_euler``: semi-implicit Euler whose penalty forces are taken at the end of the step
  (linearized), which keeps stiff closures stable at any step (order 1).

``J = [[0, I], [-K, -D]]``. Stability bounds on ``omega_n h`` for the test oscillator
``x'' + 2 zeta w x' + w^2 x = 0``: explicit Euler needs ``omega h < 2 zeta`` (it amplifies every
undamped oscillation), semi-implicit Euler ``omega h < 2`` undamped, RK4 ``2 sqrt(2)`` undamped;
implicit Euler in the penalty forces is unconditionally stable.
"""

from __future__ import annotations

import numpy as np

from vjm_ros.core import kernels as K
from vjm_ros.core.integrators.base import FixedStepIntegrator, blocks, first_order


def _polynomial_of(coefficients: tuple[float, ...], z: np.ndarray) -> np.ndarray:
    """``sum_k c_k z^k`` of a stack of square matrices ``z`` (Horner's scheme)."""
    eye = np.broadcast_to(np.eye(z.shape[-1]), z.shape)
    out = coefficients[-1] * eye
    for c in coefficients[-2::-1]:
        out = c * eye + z @ out
    return out


class ExplicitEuler(FixedStepIntegrator):
    """Forward Euler on ``(q, qd)``."""

    name = "explicit_euler"
    order = 1
    kernel_method = K.EXPLICIT_EULER

    def step_matrix(self, stiffness: np.ndarray, damping: np.ndarray, h: float) -> np.ndarray:
        return _polynomial_of((1.0, 1.0), h * first_order(stiffness, damping))


class SemiImplicitEuler(FixedStepIntegrator):
    """Symplectic (semi-implicit) Euler: velocity first, then position with the new velocity."""

    name = "semi_implicit_euler"
    order = 1
    kernel_method = K.SEMI_IMPLICIT_EULER

    def step_matrix(self, stiffness: np.ndarray, damping: np.ndarray, h: float) -> np.ndarray:
        # v+ = -h K x + (I - h D) v, x+ = x + h v+
        k, d = np.asarray(stiffness, dtype=float), np.asarray(damping, dtype=float)
        eye = np.broadcast_to(np.eye(k.shape[-1]), k.shape)
        keep = eye - h * d
        return blocks(eye - h * h * k, h * keep, -h * k, keep)


class RK4(FixedStepIntegrator):
    """The classical fourth-order Runge-Kutta method."""

    name = "rk4"
    order = 4
    kernel_method = K.RK4

    def step_matrix(self, stiffness: np.ndarray, damping: np.ndarray, h: float) -> np.ndarray:
        taylor = (1.0, 1.0, 1.0 / 2.0, 1.0 / 6.0, 1.0 / 24.0)
        return _polynomial_of(taylor, h * first_order(stiffness, damping))


class ImplicitPenaltyEuler(FixedStepIntegrator):
    """Semi-implicit Euler with the penalty closure forces linearized at the end of the step.

    See :meth:`vjm_ros.core.mechanism.Mechanism.implicit_penalty_velocity`. The stiff closure modes are
    damped numerically (the method is L-stable in them); the slow motion of the mechanism is
    integrated as by semi-implicit Euler.
    """

    name = "implicit_euler"
    order = 1
    kernel_method = K.IMPLICIT_EULER

    def stability_bounds(self, zeta: np.ndarray) -> np.ndarray:
        return np.full(np.size(zeta), np.inf)

    def step_matrix(self, stiffness: np.ndarray, damping: np.ndarray, h: float) -> np.ndarray:
        # every force of x'' = -K x - D x' is a penalty force, taken at the end of the step:
        # (I + h D + h^2 K) v+ = v - h K x, x+ = x + h v+
        k, d = np.asarray(stiffness, dtype=float), np.asarray(damping, dtype=float)
        eye = np.broadcast_to(np.eye(k.shape[-1]), k.shape)
        solve = np.linalg.inv(eye + h * d + h * h * k)
        return blocks(eye - h * h * (solve @ k), h * solve, -h * (solve @ k), solve)
