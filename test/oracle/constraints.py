"""Oracle: loop closures, their rows ``C(q)``, ``A = dC/dq``, ``Adot qd``, and their enforcement.

Rows (docs/design.md section 2) from the positions, joint columns and bias accelerations of the
closure points (:mod:`oracle.kinematics`), closure by closure:

* ``hinge``: ``C = Pa - Pb``, ``A = J_a - J_b``, ``Adot qd = a_a - a_b`` (2 rows, m);
* ``slider``: ``C = r . n_d`` with ``r = Pa - Pb`` and ``n_d = e_z x d`` the normal of the line,
  which turns with the link that carries it (``d' = omega_b n_d``, ``n_d' = -omega_b d``):
  ``A = n_d . (J_a - J_b) - (r . d) Jw_b`` and, differentiating twice at ``qdd = 0``,
  ``Adot qd = n_d . (a_a - a_b) - 2 omega_b (v_a - v_b) . d - omega_b^2 r . n_d`` (1 row, m);
* ``angle``: ``C = wrap(theta_a - theta_b - offset)``, ``A = Jw_a - Jw_b``, ``Adot qd = 0``
  (1 row, rad);

and ``Cdot = A qd`` for every row. Enforcement (the settings classes
:class:`~vjm_ros.core.constraints.PenaltyClosure` and
:class:`~vjm_ros.core.constraints.ExactClosure` stay in the package; the formulas are here):

* penalty: ``F = -(Kp C + Kv Cdot)`` per row, generalized force ``A^T F``;
* exact: ``G lambda = -(A M^-1 Q + Adot qd + 2 alpha Cdot + beta^2 C)``, ``G = A M^-1 A^T``, solved
  through the singular values of the whitened Jacobian ``B = A L^-T`` (``M = L L^T``,
  ``G = B B^T``): the minimum-norm multipliers, the singular values with
  ``s^2 <= rcond * s_max^2`` (the eigenvalues of ``G`` below ``rcond`` of the largest) dropped.
"""

from __future__ import annotations

import math

import numpy as np

from oracle.dynamics import MassFactor
from oracle.kinematics import Kinematics
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.model import ANGLE, HINGE, SLIDER, Model


class _Point:
    """Position, velocity, bias acceleration and Jacobian of one closure point."""

    def __init__(self, kin: Kinematics, ref):
        self.p = kin.position(ref.link, ref.local)
        self.jac = kin.jacobian(ref.link, self.p)
        self.v = self.jac @ kin.qd
        self.a = kin.bias_acceleration(ref.link, self.p, self.v)


class ClosureTerms:
    """The closure rows of a model at one state, in scene order.

    Parameters
    ----------
    model : Model
    kin : Kinematics
        With rates.
    jacobian : bool
        False: only ``residual``, ``row_direction`` and ``points`` (the rest stays zero).

    Attributes
    ----------
    residual, rate, bias : ndarray, shape (r,)
        Per row ``C`` (m or rad), ``Cdot = A qd`` and ``Adot qd``.
    jacobian : ndarray, shape (r, n)
        ``A = dC/dq``.
    row_direction : ndarray, shape (r, 3)
        ``(Fx, Fy, Mz)`` in the world frame that a unit row force puts on ``Pa``.
    points : ndarray, shape (k, 2)
        ``Pa`` of each closure, m.
    """

    def __init__(self, model: Model, kin: Kinematics, jacobian: bool = True):
        rows, n = model.n_rows, model.n
        self.residual = np.zeros(rows)
        self.jacobian = np.zeros((rows, n))
        self.bias = np.zeros(rows)
        self.row_direction = np.zeros((rows, 3))
        self.points = np.zeros((len(model.closures), 2))
        row = 0
        for k, closure in enumerate(model.closures):
            if closure.kind == HINGE:
                self._hinge(kin, closure, row)
            elif closure.kind == SLIDER:
                self._slider(kin, closure, row)
            elif closure.kind == ANGLE:
                self._angle(kin, closure, row)
            self.points[k] = kin.position(closure.point.link, closure.point.local)
            row += closure.rows
        if not jacobian:
            self.jacobian[:] = 0.0
            self.bias[:] = 0.0
        self.rate = self.jacobian @ kin.qd

    def _hinge(self, kin: Kinematics, closure, row: int) -> None:
        a, b = _Point(kin, closure.point), _Point(kin, closure.target)
        self.residual[row : row + 2] = a.p - b.p
        self.jacobian[row : row + 2] = a.jac - b.jac
        self.bias[row : row + 2] = a.a - b.a
        self.row_direction[row, 0] = self.row_direction[row + 1, 1] = 1.0

    def _slider(self, kin: Kinematics, closure, row: int) -> None:
        a, b = _Point(kin, closure.point), _Point(kin, closure.target)
        carrier = closure.target.link
        d = kin.rotation[carrier] @ np.asarray(closure.direction, dtype=float)
        normal = np.array((-d[1], d[0]))
        w = kin.omega[carrier]
        r, dv = a.p - b.p, a.v - b.v
        self.residual[row] = r @ normal
        self.jacobian[row] = normal @ (a.jac - b.jac) - (r @ d) * kin.angle_jacobian(carrier)
        self.bias[row] = normal @ (a.a - b.a) - 2.0 * w * (dv @ d) - w * w * (r @ normal)
        self.row_direction[row, :2] = normal

    def _angle(self, kin: Kinematics, closure, row: int) -> None:
        first, second = closure.point.link, closure.target.link
        gap = kin.theta[first] - kin.theta[second] - closure.offset
        wrapped = math.remainder(gap, 2.0 * math.pi)  # exact, in [-pi, pi]
        self.residual[row] = -math.pi if wrapped == math.pi else wrapped  # [-pi, pi)
        self.jacobian[row] = kin.angle_jacobian(first) - kin.angle_jacobian(second)
        self.row_direction[row, 2] = 1.0


class ClosureSet:
    """The closures of a model: their rows and per-closure sums.

    Attributes
    ----------
    model : Model
    closures : tuple of Closure
        In scene order, ``n_rows`` rows in all.
    row_closure : ndarray of int, shape (r,)
        Index of the closure each row belongs to.
    """

    def __init__(self, model: Model):
        self.model = model
        self.closures = model.closures
        self.n_rows = model.n_rows
        owner = []
        for k, closure in enumerate(self.closures):
            owner += [k] * closure.rows
        self.row_closure = np.array(owner, dtype=int)

    def evaluate(self, kin: Kinematics, jacobian: bool = True) -> ClosureTerms:
        """:class:`ClosureTerms` at the state of ``kin`` (``jacobian``: see there)."""
        return ClosureTerms(self.model, kin, jacobian)

    def errors(self, terms: ClosureTerms) -> np.ndarray:
        """``|C|`` of each closure over its rows, shape (k,): m (hinge, slider) or rad (angle)."""
        return np.array([np.linalg.norm(terms.residual[self.row_closure == k])
                         for k in range(len(self.closures))])

    def closure_forces(self, terms: ClosureTerms, row_force: np.ndarray) -> np.ndarray:
        """World-frame force ``(Fx, Fy, Mz)`` on each ``Pa`` (N, N, N m), shape (k, 3), from the
        row forces (shape (r,))."""
        out = np.zeros((len(self.closures), 3))
        for k in range(len(self.closures)):
            mine = self.row_closure == k
            out[k] = row_force[mine] @ terms.row_direction[mine]
        return out


def penalty_row_forces(method: PenaltyClosure, terms: ClosureTerms) -> np.ndarray:
    """Per-row penalty force ``F = -(Kp C + Kv Cdot)``, N or N m."""
    return -(np.asarray(method.kp) * terms.residual + np.asarray(method.kv) * terms.rate)


class WhitenedClosures:
    """``M = L L^T`` and the singular values of ``B = A L^-T`` (``G = A M^-1 A^T = B B^T``).

    Parameters
    ----------
    mass_matrix : ndarray, shape (n, n)
    jacobian : ndarray, shape (r, n)
    rcond : float
        Directions of ``G`` with eigenvalue ``s^2 <= rcond * s_max^2`` get no multiplier.
    """

    def __init__(self, mass_matrix: np.ndarray, jacobian: np.ndarray, rcond: float = 1e-10):
        self.mass = MassFactor(mass_matrix)
        self.whitened_t = self.mass.half_solve(jacobian.T)  # B^T = L^-1 A^T, shape (n, r)
        u, s, vt = np.linalg.svd(self.whitened_t.T, full_matrices=False)
        keep = s * s > rcond * max(float(s.max(initial=0.0)) ** 2, 1e-300)
        self.u, self.s, self.vt = u[:, keep], s[keep], vt[keep]

    def solve_multipliers(self, rhs: np.ndarray) -> np.ndarray:
        """Minimum-norm ``lambda`` of ``G lambda = rhs``: ``U S^-2 U^T rhs``."""
        return self.u @ ((self.u.T @ rhs) / self.s**2)

    def spread(self, lam: np.ndarray) -> np.ndarray:
        """``M^-1 A^T lambda`` (the motion a row force gives): ``L^-T B^T lambda``."""
        return self.mass.half_solve_transposed(self.whitened_t @ lam)

    def least_change(self, c: np.ndarray) -> np.ndarray:
        """The ``M``-metric least ``dq`` with ``A dq = c`` (the least-squares one where ``c`` is
        not in the range of ``A``): ``L^-T B^+ c``."""
        return self.mass.half_solve_transposed(self.vt.T @ ((self.u.T @ c) / self.s))


def exact_accelerations(
    method: ExactClosure, mass_matrix: np.ndarray, force: np.ndarray, terms: ClosureTerms
) -> tuple[np.ndarray, np.ndarray]:
    """Constrained accelerations and multipliers of the exact (Baumgarte) closure.

    Parameters
    ----------
    method : ExactClosure
    mass_matrix : ndarray, shape (n, n)
    force : ndarray, shape (n,)
        ``Q = tau - b``, the generalized force without closures.
    terms : ClosureTerms

    Returns
    -------
    qdd : ndarray, shape (n,)
    lam : ndarray, shape (r,)
        Row multipliers (N or N m): ``M qdd = Q + A^T lam`` and
        ``A qdd + Adot qd = -(2 alpha Cdot + beta^2 C)`` where ``G`` is regular.
    """
    if terms.jacobian.shape[0] == 0:
        return MassFactor(mass_matrix).solve(force), np.zeros(0)
    solve = WhitenedClosures(mass_matrix, terms.jacobian, method.rcond)
    free = solve.mass.solve(force)
    feedback = 2.0 * method.alpha * terms.rate + method.beta**2 * terms.residual
    lam = solve.solve_multipliers(-(terms.jacobian @ free + terms.bias + feedback))
    return free + solve.spread(lam), lam
