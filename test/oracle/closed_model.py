"""Oracle: the closed-chain reduced dynamics of :mod:`vjm_ros.control.closed_model` in numpy.

The same algebra (``S``, ``s``, ``M_r``, ``c_r``, ``g_r``, ``P = S^T B``, the point Jacobian and
bias) formed from the oracle's own kinematics, dynamics and closure rows instead of the compiled
kernels, so that the package's controller model can be compared with it.
"""

from __future__ import annotations

import numpy as np

from oracle.constraints import ClosureSet
from oracle.dynamics import dynamics_terms
from oracle.kinematics import forward_kinematics, point_jacobians, point_motion
from vjm_ros.core.model import Model


def velocity_maps(model: Model, independent: list[int], q: np.ndarray, qd: np.ndarray):
    """``S`` (n, d) and ``s`` (n,): ``qd = S ud`` and ``qdd = S udd + s`` on the closures."""
    n = model.n
    dependent = [i for i in range(n) if i not in independent]
    terms = ClosureSet(model).evaluate(forward_kinematics(model, q, qd))
    a = terms.jacobian
    d = len(independent)
    s_map = np.zeros((n, d))
    s_map[independent, np.arange(d)] = 1.0
    bias = np.zeros(n)
    if dependent:
        solve = np.linalg.solve(a[:, dependent], np.column_stack((a[:, independent], terms.bias)))
        s_map[dependent] = -solve[:, :d]
        bias[dependent] = -solve[:, d]
    return s_map, bias


def reduced_dynamics(model: Model, independent: list[int], q: np.ndarray, qd: np.ndarray):
    """``(M_r, c_r, g_r, S, s, P)`` at a state (module docstring of the package's model)."""
    s_map, s = velocity_maps(model, independent, q, qd)
    full = dynamics_terms(model, q, qd)
    still = dynamics_terms(model, q, np.zeros(model.n))
    m_r = s_map.T @ full.mass_matrix @ s_map
    g_r = s_map.T @ still.bias
    c_r = s_map.T @ (full.mass_matrix @ s + full.bias - still.bias)
    return m_r, c_r, g_r, s_map, s, s_map.T @ model.actuator_matrix()


def point_terms(model: Model, link: int, local, q: np.ndarray, qd: np.ndarray):
    """Position (2,), ``Jdot qd`` (2,) and Jacobian ``dP/dq`` (2, n) of a point of a link."""
    kin = forward_kinematics(model, q, qd)
    links, loc = np.array([link]), np.array([local], dtype=float)
    p, _, a_bias = point_motion(kin, links, loc)
    return p[0], a_bias[0], point_jacobians(model, kin, links, p)[0]
