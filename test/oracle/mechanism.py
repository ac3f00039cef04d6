"""Oracle: the closed mechanism in numpy, open-chain dynamics plus the chosen closure method.

The same interface as the package's compiled :class:`vjm_ros.core.mechanism.Mechanism`
(``evaluate``, ``accelerations``, ``implicit_penalty_velocity``, ``energies``,
``closure_jacobian``, ``project``), assembled from :mod:`oracle.dynamics` and
:mod:`oracle.constraints` with LAPACK solves, so that the kernels can be checked against it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oracle.constraints import (
    ClosureSet,
    ClosureTerms,
    exact_accelerations,
    penalty_energy,
    penalty_row_forces,
    project_velocity,
    solve_multipliers,
)
from oracle.dynamics import DynamicsTerms, dynamics_terms, energy_from_terms
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.model import Model


@dataclass
class Evaluation:
    """Every derived quantity at one state and effort.

    Attributes
    ----------
    qdd : ndarray, shape (n,)
    dyn : DynamicsTerms
    closure : ClosureTerms
    row_force : ndarray, shape (r,)
        Closure force per row (penalty force or multiplier), N or N m.
    """

    qdd: np.ndarray
    dyn: DynamicsTerms
    closure: ClosureTerms
    row_force: np.ndarray


class Mechanism:
    """Open chains closed by penalty forces or multipliers.

    Parameters
    ----------
    model : Model
    method : PenaltyClosure or ExactClosure
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
        """Accelerations and closure forces.

        Parameters
        ----------
        q, qd : ndarray, shape (n,)
        tau : ndarray, shape (n,)
            Generalized efforts, N m or N.

        Returns
        -------
        Evaluation
        """
        self.evaluations += 1
        dyn = dynamics_terms(self.model, q, qd)
        ct = self.closures.evaluate(dyn.kin)
        force = tau - dyn.bias
        if isinstance(self.method, PenaltyClosure):
            rf = penalty_row_forces(self.method, ct)
            qdd = np.linalg.solve(dyn.mass_matrix, force + ct.jacobian.T @ rf)
        else:
            qdd, rf = exact_accelerations(self.method, dyn.mass_matrix, force, ct)
        return Evaluation(qdd, dyn, ct, rf)

    def accelerations(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """``qdd`` only (what explicit integrators need)."""
        return self.evaluate(q, qd, tau).qdd

    def implicit_penalty_velocity(
        self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, h: float
    ) -> np.ndarray:
        """Velocity after one step that is implicit in the penalty forces.

        Solves ``M (v+ - v) = h (Q + A^T F+)`` with the penalty force linearized at the end of the
        step, ``F+ = -(Kp (C + h A v+) + Kv A v+)``:
        ``(M + h A^T (h Kp + Kv) A) dv = h (Q + A^T (F - h Kp A v))``.
        With exact closures this is the explicit (semi-implicit Euler) velocity update.

        Returns
        -------
        ndarray, shape (n,)
        """
        ev = self.evaluate(q, qd, tau)
        if not isinstance(self.method, PenaltyClosure):
            return qd + h * ev.qdd
        a = ev.closure.jacobian
        kp, kv = self.method.kp, self.method.kv
        lhs = ev.dyn.mass_matrix + h * (a.T * (h * kp + kv)) @ a
        rhs = h * (tau - ev.dyn.bias + a.T @ (ev.row_force - h * kp * (a @ qd)))
        return qd + np.linalg.solve(lhs, rhs)

    def energies(self, ev: Evaluation, qd: np.ndarray) -> np.ndarray:
        """Kinetic, potential, constraint and total energy, J.

        Returns
        -------
        ndarray, shape (4,)
        """
        kinetic, potential = energy_from_terms(self.model, ev.dyn, qd)
        constraint = penalty_energy(self.method, ev.closure) if self.is_penalty else 0.0
        return np.array([kinetic, potential, constraint, kinetic + potential + constraint])

    def closure_jacobian(self, q: np.ndarray) -> np.ndarray:
        """The closure Jacobian ``A(q)``, shape (r, n)."""
        return self.closures.evaluate(dynamics_terms(self.model, q, np.zeros(self.n)).kin).jacobian

    def project(
        self, q: np.ndarray, qd: np.ndarray, tol: float = 1e-12, iterations: int = 8
    ) -> tuple[np.ndarray, np.ndarray]:
        """Move ``q`` onto ``C(q) = 0`` and ``qd`` onto ``A qd = 0`` (mass-weighted least change).

        Returns
        -------
        q, qd : ndarray, shape (n,)
        """
        if self.closures.n_rows == 0:
            return q, qd
        q = q.copy()
        for _ in range(iterations):
            dyn = dynamics_terms(self.model, q, np.zeros(self.n))
            ct = self.closures.evaluate(dyn.kin)
            if np.max(np.abs(ct.residual)) <= tol:
                break
            q = q - _weighted_min_norm(dyn.mass_matrix, ct.jacobian, ct.residual)
        dyn = dynamics_terms(self.model, q, np.zeros(self.n))
        ct = self.closures.evaluate(dyn.kin)
        return q, project_velocity(dyn.mass_matrix, ct.jacobian, qd)


def _weighted_min_norm(mass_matrix: np.ndarray, a: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``M^-1 A^T (A M^-1 A^T)^+ c``: the M-metric least change ``dq`` with ``A dq = c``."""
    minv_at = np.linalg.solve(mass_matrix, a.T)
    return minv_at @ solve_multipliers(a @ minv_at, c)
