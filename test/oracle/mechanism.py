"""Oracle: the closed mechanism, open-chain dynamics plus the chosen closure method.

What the package's compiled :class:`vjm_ros.core.mechanism.Mechanism` offers (``evaluate``,
``accelerations``, ``implicit_penalty_velocity``, ``energies``, ``closure_jacobian``,
``project``), assembled from :mod:`oracle.dynamics` (Newton-Euler), :mod:`oracle.constraints`
(closure rows, multipliers through the whitened Jacobian) and :mod:`oracle.fixed` (the step
implicit in the penalty forces), so that the kernels can be checked against it.
"""

from __future__ import annotations

import numpy as np

from oracle.constraints import ClosureSet, WhitenedClosures, exact_accelerations, penalty_row_forces
from oracle.dynamics import DynamicsTerms, MassFactor
from oracle.fixed import backward_euler_penalty_velocity
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.model import Model


class Evaluation:
    """The state's dynamics and closure rows, and the closure forces and accelerations they give.

    Parameters
    ----------
    mechanism : Mechanism
    q, qd : ndarray, shape (n,)
    tau : ndarray, shape (n,)
        Generalized efforts, N m or N.

    Attributes
    ----------
    dyn : DynamicsTerms
    closure : ClosureTerms
    row_force : ndarray, shape (r,)
        Closure force per row (penalty force or multiplier), N or N m.
    qdd : ndarray, shape (n,)
    """

    def __init__(self, mechanism: Mechanism, q: np.ndarray, qd: np.ndarray, tau: np.ndarray):
        self.dyn = DynamicsTerms(mechanism.model, q, qd)
        self.closure = mechanism.closures.evaluate(self.dyn.kin)
        free = np.asarray(tau, dtype=float) - self.dyn.bias
        method = mechanism.method
        if isinstance(method, PenaltyClosure):
            self.row_force = penalty_row_forces(method, self.closure)
            self.qdd = MassFactor(self.dyn.mass_matrix).solve(
                free + self.closure.jacobian.T @ self.row_force)
        else:
            self.qdd, self.row_force = exact_accelerations(
                method, self.dyn.mass_matrix, free, self.closure)


class Mechanism:
    """Open chains closed by penalty forces or multipliers.

    Parameters
    ----------
    model : Model
    method : PenaltyClosure or ExactClosure

    Attributes
    ----------
    evaluations : int
        Right-hand sides evaluated (``evaluate``, ``accelerations``,
        ``implicit_penalty_velocity``), counted as the package's mechanism counts them.
    """

    def __init__(self, model: Model, method: PenaltyClosure | ExactClosure):
        self.model = model
        self.method = method
        self.closures = ClosureSet(model)
        self.n = model.n
        self.evaluations = 0

    @property
    def is_penalty(self) -> bool:
        """True when closures are enforced by penalty forces."""
        return isinstance(self.method, PenaltyClosure)

    def evaluate(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> Evaluation:
        """:class:`Evaluation` at ``(q, qd)`` under ``tau``."""
        self.evaluations += 1
        return Evaluation(self, q, qd, tau)

    def accelerations(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """``qdd``, shape (n,) (rad/s^2 or m/s^2)."""
        return self.evaluate(q, qd, tau).qdd

    def implicit_penalty_velocity(
        self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, h: float
    ) -> np.ndarray:
        """Velocity after one step of length ``h`` (s) backward-Euler in the penalty forces
        (:func:`oracle.fixed.backward_euler_penalty_velocity`); with exact closures
        ``qd + h qdd``."""
        ev = self.evaluate(q, qd, tau)
        if not self.is_penalty:
            return qd + h * ev.qdd
        return backward_euler_penalty_velocity(
            ev.dyn.mass_matrix, np.asarray(tau, dtype=float) - ev.dyn.bias, ev.closure.jacobian,
            ev.closure.residual, self.method.kp, self.method.kv, qd, h)

    def energies(self, ev: Evaluation, qd: np.ndarray) -> np.ndarray:
        """Kinetic, gravitational, penalty-spring (``sum 1/2 Kp C^2``) and total energy, J,
        shape (4,) (``qd``: the evaluated state's, kept for the package's signature)."""
        kinetic, potential = ev.dyn.energies()
        spring = 0.0
        if self.is_penalty:
            spring = 0.5 * float(np.asarray(self.method.kp) @ ev.closure.residual**2)
        return np.array([kinetic, potential, spring, kinetic + potential + spring])

    def closure_jacobian(self, q: np.ndarray) -> np.ndarray:
        """``A(q)``, shape (r, n)."""
        return self.closures.evaluate(DynamicsTerms(self.model, q, np.zeros(self.n)).kin).jacobian

    def project(
        self, q: np.ndarray, qd: np.ndarray, tol: float = 1e-12, iterations: int = 8
    ) -> tuple[np.ndarray, np.ndarray]:
        """Move ``q`` onto ``C(q) = 0`` and ``qd`` onto ``A qd = 0``, each by the least change in
        the metric of ``M``: at most ``iterations`` Gauss-Newton steps until ``max |C| <= tol``,
        then one velocity projection (``rcond = 1e-10``).

        Returns
        -------
        q, qd : ndarray, shape (n,)
        """
        if self.closures.n_rows == 0:
            return q, qd
        q = np.array(q, dtype=float)
        for done in range(iterations + 1):
            dyn = DynamicsTerms(self.model, q, np.zeros(self.n))
            rows = self.closures.evaluate(dyn.kin)
            metric = WhitenedClosures(dyn.mass_matrix, rows.jacobian)
            if done == iterations or np.max(np.abs(rows.residual)) <= tol:
                return q, qd - metric.least_change(rows.jacobian @ qd)
            q = q - metric.least_change(rows.residual)
        raise AssertionError("unreachable")
