"""Lagrangian dynamics of the open chains: ``M(q) qdd + b(q, qd) = tau``.

With ``J_i`` the Jacobian of the mass centre of link ``i`` and ``Jw_i`` that of its angle,

* ``M = sum_i m_i J_i^T J_i + I_i Jw_i^T Jw_i`` (the thesis's inertia matrix, existence factors
  applied by using only the active coordinates);
* ``b = sum_i J_i^T m_i (Jdot_i qdot - g)``: Coriolis/centrifugal and gravity terms (``Jw`` is
  constant in the plane, so rotation contributes no velocity-product term);
* ``T = 1/2 qd^T M qd``, ``V = -sum_i m_i g . c_i``.

These are Kane's equations for the chain, identical to the Euler-Lagrange equations of ``T - V``
(the test suite checks this against finite differences of the energies).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oracle.kinematics import Kinematics, forward_kinematics, point_jacobians, point_motion
from vjm_ros.core.model import Model


@dataclass
class DynamicsTerms:
    """Everything the equations of motion need at one state.

    Attributes
    ----------
    kin : Kinematics
    mass_matrix : ndarray, shape (n, n)
    bias : ndarray, shape (n,)
        ``b(q, qd)`` such that ``M qdd + b = tau``, N m or N.
    com : ndarray, shape (n, 2)
        Mass centres, m.
    com_velocity : ndarray, shape (n, 2)
        m/s.
    """

    kin: Kinematics
    mass_matrix: np.ndarray
    bias: np.ndarray
    com: np.ndarray
    com_velocity: np.ndarray


def dynamics_terms(model: Model, q: np.ndarray, qd: np.ndarray) -> DynamicsTerms:
    """Kinematics, mass matrix and bias forces in one pass.

    Parameters
    ----------
    model : Model
    q, qd : ndarray, shape (n,)

    Returns
    -------
    DynamicsTerms
    """
    kin = forward_kinematics(model, q, qd)
    links = np.arange(model.n)
    c, vc, ac = point_motion(kin, links, model.com)
    jc = point_jacobians(model, kin, links, c)
    jw = model.ancestors * model.is_revolute[None, :]
    m = model.mass
    mm = np.einsum("i,iak,ial->kl", m, jc, jc) + jw.T @ (model.inertia[:, None] * jw)
    bias = np.einsum("iak,ia->k", jc, m[:, None] * (ac - model.gravity[None, :]))
    return DynamicsTerms(kin, mm, bias, c, vc)


def mass_matrix(model: Model, q: np.ndarray) -> np.ndarray:
    """Joint-space inertia matrix ``M(q)``.

    Parameters
    ----------
    model : Model
        The mechanism.
    q : ndarray, shape (n,)
        Joint coordinates, rad or m.

    Returns
    -------
    ndarray, shape (n, n)
        Symmetric positive definite (kg, kg m, kg m^2 by coordinate pair).
    """
    return dynamics_terms(model, q, np.zeros(model.n)).mass_matrix


def bias_forces(model: Model, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Coriolis, centrifugal and gravity terms ``b(q, qd)`` (``M qdd + b = tau``).

    Returns
    -------
    ndarray, shape (n,)
    """
    return dynamics_terms(model, q, qd).bias


def forward_dynamics(model: Model, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Accelerations of the open chains (no closures) under joint efforts.

    Parameters
    ----------
    model : Model
    q, qd : ndarray, shape (n,)
    tau : ndarray, shape (n,)
        Generalized efforts, N m (revolute) or N (prismatic).

    Returns
    -------
    ndarray, shape (n,)
    """
    t = dynamics_terms(model, q, qd)
    return np.linalg.solve(t.mass_matrix, tau - t.bias)


def inverse_dynamics(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """Efforts that produce ``qdd`` on the open chains: ``M qdd + b``.

    Returns
    -------
    ndarray, shape (n,)
    """
    t = dynamics_terms(model, q, qd)
    return t.mass_matrix @ qdd + t.bias


def kinetic_energy(model: Model, q: np.ndarray, qd: np.ndarray) -> float:
    """``T = sum 1/2 m |v_c|^2 + 1/2 I omega^2``, J."""
    t = dynamics_terms(model, q, qd)
    return energy_from_terms(model, t, qd)[0]


def potential_energy(model: Model, q: np.ndarray) -> float:
    """Gravitational ``V = -sum m g . c``, J."""
    t = dynamics_terms(model, q, np.zeros(model.n))
    return energy_from_terms(model, t, np.zeros(model.n))[1]


def energy_from_terms(model: Model, terms: DynamicsTerms, qd: np.ndarray) -> tuple[float, float]:
    """Kinetic and potential energy from already computed terms.

    Returns
    -------
    tuple of float
        ``(T, V)``, J.
    """
    kinetic = 0.5 * float(
        np.sum(model.mass * np.sum(terms.com_velocity**2, axis=1))
        + np.sum(model.inertia * terms.kin.omega[: model.n] ** 2)
    )
    potential = -float(np.sum(model.mass * (terms.com @ model.gravity)))
    return kinetic, potential
