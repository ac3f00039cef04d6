"""The closed-chain reduction, compiled, and joint-space inverse dynamics for controllers at 1 kHz.

:func:`velocity_map` forms ``S`` and ``s`` (``qd = S ud``, ``qdd = S udd + s``) from the closure
rows: the one definition of the reduction, which :mod:`vjm_ros.control.closed_model` calls too.
One evaluation by the simulator's compiled kernel (:func:`vjm_ros.core.kernels.evaluate`) fills
``M``, ``b``, ``A``, ``Adot qd``, ``C`` and ``A qd`` into a workspace of its own; one compiled
function (:func:`reduced_inverse_dynamics`) forms ``S``, ``s``, ``w = S^T (M (S udd + s) + b)``,
``P = S^T B``, the minimum ``W``-norm efforts and the preload along the oriented null-space
direction of ``P`` (the generalized cross product of its rows,
:mod:`vjm_ros.control.distribution`). The algebra is that of
:mod:`vjm_ros.control.closed_model` (checked equal to round-off in the tests), without Python-level
array operations: the cost is the two calls' entry overhead plus a few microseconds of arithmetic.
"""

from __future__ import annotations

import numpy as np

from vjm_ros.core import kernels as K
from vjm_ros.core import layout
from vjm_ros.core.constraints import ExactClosure
from vjm_ros.core.model import Model
from vjm_ros.jit import jit

OK, OFF_CLOSURES, SINGULAR, UNDERACTUATED, NONFINITE, BEYOND_LIMITS, OFF_VELOCITIES = range(7)
"""Status codes of :func:`reduced_inverse_dynamics`."""


@jit
def velocity_map(jac: np.ndarray, adot_qd: np.ndarray, independent: np.ndarray,
                 dependent: np.ndarray, singular_tolerance: float, s_map: np.ndarray,
                 s_bias: np.ndarray) -> float:
    """``S`` and ``s`` of the closed chain at one state; the smallest singular value of ``A_v``.

    With ``A = [A_u A_v]`` (columns ``independent`` and ``dependent``): ``S = [I; -A_v^-1 A_u]``
    (``A S = 0``) and ``s = [0; -A_v^-1 (Adot qd)]``, so that ``qd = S ud`` and
    ``qdd = S udd + s``.

    Parameters
    ----------
    jac : ndarray, shape (r, n)
        ``A``.
    adot_qd : ndarray, shape (r,)
        ``Adot qd``, m/s^2 or rad/s^2.
    independent : ndarray of int64, shape (d,)
    dependent : ndarray of int64, shape (r,)
        Coordinate indices, ``d + r = n``.
    singular_tolerance : float
        Below this smallest singular value of ``A_v`` (m per unit coordinate) nothing is solved.
    s_map : ndarray, shape (n, d)
        Receives ``S`` (its dependent rows only where ``A_v`` is regular).
    s_bias : ndarray, shape (n,)
        Receives ``s`` (likewise).

    Returns
    -------
    float
        The smallest singular value of ``A_v`` (``inf`` without closures).
    """
    d = independent.shape[0]
    r = dependent.shape[0]
    s_map[:, :] = 0.0
    s_bias[:] = 0.0
    for j in range(d):
        s_map[independent[j], j] = 1.0
    if r == 0:
        return np.inf
    a_v = np.empty((r, r))
    rhs = np.empty((r, d + 1))
    for i in range(r):
        for j in range(r):
            a_v[i, j] = jac[i, dependent[j]]
        for j in range(d):
            rhs[i, j] = jac[i, independent[j]]
        rhs[i, d] = adot_qd[i]
    smallest = np.linalg.svd(a_v)[1][r - 1]
    if smallest < singular_tolerance:
        return smallest
    x = np.linalg.solve(a_v, rhs)
    for i in range(r):
        for j in range(d):
            s_map[dependent[i], j] = -x[i, j]
        s_bias[dependent[i]] = -x[i, d]
    return smallest


@jit
def reduced_inverse_dynamics(mm: np.ndarray, bias: np.ndarray, jac: np.ndarray,
                             crow: np.ndarray, independent: np.ndarray, dependent: np.ndarray,
                             actuated: np.ndarray, udd: np.ndarray, winv: np.ndarray,
                             limits: np.ndarray, closure_tolerance: float,
                             velocity_tolerance: float, singular_tolerance: float,
                             preload: float, tau: np.ndarray, p_out: np.ndarray,
                             w_out: np.ndarray, z_out: np.ndarray) -> int:
    """Minimum-norm efforts plus preload for independent accelerations ``udd``; a status code.

    ``mm`` (n, n), ``bias`` (n,), ``jac`` (r, n), ``crow`` (r, 7) come from the kernel's
    evaluation; ``independent`` (d,), ``dependent`` (r,), ``actuated`` (m,) are coordinate
    indices; ``winv`` (m,) the inverse weights, ``limits`` (m,) the largest efforts (N m or N),
    ``preload`` (N m or N) the largest component of the null-space effort added (nonzero only
    with ``m = d + 1``, checked by the caller). Writes ``tau`` (m,), ``p_out`` (d, m),
    ``w_out`` (d,) and, with a preload, its direction ``z_out`` (m,).
    """
    n = mm.shape[0]
    d = independent.shape[0]
    r = dependent.shape[0]
    m = actuated.shape[0]
    for i in range(r):
        if abs(crow[i, layout.R_RES]) > closure_tolerance:
            return OFF_CLOSURES
    for i in range(r):
        if abs(crow[i, layout.R_RATE]) > velocity_tolerance:
            return OFF_VELOCITIES
    s_map = np.empty((n, d))
    s_bias = np.empty(n)
    if velocity_map(jac, crow[:, layout.R_BIAS], independent, dependent, singular_tolerance, s_map,
                    s_bias) < singular_tolerance:
        return SINGULAR
    force = mm @ (s_map @ udd + s_bias) + bias
    w_out[:] = s_map.T @ force
    for k in range(m):
        p_out[:, k] = s_map[actuated[k], :]
    g = (p_out * winv) @ p_out.T
    if np.linalg.svd(g)[1][d - 1] < 1e-14 * max(1.0, np.abs(g).max()):
        return UNDERACTUATED
    tau[:] = winv * (p_out.T @ np.linalg.solve(g, w_out))
    if preload != 0.0:
        preload_direction(jac, actuated, z_out)
        for k in range(m):
            tau[k] += preload * z_out[k]
    for k in range(m):
        if abs(tau[k]) > limits[k]:
            return BEYOND_LIMITS
    return OK


@jit
def preload_direction(jac: np.ndarray, actuated: np.ndarray, z: np.ndarray) -> None:
    """Write into ``z`` (m,) the oriented direction of the efforts the closures balance.

    The efforts' part of the generalized cross product of the rows of ``N = [A^T B]``
    (n x (n + 1); ``A = jac`` (r, n), ``B`` selects the ``actuated`` coordinates (m,), with
    ``r + m = n + 1``): ``z_k = (-1)^(n+r+k) det(N without column r + k)``, scaled to
    ``max |z_k| = 1`` (:mod:`vjm_ros.control.distribution` says why this orientation).
    """
    r, n = jac.shape
    m = actuated.shape[0]
    minor = np.zeros((n, n))
    largest = 0.0
    for k in range(m):
        minor[:, :] = 0.0
        for i in range(n):
            for j in range(r):
                minor[i, j] = jac[j, i]
        c = r
        for j in range(m):
            if j != k:
                minor[actuated[j], c] = 1.0
                c += 1
        z[k] = np.linalg.det(minor) if (n + r + k) % 2 == 0 else -np.linalg.det(minor)
        largest = max(largest, abs(z[k]))
    for k in range(m):
        z[k] /= largest


class CompiledInverseDynamics:
    """A workspace of the kernel and index arrays of one model (one per controller).

    Parameters
    ----------
    model : Model
    independent : list of int
        Independent coordinates (see :class:`~vjm_ros.control.ClosedChainModel`).
    """

    def __init__(self, model: Model, independent: list[int]) -> None:
        from vjm_ros.core.mechanism import Mechanism

        self.mech = Mechanism(model, ExactClosure(alpha=0.0, beta=0.0))
        n, self.n = model.n, model.n
        self.model = self.mech.packed
        self.data = self.mech.new_data()
        self.independent = np.array(independent, dtype=np.int64)
        self.dependent = np.array([i for i in range(n) if i not in independent], dtype=np.int64)
        self.actuated = np.array([a.joint for a in model.actuators], dtype=np.int64)
        m, d = len(self.actuated), len(independent)
        self.ones, self.unlimited = np.ones(m), np.full(m, np.inf)
        self.zeros = np.zeros(n)
        self.qdd = np.empty(n)
        self.tau, self.p, self.w = np.empty(m), np.empty((d, m)), np.empty(d)
        self.direction = np.empty(m)

    def __call__(self, q: np.ndarray, qd: np.ndarray, udd: np.ndarray, winv: np.ndarray,
                 limits: np.ndarray, closure_tolerance: float, velocity_tolerance: float,
                 singular_tolerance: float, preload: float) -> int:
        """Evaluate the model at ``(q, qd)`` and the efforts for ``udd``; a status code."""
        if not _finite(q, qd, udd):
            return NONFINITE
        data = self.data
        if K.evaluate(self.model, data, q, qd, self.zeros, self.qdd):
            return SINGULAR
        return reduced_inverse_dynamics(data.mm, data.bias, data.jac, data.crow, self.independent,
                                        self.dependent,
                                        self.actuated, udd, winv, limits, closure_tolerance,
                                        velocity_tolerance, singular_tolerance, preload,
                                        self.tau, self.p, self.w, self.direction)


@jit
def _finite(q, qd, udd):
    for x in (q, qd):
        for i in range(x.shape[0]):
            if not np.isfinite(x[i]):
                return False
    for i in range(udd.shape[0]):
        if not np.isfinite(udd[i]):
            return False
    return True
