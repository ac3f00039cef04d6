"""Loop closures: the two ways to enforce them, their rows, and the modes of penalty closures.

Rows (docs/design.md section 2; computed by :func:`vjm_ros.core.terms.terms`):

* ``hinge``: ``C = Pa - Pb`` (2 rows, m);
* ``slider``: ``C = (Pa - P0) . n_d`` with ``n_d = e_z x d`` the line normal (1 row, m); the line
  may be carried by a link, then ``d`` and ``P0`` turn with it;
* ``angle``: ``C = wrap(theta_a - theta_b - offset)`` (1 row, rad).

Enforcement (settings here, formulas in the kernels):

* :class:`PenaltyClosure`: force ``F = -(Kp C + Kv Cdot)`` per row, generalized force ``A^T F``;
* :class:`ExactClosure`: multipliers from ``A M^-1 A^T lambda = -(A M^-1 Q + Adot qd + 2 alpha Cdot
  + beta^2 C)``, solved by a truncated eigen-decomposition so that a rank-deficient ``A`` (a
  singular pose or redundant closures) gives the minimum-norm multipliers instead of a blow-up.

Both report each closure's force as a world-frame vector ``(Fx, Fy, Mz)`` acting on ``Pa``.
:func:`penalty_modes` judges penalty gains against a step (the stiffness check).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vjm_ros.core.model import Model


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


class ClosureRows:
    """The row layout of a model's closures and the per-closure reductions of row quantities.

    Parameters
    ----------
    model : Model

    Attributes
    ----------
    closures : tuple of Closure
    n_rows : int
        ``r``, the number of rows.
    row_closure : ndarray of int, shape (r,)
        Closure of each row.
    """

    def __init__(self, model: Model):
        self.model = model
        self.closures = model.closures
        self.n_rows = model.n_rows
        self.row_closure = np.array(
            [k for k, c in enumerate(self.closures) for _ in range(c.rows)], dtype=int
        )
        self._starts = np.array([sl.start for sl in self.row_slices()], dtype=np.intp)

    def row_slices(self) -> list[slice]:
        """Row range of each closure in the stacked residual."""
        out, start = [], 0
        for c in self.closures:
            out.append(slice(start, start + c.rows))
            start += c.rows
        return out

    def errors(self, terms: ClosureTerms) -> np.ndarray:
        """Size of each closure's residual (norm over its rows).

        Returns
        -------
        ndarray, shape (k,)
            m for hinge and slider, rad for angle.
        """
        if not len(self._starts):
            return np.zeros(0)
        return np.sqrt(np.add.reduceat(terms.residual**2, self._starts))

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
        if not len(self._starts):
            return np.zeros((0, 3))
        return np.add.reduceat(terms.row_direction * row_force[:, None], self._starts, axis=0)


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
