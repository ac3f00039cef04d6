"""Loop closures: residuals ``C(q)``, Jacobians ``A = dC/dq``, and the two ways to enforce them.

Rows (docs/design.md section 2):

* ``hinge``: ``C = Pa - Pb`` (2 rows, m);
* ``slider``: ``C = (Pa - P0) . n_d`` with ``n_d = e_z x d`` the line normal (1 row, m); the line
  may be carried by a link, then ``d`` and ``P0`` turn with it;
* ``angle``: ``C = wrap(theta_a - theta_b - offset)`` (1 row, rad).

For every row this module also gives ``Cdot = A qd`` and the velocity-product term ``Adot qd``
(the part of ``Cddot`` that does not depend on ``qdd``), which the exact method needs.

Enforcement:

* :class:`PenaltyClosure`: force ``F = -(Kp C + Kv Cdot)`` per row, generalized force ``A^T F``;
* :class:`ExactClosure`: multipliers from ``A M^-1 A^T lambda = -(A M^-1 Q + Adot qd + 2 alpha Cdot
  + beta^2 C)``, solved by a truncated eigen-decomposition so that a rank-deficient ``A`` (a
  singular pose or redundant closures) gives the minimum-norm multipliers instead of a blow-up.

Both report each closure's force as a world-frame vector ``(Fx, Fy, Mz)`` acting on ``Pa``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vjm_ros.core.kinematics import Kinematics, angular_jacobian, point_jacobians, point_motion
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
            From :func:`vjm_ros.core.kinematics.forward_kinematics` with rates.
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


@dataclass
class PenaltyClosure:
    """The thesis's PD closure ``F = -(Kp C + Kv Cdot)`` per row.

    Attributes
    ----------
    kp : ndarray, shape (r,)
        Stiffness per row, N/m (N m/rad for angle rows).
    kv : ndarray, shape (r,)
        Damping per row, N s/m (N m s/rad).
    """

    kp: np.ndarray
    kv: np.ndarray

    method = "penalty"

    def row_forces(self, terms: ClosureTerms) -> np.ndarray:
        """Per-row closure force, N or N m."""
        return -(self.kp * terms.residual + self.kv * terms.rate)

    def energy(self, terms: ClosureTerms) -> float:
        """Energy stored in the penalty springs ``sum 1/2 Kp C^2``, J."""
        return 0.5 * float(np.sum(self.kp * terms.residual**2))

    def dissipation(self, terms: ClosureTerms) -> float:
        """Power drawn by the penalty dampers ``sum Kv Cdot^2``, W."""
        return float(np.sum(self.kv * terms.rate**2))


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


def effective_masses(mass_matrix: np.ndarray, jacobian: np.ndarray) -> np.ndarray:
    """Effective mass of each closure row, ``1 / (A M^-1 A^T)_ii`` (arguments as
    :func:`closure_mobility`).

    Returns
    -------
    ndarray, shape (r,)
        kg (kg m^2 for angle rows); ``inf`` for a row that no coordinate moves.
    """
    diag = np.diag(closure_mobility(mass_matrix, jacobian)).copy()
    with np.errstate(divide="ignore"):
        return np.where(diag > 0, 1.0 / np.maximum(diag, 1e-300), np.inf)


@dataclass
class PenaltyModes:
    """Coupled modes of the penalty closure error near the closure manifold.

    With row forces ``F = -(Kp C + Kv Cdot)`` the closure error obeys, to first order,
    ``Cddot = -G Kp C - G Kv Cdot`` (``G`` from :func:`closure_mobility`), i.e.
    ``x' = J x`` with ``x = (C, Cdot)`` and ``J = [[0, I], [-G Kp, -G Kv]]``. Directions that
    ``G`` does not reach (its null space, in a singular pose or with redundant closures) get no
    penalty force and set no time scale; they are left out.

    Attributes
    ----------
    omega_n : ndarray, shape (p,)
        Natural frequency of each mode, rad/s.
    zeta : ndarray, shape (p,)
        Damping ratio of each mode (dimensionless).
    eigenvalues : ndarray of complex, shape (p, 2)
        The roots ``mu`` of each mode (eigenvalues of ``J``), 1/s:
        ``mu^2 + 2 zeta omega_n mu + omega_n^2 = 0``.
    share : ndarray, shape (p, r)
        Fraction of each mode carried by each row (rows sum to 1): of the mode's spring energy
        ``1/2 Kp_i C_i^2`` for proportional gains, of ``|C_i|^2`` otherwise.
    proportional : bool
        ``Kv = c Kp`` for one constant ``c``: then every mode is an independent damped
        oscillator and ``stiffness``/``damping`` are diagonal (modal coordinates).
    stiffness, damping : ndarray, shape (q, q)
        The closure dynamics restricted to the directions ``G`` reaches,
        ``y'' = -stiffness y - damping y'`` (1/s^2, 1/s): modal coordinates when
        ``proportional`` (``q = p``), else coordinates in an orthonormal basis of the range of
        ``G`` (``q`` its rank).
    """

    omega_n: np.ndarray
    zeta: np.ndarray
    eigenvalues: np.ndarray
    share: np.ndarray
    proportional: bool
    stiffness: np.ndarray
    damping: np.ndarray


def penalty_modes(
    mobility: np.ndarray, kp: np.ndarray, kv: np.ndarray, rcond: float = 1e-10
) -> PenaltyModes:
    """Coupled modes of the penalty closure from ``G``, ``Kp`` and ``Kv``.

    Proportional gains (``Kv = c Kp``, what raw gains or ``omega_n``/``zeta`` give): the
    eigenvalues ``k`` of the symmetric ``Kp^1/2 G Kp^1/2`` (those of ``G Kp``) give
    ``omega_n = sqrt(k)`` and ``zeta = c omega_n / 2``. A single row, or rows that share no
    coordinate, gives back the per-row ``omega_n = sqrt(Kp_i G_ii)`` (``Kp_i / m_eff``).
    Otherwise the modes come from the eigenvalues ``mu`` of ``J`` restricted to the range of
    ``G``: a complex pair gives ``omega_n = |mu|``, ``zeta = -Re mu / |mu|``; a real ``mu``
    counts as a mode with the double root ``mu`` (``omega_n = |mu|``, ``zeta = 1``).

    Parameters
    ----------
    mobility : ndarray, shape (r, r)
        ``G = A M^-1 A^T`` at the pose judged.
    kp : ndarray, shape (r,)
        Row stiffness, N/m (N m/rad).
    kv : ndarray, shape (r,)
        Row damping, N s/m (N m s/rad).
    rcond : float
        Eigenvalues below ``rcond`` times the largest are treated as zero.

    Returns
    -------
    PenaltyModes
        Modes sorted by ``omega_n``, stiffest first.
    """
    g = np.asarray(mobility, dtype=float)
    kp = np.asarray(kp, dtype=float)
    kv = np.asarray(kv, dtype=float)
    r = kp.size
    spring = kp > 0
    c = float(np.median(kv[spring] / kp[spring])) if spring.any() else 0.0
    scale = max(float(np.max(np.abs(kv), initial=0.0)), 1e-300)
    proportional = bool(spring.any()) and float(np.max(np.abs(kv - c * kp))) <= 1e-9 * scale
    if proportional:
        w = np.sqrt(kp)
        k, u = np.linalg.eigh(w[:, None] * g * w[None, :])
        keep = k > rcond * max(float(k[-1]), 1e-300)
        k, u = k[keep][::-1], u[:, keep][:, ::-1]
        omega = np.sqrt(k)
        zeta = 0.5 * c * omega
        disc = np.sqrt(zeta.astype(complex) ** 2 - 1.0)
        roots = omega[:, None] * np.stack((-zeta + disc, -zeta - disc), axis=1)
        return PenaltyModes(omega, zeta, roots, (u**2).T, True, np.diag(k), np.diag(c * k))
    if r == 0 or not np.any(g):
        empty = np.zeros(0)
        return PenaltyModes(empty, empty, np.zeros((0, 2), complex), np.zeros((0, r)), False,
                            np.zeros((0, 0)), np.zeros((0, 0)))
    lam, vec = np.linalg.eigh(g)
    basis = vec[:, lam > rcond * max(float(lam[-1]), 1e-300)]
    stiffness = basis.T @ (g * kp[None, :]) @ basis
    damping = basis.T @ (g * kv[None, :]) @ basis
    q = basis.shape[1]
    jac = np.block([[np.zeros((q, q)), np.eye(q)], [-stiffness, -damping]])
    mu, modes = np.linalg.eig(jac)
    size = np.abs(mu)
    live = size > rcond * max(float(size.max(initial=0.0)), 1e-300)
    real = np.abs(mu.imag) <= 1e-9 * size
    pick = live & (real | (mu.imag > 0))
    mu, shape = mu[pick], np.abs(basis @ modes[:q, pick]) ** 2
    omega = np.abs(mu)
    zeta = np.where(real[pick], 1.0, -mu.real / np.maximum(omega, 1e-300))
    roots = np.stack((mu, np.where(real[pick], mu, mu.conj())), axis=1)
    order = np.argsort(-omega, kind="stable")
    share = (shape / np.maximum(shape.sum(axis=0), 1e-300)).T
    return PenaltyModes(omega[order], zeta[order], roots[order], share[order], False,
                        stiffness, damping)


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


@dataclass
class ExactClosure:
    """Closure by Lagrange multipliers at acceleration level with Baumgarte stabilization.

    Attributes
    ----------
    alpha : float
        Velocity feedback, 1/s (the ``2 alpha Cdot`` term).
    beta : float
        Position feedback, 1/s (the ``beta^2 C`` term).
    projection : bool
        Project ``q`` and ``qd`` back onto the closure manifold after every step.
    rcond : float
        Relative eigenvalue cut-off for rank-deficient ``A M^-1 A^T``.
    """

    alpha: float = 10.0
    beta: float = 10.0
    projection: bool = False
    rcond: float = 1e-10

    method = "exact"

    def accelerations(
        self, mass_matrix: np.ndarray, force: np.ndarray, terms: ClosureTerms
    ) -> tuple[np.ndarray, np.ndarray]:
        """Constrained accelerations and multipliers.

        Parameters
        ----------
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
            a @ minv_q + terms.bias + 2.0 * self.alpha * terms.rate + self.beta**2 * terms.residual
        )
        lam = solve_multipliers(g, rhs, self.rcond)
        return minv_q + minv_at @ lam, lam


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
