"""Oracle: loop closures in numpy, residuals ``C(q)``, Jacobians ``A = dC/dq`` and their enforcement.

An independent formulation of the closure rows of :mod:`vjm_ros.core.kernels` (docs/design.md
section 2), written with whole-array numpy operations:

* ``hinge``: ``C = Pa - Pb`` (2 rows, m);
* ``slider``: ``C = (Pa - P0) . n_d`` with ``n_d = e_z x d`` the line normal (1 row, m); the line
  may be carried by a link, then ``d`` and ``P0`` turn with it;
* ``angle``: ``C = wrap(theta_a - theta_b - offset)`` (1 row, rad).

For every row this module also gives ``Cdot = A qd`` and the velocity-product term ``Adot qd``.
Enforcement (the settings classes :class:`~vjm_ros.core.constraints.PenaltyClosure` and
:class:`~vjm_ros.core.constraints.ExactClosure` stay in the package; the formulas are here):

* penalty: force ``F = -(Kp C + Kv Cdot)`` per row, generalized force ``A^T F``;
* exact: multipliers from ``A M^-1 A^T lambda = -(A M^-1 Q + Adot qd + 2 alpha Cdot + beta^2 C)``,
  solved by a truncated eigen-decomposition (LAPACK ``dsyevd``) for the minimum-norm multipliers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oracle.kinematics import Kinematics, angular_jacobian, point_jacobians, point_motion
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.model import ANGLE, GROUND, HINGE, SLIDER, Model


@dataclass
class ClosureTerms:
    """Closure rows at one state.

    Attributes
    ----------
    residual : ndarray, shape (r,)
        ``C``, m or rad.
    rate : ndarray, shape (r,)
        ``Cdot = A qd``.
    jacobian : ndarray, shape (r, n)
        ``A``.
    bias : ndarray, shape (r,)
        ``Adot qd``.
    row_direction : ndarray, shape (r, 3)
        World-frame force (``Fx, Fy, Mz``) produced by a unit multiplier on each row.
    points : ndarray, shape (k, 2)
        Application point ``Pa`` of each closure, m.
    """

    residual: np.ndarray
    rate: np.ndarray
    jacobian: np.ndarray
    bias: np.ndarray
    row_direction: np.ndarray
    points: np.ndarray


class ClosureSet:
    """Evaluates all closures of a model together.

    Parameters
    ----------
    model : Model
    """

    def __init__(self, model: Model):
        self.model = model
        self.closures = model.closures
        self.n_rows = model.n_rows
        self.row_closure = np.array(
            [k for k, c in enumerate(self.closures) for _ in range(c.rows)], dtype=int
        )
        links, local = [], []
        for c in self.closures:
            links += [c.point.link, c.target.link]
            local += [c.point.local, c.target.local]
        self._links = np.array(links, dtype=int).reshape(-1)
        self._local = np.array(local, dtype=float).reshape(-1, 2)

    def row_slices(self) -> list[slice]:
        """Row range of each closure in the stacked residual."""
        out, start = [], 0
        for c in self.closures:
            out.append(slice(start, start + c.rows))
            start += c.rows
        return out

    def evaluate(self, kin: Kinematics, jacobian: bool = True) -> ClosureTerms:
        """Residuals, rates, Jacobian and bias terms of every closure.

        Parameters
        ----------
        kin : Kinematics
            From :func:`oracle.kinematics.forward_kinematics` with rates.
        jacobian : bool
            Skip ``A`` and ``Adot qd`` when False (they are then zero arrays).

        Returns
        -------
        ClosureTerms
        """
        model = self.model
        r, n = self.n_rows, model.n
        res = np.zeros(r)
        rate = np.zeros(r)
        jac = np.zeros((r, n))
        bias = np.zeros(r)
        direction = np.zeros((r, 3))
        k = len(self.closures)
        points = np.zeros((k, 2))
        if k == 0:
            return ClosureTerms(res, rate, jac, bias, direction, points)
        p, v, a = point_motion(kin, self._links, self._local)
        jp = point_jacobians(model, kin, self._links, p) if jacobian else None
        row = 0
        for i, c in enumerate(self.closures):
            ia, ib = 2 * i, 2 * i + 1
            points[i] = p[ia]
            if c.kind == HINGE:
                res[row : row + 2] = p[ia] - p[ib]
                rate[row : row + 2] = v[ia] - v[ib]
                direction[row, 0] = 1.0
                direction[row + 1, 1] = 1.0
                if jacobian:
                    jac[row : row + 2] = jp[ia] - jp[ib]
                    bias[row : row + 2] = a[ia] - a[ib]
                row += 2
            elif c.kind == SLIDER:
                lk = c.target.link
                rot = kin.rotation[lk]
                d = rot @ np.asarray(c.direction)
                nd = np.array((-d[1], d[0]))
                w = kin.omega[lk]
                dp, dv = p[ia] - p[ib], v[ia] - v[ib]
                res[row] = dp @ nd
                rate[row] = dv @ nd - w * (dp @ d)
                direction[row, :2] = nd
                if jacobian:
                    jrow = nd @ (jp[ia] - jp[ib])
                    if lk != GROUND:
                        jrow = jrow - (dp @ d) * angular_jacobian(model, np.array([lk]))[0]
                    jac[row] = jrow
                    bias[row] = (a[ia] - a[ib]) @ nd - 2.0 * w * (dv @ d) - w * w * (dp @ nd)
                row += 1
            elif c.kind == ANGLE:
                la, lb = c.point.link, c.target.link
                diff = kin.theta[la] - kin.theta[lb] - c.offset
                res[row] = (diff + np.pi) % (2.0 * np.pi) - np.pi
                rate[row] = kin.omega[la] - kin.omega[lb]
                direction[row, 2] = 1.0
                if jacobian:
                    jw = angular_jacobian(model, np.array([la, lb]))
                    jac[row] = jw[0] - jw[1]
                row += 1
        return ClosureTerms(res, rate, jac, bias, direction, points)

    def errors(self, terms: ClosureTerms) -> np.ndarray:
        """Size of each closure's residual (norm over its rows).

        Returns
        -------
        ndarray, shape (k,)
            m for hinge and slider, rad for angle.
        """
        sq = np.zeros(len(self.closures))
        np.add.at(sq, self.row_closure, terms.residual**2)
        return np.sqrt(sq)

    def closure_forces(self, terms: ClosureTerms, row_force: np.ndarray) -> np.ndarray:
        """World-frame force of each closure from per-row forces.

        Parameters
        ----------
        terms : ClosureTerms
        row_force : ndarray, shape (r,)

        Returns
        -------
        ndarray, shape (k, 3)
            ``(Fx, Fy, Mz)`` acting on ``Pa``: N, N, N m.
        """
        out = np.zeros((len(self.closures), 3))
        np.add.at(out, self.row_closure, terms.row_direction * row_force[:, None])
        return out


def penalty_row_forces(method: PenaltyClosure, terms: ClosureTerms) -> np.ndarray:
    """Per-row penalty force ``F = -(Kp C + Kv Cdot)``, N or N m."""
    return -(method.kp * terms.residual + method.kv * terms.rate)


def penalty_energy(method: PenaltyClosure, terms: ClosureTerms) -> float:
    """Energy stored in the penalty springs ``sum 1/2 Kp C^2``, J."""
    return 0.5 * float(np.sum(method.kp * terms.residual**2))


def penalty_dissipation(method: PenaltyClosure, terms: ClosureTerms) -> float:
    """Power drawn by the penalty dampers ``sum Kv Cdot^2``, W."""
    return float(np.sum(method.kv * terms.rate**2))


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
        Row multipliers (the closure force per row, N or N m): ``M qdd = Q + A^T lam``.
    """
    a = terms.jacobian
    if a.shape[0] == 0:
        return np.linalg.solve(mass_matrix, force), np.zeros(0)
    x = np.linalg.solve(mass_matrix, np.column_stack((force, a.T)))
    minv_q, minv_at = x[:, 0], x[:, 1:]
    g = a @ minv_at
    rhs = -(
        a @ minv_q + terms.bias + 2.0 * method.alpha * terms.rate + method.beta**2 * terms.residual
    )
    lam = solve_multipliers(g, rhs, method.rcond)
    return minv_q + minv_at @ lam, lam


def closure_mobility(mass_matrix: np.ndarray, jacobian: np.ndarray) -> np.ndarray:
    """``G = A M^-1 A^T``: closure-row accelerations per unit row force.

    ``Cddot = G F + (terms without F)`` for row forces ``F``; symmetric positive semi-definite,
    rank-deficient when ``A`` loses rank (a singular pose, redundant closures).

    Parameters
    ----------
    mass_matrix : ndarray, shape (n, n)
    jacobian : ndarray, shape (r, n)

    Returns
    -------
    ndarray, shape (r, r)
        1/kg for translation rows (1/(kg m^2) for angle rows, mixed entries between them).
    """
    g = jacobian @ np.linalg.solve(mass_matrix, jacobian.T)
    return 0.5 * (g + g.T)


def solve_multipliers(g: np.ndarray, rhs: np.ndarray, rcond: float = 1e-10) -> np.ndarray:
    """Minimum-norm solution of ``G lambda = rhs`` for symmetric positive semi-definite ``G``.

    Eigenvalues below ``rcond * max eigenvalue`` are treated as zero, so directions that the
    closures do not constrain independently (rank loss of ``A``) receive no multiplier.

    Parameters
    ----------
    g : ndarray, shape (r, r)
    rhs : ndarray, shape (r,)
    rcond : float

    Returns
    -------
    ndarray, shape (r,)
    """
    if g.shape[0] == 0:
        return np.zeros(0)
    w, v = np.linalg.eigh(g)
    keep = w > rcond * max(float(w[-1]), 1e-300)
    inv = np.zeros_like(w)
    inv[keep] = 1.0 / w[keep]
    return v @ (inv * (v.T @ rhs))


def project_velocity(
    mass_matrix: np.ndarray, jacobian: np.ndarray, qd: np.ndarray, rcond: float = 1e-10
) -> np.ndarray:
    """Remove the part of ``qd`` that violates ``A qd = 0`` (kinetic-energy metric).

    Returns
    -------
    ndarray, shape (n,)
    """
    if jacobian.shape[0] == 0:
        return qd
    minv_at = np.linalg.solve(mass_matrix, jacobian.T)
    g = jacobian @ minv_at
    return qd - minv_at @ solve_multipliers(g, jacobian @ qd, rcond)
