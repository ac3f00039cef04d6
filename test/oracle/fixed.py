"""Oracle: the fixed-step methods of docs/design.md section 3, on any system with ``accelerations``.

The package runs these methods only inside the compiled kernel (:func:`vjm_ros.core.kernels.step`);
these step the numpy :class:`oracle.mechanism.Mechanism` or the compiled one, so that the two can
be compared. Each step holds the efforts ``tau`` and advances ``(q, qd)`` by ``h``:

* ``explicit_euler``: ``q+ = q + h qd``, ``qd+ = qd + h a(q, qd)``;
* ``semi_implicit_euler``: ``qd+ = qd + h a(q, qd)``, then ``q+ = q + h qd+``;
* ``rk4``: the classical Runge-Kutta method as a Butcher tableau ``(A, b, c)``, applied by a
  generic explicit Runge-Kutta step to the first-order system ``y = (q, qd)``,
  ``y' = f(y) = (qd, a(q, qd))``: ``k_i = f(y + h sum_j A_ij k_j)``, ``y+ = y + h sum_i b_i k_i``;
* ``implicit_euler``: backward Euler in the penalty forces, explicit in everything else. With
  ``M``, ``Q = tau - b``, ``A`` and ``C`` taken at the start of the step and the penalty force at
  its end linearized, ``F+ = -(Kp (C + h A v+) + Kv A v+)``, the velocity ``v+`` solves
  ``R(v+) = M (v+ - qd) - h (Q + A^T F+) = 0``; ``R`` is affine in ``v+``, so one Newton step
  from ``qd`` with ``dR/dv+ = M + h A^T (h Kp + Kv) A`` solves it exactly. Then
  ``q+ = q + h v+``. With exact closures it is semi-implicit Euler.

Stability bounds stay with the package's integrators (:mod:`vjm_ros.core.integrators`).
"""

from __future__ import annotations

import numpy as np

from vjm_ros.core.constraints import PenaltyClosure


class OracleStep:
    """A method given by one step; :meth:`advance` repeats it over a control tick."""

    name = ""

    def step(self, system, q, qd, tau, h):
        """``(q+, qd+)`` after one step of length ``h`` (s) with the efforts ``tau`` held."""
        raise NotImplementedError

    def advance(self, system, t, q, qd, tau, dt, substeps=1):
        """``substeps`` steps of ``h = dt / substeps`` with ``tau`` held; returns ``(q, qd)``
        (``t`` unused: the systems here do not depend on time)."""
        h = dt / substeps
        for _ in range(substeps):
            q, qd = self.step(system, q, qd, tau, h)
        return q, qd


class ExplicitEuler(OracleStep):
    """Forward Euler: position and velocity both from the start of the step."""

    name = "explicit_euler"

    def step(self, system, q, qd, tau, h):
        return q + h * qd, qd + h * system.accelerations(q, qd, tau)


class SemiImplicitEuler(OracleStep):
    """Symplectic Euler: the new velocity first, the position with it."""

    name = "semi_implicit_euler"

    def step(self, system, q, qd, tau, h):
        velocity = qd + h * system.accelerations(q, qd, tau)
        return q + h * velocity, velocity


class ButcherTableau:
    """An explicit Runge-Kutta method ``(A, b, c)``.

    Parameters
    ----------
    a : array_like, shape (s, s)
        Strictly lower triangular.
    b, c : array_like, shape (s,)

    Raises
    ------
    ValueError
        When ``A`` is not strictly lower triangular or a row sum of ``A`` differs from its node
        ``c_i`` (the stages would not be consistent in time).
    """

    def __init__(self, a, b, c):
        self.a = np.asarray(a, dtype=float)
        self.b = np.asarray(b, dtype=float)
        self.c = np.asarray(c, dtype=float)
        if np.any(np.triu(self.a)):
            raise ValueError("an explicit tableau has A strictly lower triangular")
        if not np.allclose(self.a.sum(axis=1), self.c, rtol=0, atol=1e-15):
            raise ValueError(f"row sums of A {self.a.sum(axis=1)} differ from c {self.c}")

    @property
    def stages(self) -> int:
        """Number of stages ``s``."""
        return len(self.b)

    def order_conditions(self) -> dict[str, float]:
        """The left sides of the conditions up to order 4 (the right sides: 1, 1/2, 1/3, 1/6,
        1/4, 1/8, 1/12, 1/24)."""
        a, b, c = self.a, self.b, self.c
        return {
            "b": b.sum(), "bc": b @ c, "bc2": b @ c**2, "bAc": b @ a @ c,
            "bc3": b @ c**3, "bcAc": (b * c) @ a @ c, "bAc2": b @ a @ c**2, "bAAc": b @ a @ a @ c,
        }


class ExplicitRungeKutta(OracleStep):
    """A generic explicit Runge-Kutta step on ``y = (q, qd)``, driven by :attr:`tableau`."""

    tableau: ButcherTableau

    def step(self, system, q, qd, tau, h):
        n = len(q)
        y = np.concatenate((q, qd))
        slopes = np.zeros((self.tableau.stages, 2 * n))
        for i, row in enumerate(self.tableau.a):
            stage = y + h * (row[:i] @ slopes[:i])
            slopes[i, :n] = stage[n:]
            slopes[i, n:] = system.accelerations(stage[:n], stage[n:], tau)
        y = y + h * (self.tableau.b @ slopes)
        return y[:n], y[n:]


class RK4(ExplicitRungeKutta):
    """The classical fourth-order Runge-Kutta method."""

    name = "rk4"
    tableau = ButcherTableau(
        a=[[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
        b=[1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0],
        c=[0.0, 0.5, 0.5, 1.0],
    )


def backward_euler_penalty_velocity(mass_matrix, force, jacobian, residual, kp, kv, qd, h):
    """``v+`` of a step backward-Euler in the linearized penalty forces (module docstring).

    Parameters
    ----------
    mass_matrix : ndarray, shape (n, n)
    force : ndarray, shape (n,)
        ``Q = tau - b`` at the start of the step, N m or N.
    jacobian : ndarray, shape (r, n)
        ``A``.
    residual : ndarray, shape (r,)
        ``C``, m or rad.
    kp, kv : ndarray, shape (r,)
        Penalty gains per row.
    qd : ndarray, shape (n,)
        Velocity at the start of the step.
    h : float
        Step, s.

    Returns
    -------
    ndarray, shape (n,)
    """
    kp, kv = np.asarray(kp, dtype=float), np.asarray(kv, dtype=float)

    def end_force(v):
        return -(kp * (residual + h * (jacobian @ v)) + kv * (jacobian @ v))

    def newton_residual(v):
        return mass_matrix @ (v - qd) - h * (force + jacobian.T @ end_force(v))

    slope = mass_matrix + h * jacobian.T @ ((h * kp + kv)[:, None] * jacobian)
    return qd - np.linalg.solve(slope, newton_residual(qd))


class ImplicitPenaltyEuler(OracleStep):
    """Backward Euler in the penalty forces (module docstring): one evaluation per step."""

    name = "implicit_euler"

    def step(self, system, q, qd, tau, h):
        ev = system.evaluate(q, qd, tau)
        if isinstance(system.method, PenaltyClosure):
            velocity = backward_euler_penalty_velocity(
                ev.dyn.mass_matrix, tau - ev.dyn.bias, ev.closure.jacobian, ev.closure.residual,
                system.method.kp, system.method.kv, qd, h)
        else:
            velocity = qd + h * ev.qdd
        return q + h * velocity, velocity


INTEGRATORS = {
    cls.name: cls for cls in (ExplicitEuler, SemiImplicitEuler, RK4, ImplicitPenaltyEuler)
}
"""The oracle's fixed-step methods by registry name."""
