"""Planar chain kinematics: link frames, point positions, velocities, Jacobians and ``Jdot qdot``.

All chains of a scene are handled at once. With ``A`` the ancestor matrix of the model
(``A[i, k] = 1`` when joint ``k`` moves link ``i``), the recursions of the chain become sums:

* ``theta_pred = theta1 + A_strict @ phi`` and ``theta = theta_pred + phi``;
* ``O = O_base + A @ d`` with ``d_k = a_pred u(theta_pred_k) + B_k n(theta_pred_k)``;
* rates and the velocity-product ("bias") accelerations follow by differentiating ``d_k``.

A point ``P`` on link ``i`` moves with joint ``k`` (``A[i, k] = 1``) as ``e_z x (P - O_k)`` for a
revolute joint (rotation about the joint's origin ``O_k``) and as ``n(theta_pred_k)`` for a
prismatic joint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vjm_ros.core.model import Model


@dataclass
class Kinematics:
    """Link frames and rates of a configuration.

    Every array has one extra trailing row that stands for the ground (index ``-1``), so that
    ground points can be handled by the same indexing as link points.

    Attributes
    ----------
    theta : ndarray, shape (n + 1,)
        Absolute link angles ``theta_i``, rad (ground row: 0).
    origin : ndarray, shape (n + 1, 2)
        Link origins ``O_i``, m (ground row: 0).
    omega : ndarray, shape (n + 1,)
        Absolute angular velocities, rad/s.
    v_origin : ndarray, shape (n + 1, 2)
        Origin velocities, m/s.
    a_origin : ndarray, shape (n + 1, 2)
        Origin accelerations at zero joint acceleration (``Jdot qdot``), m/s^2.
    n_pred : ndarray, shape (n, 2)
        ``n(theta_pred)``: slide direction of each joint.
    rotation : ndarray, shape (n + 1, 2, 2)
        Columns ``u(theta_i)``, ``n(theta_i)``.
    slide : ndarray, shape (n,)
        Slides ``B`` (active or locked), m.
    """

    theta: np.ndarray
    origin: np.ndarray
    omega: np.ndarray
    v_origin: np.ndarray
    a_origin: np.ndarray
    n_pred: np.ndarray
    rotation: np.ndarray
    slide: np.ndarray


def _cross_z(v: np.ndarray) -> np.ndarray:
    """``e_z x v`` for planar vectors ``v`` of shape (..., 2)."""
    out = np.empty_like(v)
    out[..., 0] = -v[..., 1]
    out[..., 1] = v[..., 0]
    return out


def forward_kinematics(model: Model, q: np.ndarray, qd: np.ndarray | None = None) -> Kinematics:
    """Link frames, rates and bias accelerations.

    Parameters
    ----------
    model : Model
    q : ndarray, shape (n,)
        Generalized coordinates (rad or m).
    qd : ndarray, shape (n,), optional
        Generalized rates; zero when omitted.

    Returns
    -------
    Kinematics
    """
    rev = model.is_revolute
    phi = np.where(rev, q, model.locked_angle)
    slide = np.where(rev, model.locked_slide, q)
    theta_pred = model.base_angle + model.strict_ancestors @ phi
    theta = theta_pred + phi
    cp, sp = np.cos(theta_pred), np.sin(theta_pred)
    u_pred = np.stack((cp, sp), axis=1)
    n_pred = np.stack((-sp, cp), axis=1)
    d = model.pred_length[:, None] * u_pred + slide[:, None] * n_pred
    n = model.n
    origin = np.zeros((n + 1, 2))
    origin[:n] = model.base_origin + model.ancestors @ d
    theta_ext = np.zeros(n + 1)
    theta_ext[:n] = theta
    c, s = np.cos(theta_ext), np.sin(theta_ext)
    rotation = np.empty((n + 1, 2, 2))
    rotation[:, 0, 0] = c
    rotation[:, 1, 0] = s
    rotation[:, 0, 1] = -s
    rotation[:, 1, 1] = c

    omega = np.zeros(n + 1)
    v_origin = np.zeros((n + 1, 2))
    a_origin = np.zeros((n + 1, 2))
    if qd is not None:
        phid = np.where(rev, qd, 0.0)
        slided = np.where(rev, 0.0, qd)
        omega_pred = model.strict_ancestors @ phid
        omega[:n] = omega_pred + phid
        dv = omega_pred[:, None] * _cross_z(d) + slided[:, None] * n_pred
        v_origin[:n] = model.ancestors @ dv
        da = -(omega_pred**2)[:, None] * d - (2.0 * omega_pred * slided)[:, None] * u_pred
        a_origin[:n] = model.ancestors @ da
    return Kinematics(theta_ext, origin, omega, v_origin, a_origin, n_pred, rotation, slide)


def point_positions(kin: Kinematics, links: np.ndarray, local: np.ndarray) -> np.ndarray:
    """World positions of points given in link frames.

    Parameters
    ----------
    kin : Kinematics
    links : ndarray of int, shape (m,)
        Link index of each point (``-1``: ground, then ``local`` is the world position).
    local : ndarray, shape (m, 2)
        ``(s, w)`` coordinates in the link frame, m.

    Returns
    -------
    ndarray, shape (m, 2)
    """
    return kin.origin[links] + np.einsum("mij,mj->mi", kin.rotation[links], local)


def point_motion(
    kin: Kinematics, links: np.ndarray, local: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities and bias accelerations (``Jdot qdot``) of link points.

    Parameters
    ----------
    kin : Kinematics
    links : ndarray of int, shape (m,)
    local : ndarray, shape (m, 2)

    Returns
    -------
    p, v, a_bias : ndarray, shape (m, 2)
        m, m/s, m/s^2.
    """
    r = np.einsum("mij,mj->mi", kin.rotation[links], local)
    w = kin.omega[links]
    p = kin.origin[links] + r
    v = kin.v_origin[links] + w[:, None] * _cross_z(r)
    a = kin.a_origin[links] - (w**2)[:, None] * r
    return p, v, a


def point_jacobians(model: Model, kin: Kinematics, links: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Translational Jacobians ``dP/dq`` of points attached to links.

    Parameters
    ----------
    model : Model
    kin : Kinematics
    links : ndarray of int, shape (m,)
        Link carrying each point (``-1``: ground, giving a zero Jacobian).
    p : ndarray, shape (m, 2)
        World positions of the points, m.

    Returns
    -------
    ndarray, shape (m, 2, n)
    """
    n = model.n
    mask = np.zeros((len(links), n))
    on_link = links >= 0
    mask[on_link] = model.ancestors[links[on_link]]
    arm = _cross_z(p[:, None, :] - kin.origin[None, :n, :])  # (m, n, 2)
    cols = np.where(model.is_revolute[None, :, None], arm, kin.n_pred[None, :, :])
    return np.transpose(cols * mask[:, :, None], (0, 2, 1))


def angular_jacobian(model: Model, links: np.ndarray) -> np.ndarray:
    """``d theta_i / dq`` for the given links.

    Parameters
    ----------
    model : Model
    links : ndarray of int, shape (m,)
        Link indices (``-1``: ground, zero row).

    Returns
    -------
    ndarray, shape (m, n)
    """
    out = np.zeros((len(links), model.n))
    on_link = links >= 0
    out[on_link] = model.ancestors[links[on_link]] * model.is_revolute[None, :]
    return out


def link_segments(model: Model, kin: Kinematics) -> np.ndarray:
    """Start and end point of every moving link, for drawing.

    Returns
    -------
    ndarray, shape (n, 2, 2)
        ``[i, 0]`` is ``O_i``, ``[i, 1]`` is ``O_i + a_i u(theta_i)``, m.
    """
    n = model.n
    start = kin.origin[:n]
    end = start + model.length[:, None] * kin.rotation[:n, :, 0]
    return np.stack((start, end), axis=1)


def base_segments(model: Model, kin: Kinematics) -> np.ndarray:
    """Ground link of each chain plus the slide offset of its first joint, for drawing.

    Returns
    -------
    ndarray, shape (n_chains, 2, 2)
        From the chain's ground point ``O`` to the first link's origin, m.
    """
    out = np.zeros((len(model.chains), 2, 2))
    for c, chain in enumerate(model.chains):
        out[c, 0] = chain.origin
        out[c, 1] = kin.origin[chain.links[0]] if chain.links else chain.origin
    return out
