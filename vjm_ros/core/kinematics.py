"""Link frames of a configuration, as the compiled kernel computes them, and what is read off them.

:class:`Kinematics` holds the kernel's link frames and rates
(:meth:`vjm_ros.core.mechanism.Mechanism.kinematics`, or the ``dyn.kin`` of an evaluation); the
functions here only read them: points given in link frames, the links as segments for drawing. The recursions themselves are in :func:`vjm_ros.core.terms.terms`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vjm_ros.core.model import Model


@dataclass
class Kinematics:
    """Link frames and rates of a configuration (filled by the compiled kernel).

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


def point_positions(kin: Kinematics, links: np.ndarray, local: np.ndarray) -> np.ndarray:
    """World positions of points given in link frames.

    Parameters
    ----------
    kin : Kinematics
        From :meth:`vjm_ros.core.mechanism.Mechanism.kinematics` or an evaluation.
    links : ndarray of int, shape (m,)
        Link index of each point (``-1``: ground, then ``local`` is the world position).
    local : ndarray, shape (m, 2)
        ``(s, w)`` coordinates in the link frame, m.

    Returns
    -------
    ndarray, shape (m, 2)
    """
    return kin.origin[links] + np.einsum("mij,mj->mi", kin.rotation[links], local)


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

