"""Efforts of redundant actuators: the minimum-norm distribution, the preload, the limits.

With ``m`` actuators and ``d`` degrees of freedom, the efforts ``tau`` (m,) that give a motion
solve ``P tau = w`` with ``P = S^T B`` (d x m) and ``w = M_r udd + c_r + g_r`` (d,)
(:mod:`vjm_ros.control.closed_model`). For ``m > d`` the answer is the minimum ``W``-norm one,
``tau = W^-1 P^T (P W^-1 P^T)^-1 w``, plus any effort of the null space of ``P``: efforts that
the closures balance and that move nothing (antagonism, preload).

**The preload direction.** With one actuator more than degrees of freedom (``m = d + 1``, as
three_chain's 3 for 2) the null space of ``P`` is a line: the efforts ``tau`` that the closure
forces balance, ``B tau + A^T lambda = 0`` for some multipliers ``lambda``. That is the null space
of ``N = [A^T B]`` (n x (r + m), with ``r + m = n + 1``), whose direction is the *generalized
cross product* of the rows of ``N``: ``y_k = (-1)^(n+k) det(N without column k)``, the one
direction with ``det([N; y^T]) > 0`` (the determinant is ``sum_k y_k^2``). The preload direction
``z`` is the efforts' part of ``y`` (its last ``m`` components), scaled so that
``max_k |z_k| = 1`` (:func:`vjm_ros.control.compiled.preload_direction`). It is a polynomial in ``A`` and ``B``, functions
of the pose alone, so it changes continuously along a motion wherever the actuators can balance
every load (``N`` of full rank), and it does not depend on the choice of independent
coordinates: a given ``preload`` means the same antagonism everywhere. (An SVD's null vector
has an arbitrary sign, which flipped 8 times in 5 s of three_chain's fall; so does the cross
product of the rows of ``P`` alone, :func:`null_direction`, whose sign follows that of
``det(A_v)`` and reverses where the motion passes a pose at which the independent coordinates
do not determine the others.)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from vjm_ros.control.arguments import number_array, real, vector
from vjm_ros.control.errors import InfeasibleEffortsError
from vjm_ros.core.errors import ConfigurationError

LIMIT_SLACK = 1e-12
"""Relative slack on the actuators' limits: an effort within ``limit * (1 + LIMIT_SLACK)`` is
within (round-off of the distribution's solve)."""


def null_direction(p: np.ndarray) -> np.ndarray:
    """The null-space direction of ``P`` alone: the generalized cross product of its rows.

    ``z_k = (-1)^(d+k) det(P without column k)``, scaled to ``max |z_k| = 1``: ``P z = 0`` and
    ``det([P; z^T]) > 0``. Its orientation is relative to ``P``, which depends on the independent
    coordinates: along a motion it reverses with the sign of ``det(A_v)`` (module docstring).
    :func:`vjm_ros.control.compiled.preload_direction` is the one continuous along a motion.

    Parameters
    ----------
    p : ndarray, shape (d, d + 1)
        ``P = S^T B`` with full row rank.

    Returns
    -------
    ndarray, shape (d + 1,)
        Dimensionless.
    """
    d, m = p.shape
    check_one_null_dimension(d, m)
    z = np.array([(-1.0) ** (d + k) * np.linalg.det(np.delete(p, k, axis=1))
                  for k in range(m)])
    return z / np.max(np.abs(z))


def check_one_null_dimension(d: int, m: int) -> None:
    """Refuse ``m`` actuators for ``d`` degrees of freedom unless ``m = d + 1``."""
    if m != d + 1:
        raise ConfigurationError(
            f"preload: expected one actuator more than degrees of freedom (a one-dimensional "
            f"null space), found {m} actuators for {d} degrees of freedom")


def check_preload(preload: float, d: int, m: int, scene: str = "the mechanism") -> None:
    """Refuse a nonzero ``preload`` where it has no single direction.

    Raises
    ------
    ConfigurationError
        ``m <= d`` (no effort moves nothing) or ``m > d + 1`` (a null space of more than one
        dimension, in which one number does not choose a direction).
    """
    if preload == 0.0 or m == d + 1:
        return
    if m <= d:
        raise ConfigurationError(
            f"preload: expected redundant actuation (more actuators than degrees of freedom), "
            f"found {m} actuators for {d} degrees of freedom in {scene}: no effort is left "
            f"that moves nothing; pass preload=0")
    raise ConfigurationError(
        f"preload: expected one actuator more than degrees of freedom, found {m} actuators for "
        f"{d} degrees of freedom in {scene}: one number does not choose a direction in a "
        f"{m - d}-dimensional null space")


def inverse_weights(weights: object, m: int) -> np.ndarray:
    """``W^-1`` from ``m`` positive finite effort weights, shape (m,).

    Raises
    ------
    ArgumentTypeError
        Not numbers.
    ConfigurationError
        Another count, or weights that are not positive and finite.
    """
    what = f"{m} positive finite numbers"
    wts = number_array(weights, "weights", what)
    if wts.shape != (m,) or not np.all((wts > 0) & np.isfinite(wts)):
        raise ConfigurationError(f"weights: expected {what}, found {wts.tolist()}")
    return 1.0 / wts


def distribute(p: np.ndarray, w: np.ndarray, limits: np.ndarray,
               weights: ArrayLike | None = None,
               preload: float = 0.0, names: Sequence[str] | None = None,
               direction: np.ndarray | None = None) -> np.ndarray:
    """Efforts ``tau`` with ``P tau = w``: minimum ``W``-norm, plus a preload, within limits.

    Parameters
    ----------
    p : ndarray, shape (d, m)
    w : ndarray, shape (d,)
    limits : ndarray, shape (m,)
        Largest ``|tau_i|``, N m or N.
    weights : array_like, shape (m,), optional
        Positive finite weights ``W`` (default: ones).
    preload : float
        Largest component of the added null-space effort ``preload * z``, N m or N; needs
        ``m = d + 1`` when nonzero.
    names : sequence of str, optional
        The actuators' joint names, for the messages (default ``actuator 0``, ...).
    direction : ndarray, shape (m,), optional
        ``z``: pass :attr:`ReducedDynamics.preload_direction
        <vjm_ros.control.closed_model.ReducedDynamics>`, the
        orientation continuous along a motion; default :func:`null_direction` of ``P``, whose
        orientation is relative to ``P`` only.

    Returns
    -------
    ndarray, shape (m,)
        N m or N. Where ``tau`` with the preload exceeds a limit, a point of the null space
        within every limit is returned instead (if one exists).

    Raises
    ------
    InfeasibleEffortsError
        ``w`` cannot be produced within the limits (or ``P`` has not full row rank).
    ConfigurationError
        Bad weights, or a preload without a single null-space direction.
    """
    d, m = p.shape
    winv = np.ones(m) if weights is None else inverse_weights(weights, m)
    preload = real(preload, "preload", "N m or N")
    check_preload(preload, d, m)
    names = [f"actuator {k}" for k in range(m)] if names is None else list(names)
    g = (p * winv) @ p.T
    if np.linalg.matrix_rank(g) < d:
        raise InfeasibleEffortsError(
            "the actuators cannot produce every motion at this pose (S^T B has not full rank)")
    tau = winv * (p.T @ np.linalg.solve(g, w))
    if preload:
        z = null_direction(p) if direction is None else vector(direction, m, "direction")
        tau = tau + preload * z
    if np.all(np.abs(tau) <= limits * (1 + LIMIT_SLACK)):
        return tau
    if m > d:  # move along the null space into the box, if the box is reachable
        from scipy.optimize import linprog

        null = np.eye(m) - (winv[:, None] * p.T) @ np.linalg.solve(g, p)
        basis = np.linalg.svd(null)[0][:, : m - d]
        res = linprog(np.zeros(m - d), A_ub=np.vstack((basis, -basis)),
                      b_ub=np.concatenate((limits - tau, limits + tau)),
                      bounds=[(None, None)] * (m - d), method="highs")
        if res.status == 0:
            return tau + basis @ res.x
    worst = int(np.argmax(np.abs(tau) / limits))
    raise InfeasibleEffortsError(
        f"efforts beyond the limits: {names[worst]} needs {tau[worst]:.4g} against a limit of "
        f"{limits[worst]:g} (no distribution within the limits gives this motion)",
        actuator=names[worst], needed=float(tau[worst]), limit=float(limits[worst]))
