"""Oracle: open-chain dynamics ``M(q) qdd + b(q, qd) = tau`` by the recursive Newton-Euler method.

Inverse dynamics is written as the balance of each link (docs/design.md section 1 conventions,
gravity ``g``), chain by chain:

* outward, the motion: ``omega_i = omega_pred + phid_i``, ``alpha_i = alpha_pred + phidd_i``;
  the origin ``O_i = O_pred + d_i`` (``d_i`` fixed on the predecessor plus the slide ``B_i`` along
  its normal ``n_i``) accelerates as
  ``a_O,i = a_O,pred + alpha_pred e_z x d_i - omega_pred^2 d_i + 2 omega_pred Bd_i e_z x n_i
  + Bdd_i n_i`` and the mass centre as ``a_c,i = a_O,i + alpha_i e_z x r_i - omega_i^2 r_i``
  (``r_i = c_i - O_i``);
* inward, the forces: joint ``i`` acts on link ``i`` with the force
  ``F_i = m_i (a_c,i - g) + F_(i+1)`` and the moment about ``O_i``
  ``N_i = I_i alpha_i + N_(i+1) + r_i x F_i + (O_(i+1) - c_i) x F_(i+1)`` (Newton and Euler about
  the mass centre, the successor's joint reacting on the link);
* the joint effort is what the joint does not hold by itself: ``tau_i = N_i`` (revolute) or
  ``tau_i = F_i . n_i`` (prismatic).

So ``b = ID(q, qd, 0)`` and column ``k`` of ``M`` is ``ID(q, 0, e_k)`` without gravity. The
energies are the definitions ``T = sum 1/2 m_i |v_c,i|^2 + 1/2 I_i omega_i^2``,
``V = -sum m_i g . c_i``. ``test/test_dynamics.py`` checks ``M`` and ``b`` against finite
differences of this ``T`` and ``V`` computed from ``test/chains.py``.
"""

from __future__ import annotations

import numpy as np

from oracle.kinematics import Kinematics, forward_kinematics, point_motion
from vjm_ros.core.model import Model


def chain_efforts(model: Model, kin: Kinematics, com, chain, qd, qdd, gravity) -> dict[int, float]:
    """Joint efforts of one chain that give ``qdd`` at the pose of ``kin`` moving at ``qd``.

    Parameters
    ----------
    model : Model
    kin : Kinematics
        Frames of the configuration (only positions and angles are read).
    com : sequence of (float, float)
        Mass centres by link, m.
    chain : Chain
    qd, qdd : sequence of float, length n
        Rates and accelerations (only the chain's entries are read).
    gravity : (float, float)
        m/s^2.

    Returns
    -------
    dict
        Link (= joint) index to its effort, N m (revolute) or N (prismatic).
    """
    spin = accel = 0.0  # the ground link is at rest
    px, py = (float(c) for c in chain.origin)
    ax = ay = 0.0
    motion = []
    for i in chain.links:
        ox, oy = kin.origin_xy[i]
        nx, ny = kin.normal_xy[i]
        dx, dy = ox - px, oy - py
        rate, rate2 = (0.0, 0.0) if kin.revolute[i] else (qd[i], qdd[i])
        # a_O += alpha_pred e_z x d - omega_pred^2 d + 2 omega_pred Bd e_z x n + Bdd n
        ax += -accel * dy - spin * spin * dx - 2.0 * spin * rate * ny + rate2 * nx
        ay += accel * dx - spin * spin * dy + 2.0 * spin * rate * nx + rate2 * ny
        if kin.revolute[i]:
            spin, accel = spin + qd[i], accel + qdd[i]
        rx, ry = com[i][0] - ox, com[i][1] - oy
        acx = ax - accel * ry - spin * spin * rx  # a_c = a_O + alpha e_z x r - omega^2 r
        acy = ay + accel * rx - spin * spin * ry
        motion.append((i, accel, acx, acy))
        px, py = ox, oy
    gx, gy = gravity
    fx = fy = moment = 0.0
    next_origin = None  # O_(i+1), where the successor's joint acts
    efforts = {}
    for i, alpha, acx, acy in reversed(motion):
        link = model.links[i]
        cx, cy = com[i]
        ox, oy = kin.origin_xy[i]
        outer_x, outer_y = fx, fy  # the successor's joint force on the successor
        # F_i = m (a_c - g) + F_(i+1); N_i = I alpha + N_(i+1) + r x F_i + (O_(i+1) - c) x F_(i+1)
        fx, fy = link.mass * (acx - gx) + outer_x, link.mass * (acy - gy) + outer_y
        moment = link.inertia * alpha + moment + (cx - ox) * fy - (cy - oy) * fx
        if next_origin is not None:
            moment += (next_origin[0] - cx) * outer_y - (next_origin[1] - cy) * outer_x
        nx, ny = kin.normal_xy[i]
        efforts[i] = moment if kin.revolute[i] else fx * nx + fy * ny
        next_origin = (ox, oy)
    return efforts


def newton_euler(model: Model, kin: Kinematics, com, qd, qdd, gravity) -> np.ndarray:
    """:func:`chain_efforts` of every chain, shape (n,): the efforts for ``qdd``."""
    tau = np.zeros(len(model.links))
    qd, qdd = [float(x) for x in qd], [float(x) for x in qdd]
    com = [(float(x), float(y)) for x, y in com]
    gravity = (float(gravity[0]), float(gravity[1]))
    for chain in model.chains:
        for i, effort in chain_efforts(model, kin, com, chain, qd, qdd, gravity).items():
            tau[i] = effort
    return tau


class DynamicsTerms:
    """Everything the equations of motion need at one state.

    Parameters
    ----------
    model : Model
    q, qd : ndarray, shape (n,)

    Attributes
    ----------
    kin : Kinematics
    mass_matrix : ndarray, shape (n, n)
        ``M``: kg, kg m, kg m^2 by coordinate pair.
    bias : ndarray, shape (n,)
        ``b(q, qd)`` with ``M qdd + b = tau``, N m or N.
    com, com_velocity : ndarray, shape (n, 2)
        Mass centres (m) and their velocities (m/s).
    """

    def __init__(self, model: Model, q: np.ndarray, qd: np.ndarray):
        self.model = model
        self.kin = forward_kinematics(model, q, qd)
        count = len(model.links)
        local = np.array([link.com for link in model.links], dtype=float).reshape(count, 2)
        self.com, self.com_velocity, _ = point_motion(self.kin, np.arange(count), local)
        self.bias = newton_euler(model, self.kin, self.com, self.kin.qd, np.zeros(count),
                                 model.gravity)
        # column k: the efforts of a unit qdd_k from rest without gravity; chains do not push
        # one another (closures act through forces only), so only k's chain has entries
        self.mass_matrix = np.zeros((count, count))
        com = [(float(x), float(y)) for x, y in self.com]
        still = [0.0] * count
        for chain in model.chains:
            for k in chain.links:
                unit = [0.0] * count
                unit[k] = 1.0
                for i, effort in chain_efforts(model, self.kin, com, chain, still, unit,
                                               (0.0, 0.0)).items():
                    self.mass_matrix[i, k] = effort

    def energies(self) -> tuple[float, float]:
        """Kinetic and gravitational energy ``(T, V)``, J."""
        kinetic = potential = 0.0
        for i, link in enumerate(self.model.links):
            v = self.com_velocity[i]
            kinetic += 0.5 * link.mass * float(v @ v) + 0.5 * link.inertia * self.kin.omega[i] ** 2
            potential -= link.mass * float(self.model.gravity @ self.com[i])
        return kinetic, potential


def dynamics_terms(model: Model, q: np.ndarray, qd: np.ndarray) -> DynamicsTerms:
    """:class:`DynamicsTerms` at ``(q, qd)``."""
    return DynamicsTerms(model, q, qd)


def mass_matrix(model: Model, q: np.ndarray) -> np.ndarray:
    """Joint-space inertia matrix ``M(q)``, shape (n, n) (kg, kg m, kg m^2 by coordinate pair)."""
    return DynamicsTerms(model, q, np.zeros(model.n)).mass_matrix


def bias_forces(model: Model, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Coriolis, centrifugal and gravity terms ``b(q, qd)`` (``M qdd + b = tau``), shape (n,)."""
    return DynamicsTerms(model, q, qd).bias


def forward_dynamics(model: Model, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Accelerations of the open chains (no closures) under joint efforts.

    Parameters
    ----------
    model : Model
    q, qd : ndarray, shape (n,)
    tau : ndarray, shape (n,)
        N m (revolute) or N (prismatic).

    Returns
    -------
    ndarray, shape (n,)
        ``M^-1 (tau - b)`` by a Cholesky factor of ``M``.
    """
    terms = DynamicsTerms(model, q, qd)
    return MassFactor(terms.mass_matrix).solve(tau - terms.bias)


def inverse_dynamics(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """Efforts that produce ``qdd`` on the open chains: one Newton-Euler pass, shape (n,)."""
    terms = DynamicsTerms(model, q, qd)
    return newton_euler(model, terms.kin, terms.com, terms.kin.qd, np.asarray(qdd, dtype=float),
                        model.gravity)


def kinetic_energy(model: Model, q: np.ndarray, qd: np.ndarray) -> float:
    """``T = sum 1/2 m |v_c|^2 + 1/2 I omega^2``, J."""
    return DynamicsTerms(model, q, qd).energies()[0]


def potential_energy(model: Model, q: np.ndarray) -> float:
    """Gravitational ``V = -sum m g . c``, J."""
    return DynamicsTerms(model, q, np.zeros(model.n)).energies()[1]


class MassFactor:
    """The Cholesky factor ``M = L L^T`` of a mass matrix and the solves it gives.

    The triangular solves go through LAPACK's ``dgesv`` (faster here than scipy's triangular
    solver for these small matrices; on a triangular matrix it is as accurate).

    Parameters
    ----------
    mass_matrix : ndarray, shape (n, n)
        Symmetric positive definite.

    Raises
    ------
    numpy.linalg.LinAlgError
        When ``M`` is not positive definite (a massless chain makes it singular).
    """

    def __init__(self, mass_matrix: np.ndarray):
        self.lower = np.linalg.cholesky(mass_matrix)

    def half_solve(self, rhs: np.ndarray) -> np.ndarray:
        """``L^-1 rhs`` for ``rhs`` of shape (n,) or (n, m)."""
        return np.linalg.solve(self.lower, rhs)

    def half_solve_transposed(self, rhs: np.ndarray) -> np.ndarray:
        """``L^-T rhs``."""
        return np.linalg.solve(self.lower.T, rhs)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``M^-1 rhs``."""
        return self.half_solve_transposed(self.half_solve(rhs))
