"""Oracle: planar chain kinematics, a loop along each chain plus the joint columns of a point.

Written from docs/design.md section 1 and the scene description alone (chains, links, joints);
it reads none of the index arrays ``Model.build`` derives. Along a chain, from its ground point
``O``, ground angle ``theta1`` and ground length ``a1``::

    O_i = O_pred + a_pred u(theta_pred) + B_i n(theta_pred),    theta_i = theta_pred + phi_i

with ``(phi_i, B_i) = (q_i, locked slide)`` for a revolute joint, ``(locked angle, q_i)`` for a
prismatic one. Motion is not propagated link to link; it is summed over the joints that carry a
point. A point ``P`` of link ``i`` is carried by the joints ``k`` from the first of its chain up
to ``i``, and joint ``k`` moves it along the column

* ``J_k = e_z x (P - O_k)`` (revolute: a turn about the joint's origin), or
* ``J_k = n(theta_pred_k)`` (prismatic: a slide along the preceding link's normal),

so ``v_P = sum_k J_k qd_k``. Its acceleration at ``qdd = 0`` (``Jdot qd``) is
``sum_k Jdot_k qd_k`` with the columns' rates ``Jdot_k = e_z x (v_P - v_{O_k})`` (revolute) and
``Jdot_k = -omega_pred_k u(theta_pred_k)`` (prismatic: the slide direction turns with the
preceding link). The link angle moves with every revolute joint in front of it
(``omega_i = sum phid_k``).
"""

from __future__ import annotations

import math

import numpy as np

from vjm_ros.core.model import GROUND, REVOLUTE, Model


class Kinematics:
    """Link frames and rates of one configuration, filled by the chain loop.

    The per-link arrays carry one trailing row for the ground (index ``-1``: angle 0, origin 0,
    at rest), so ground points index like link points.

    Parameters
    ----------
    model : Model
    q, qd : ndarray, shape (n,)
        Coordinates (rad or m) and rates (rad/s or m/s; ``None``: at rest).

    Attributes
    ----------
    theta, omega : ndarray, shape (n + 1,)
        Absolute link angles (rad) and their rates (rad/s).
    origin, v_origin, a_origin : ndarray, shape (n + 1, 2)
        Link origins ``O_i`` (m), their velocities (m/s) and accelerations at ``qdd = 0``
        (m/s^2).
    rotation : ndarray, shape (n + 1, 2, 2)
        Columns ``u(theta_i)`` and ``n(theta_i)``.
    n_pred : ndarray, shape (n, 2)
        ``n(theta_pred_i)``, the slide direction of joint ``i``.
    slide : ndarray, shape (n,)
        Slide ``B_i`` of every joint, active or locked, m.
    carriers : list of tuple of int
        For each link, the joints that move it, base first.
    origin_xy, normal_xy : list of (float, float)
        ``origin[:n]`` and ``n_pred`` as Python floats (for the scalar loops).
    revolute : list of bool
        Kind of each joint.
    qd : ndarray, shape (n,)
    """

    def __init__(self, model: Model, q: np.ndarray, qd: np.ndarray | None = None):
        count = len(model.links)
        self.qd = np.zeros(count) if qd is None else np.asarray(qd, dtype=float)
        rates = [float(x) for x in self.qd]
        self.revolute = [joint.kind == REVOLUTE for joint in model.joints]
        self.carriers: list[tuple[int, ...]] = [()] * count
        theta, slide, omega_pred = [0.0] * count, [0.0] * count, [0.0] * count
        origin, normal = [(0.0, 0.0)] * count, [(0.0, 1.0)] * count
        for chain in model.chains:
            x, y = (float(c) for c in chain.origin)
            angle, reach, spin = float(chain.angle), float(chain.length), 0.0
            carried: tuple[int, ...] = ()
            for i in chain.links:
                joint = model.joints[i]
                if self.revolute[i]:
                    turn, push = float(q[i]), joint.slide
                else:
                    turn, push = joint.angle, float(q[i])
                ux, uy = math.cos(angle), math.sin(angle)
                x, y = x + reach * ux - push * uy, y + reach * uy + push * ux
                normal[i], omega_pred[i], slide[i] = (-uy, ux), spin, push
                angle = angle + turn
                carried = carried + (i,)
                self.carriers[i] = carried
                origin[i], theta[i] = (x, y), angle
                if self.revolute[i]:
                    spin = spin + rates[i]
                reach = model.links[i].length
        self.origin_xy, self.normal_xy = origin, normal
        self._omega_pred, self._rates = omega_pred, rates
        self.theta = np.array(theta + [0.0])
        self.origin = np.array(origin + [(0.0, 0.0)]).reshape(count + 1, 2)
        self.n_pred = np.array(normal).reshape(count, 2)
        self.slide = np.array(slide)
        self.rotation = np.zeros((count + 1, 2, 2))
        self.rotation[:, 0, 0] = self.rotation[:, 1, 1] = np.cos(self.theta)
        self.rotation[:, 1, 0] = np.sin(self.theta)
        self.rotation[:, 0, 1] = -self.rotation[:, 1, 0]
        self.omega = np.array([sum(rates[k] for k in self.carriers[i] if self.revolute[k])
                               for i in range(count)] + [0.0])
        # origins' velocities first (the revolute columns' rates need them), then accelerations
        self._v_origin = [self._velocity(i, origin[i]) for i in range(count)]
        self.v_origin = np.array(self._v_origin + [(0.0, 0.0)]).reshape(count + 1, 2)
        accelerations = [self._bias(i, origin[i], self._v_origin[i]) for i in range(count)]
        self.a_origin = np.array(accelerations + [(0.0, 0.0)]).reshape(count + 1, 2)

    @property
    def n(self) -> int:
        """Number of coordinates."""
        return len(self.slide)

    def _columns(self, link: int, p):
        """``(k, (Jx, Jy))`` for every joint ``k`` that carries the point ``p`` of ``link``."""
        if link == GROUND:
            return []
        px, py = p
        out = []
        for k in self.carriers[link]:
            if self.revolute[k]:
                ox, oy = self.origin_xy[k]
                out.append((k, (oy - py, px - ox)))  # e_z x (P - O_k)
            else:
                out.append((k, self.normal_xy[k]))
        return out

    def _velocity(self, link: int, p) -> tuple[float, float]:
        vx = vy = 0.0
        for k, (jx, jy) in self._columns(link, p):
            vx, vy = vx + jx * self._rates[k], vy + jy * self._rates[k]
        return vx, vy

    def _bias(self, link: int, p, v) -> tuple[float, float]:
        ax = ay = 0.0
        if link == GROUND:
            return ax, ay
        for k in self.carriers[link]:
            if self.revolute[k]:
                wx, wy = v[0] - self._v_origin[k][0], v[1] - self._v_origin[k][1]
                rx, ry = -wy, wx  # e_z x (v_P - v_O_k)
            else:
                nx, ny = self.normal_xy[k]
                rx, ry = -self._omega_pred[k] * ny, self._omega_pred[k] * nx  # -w u = w e_z x n
            ax, ay = ax + rx * self._rates[k], ay + ry * self._rates[k]
        return ax, ay

    def jacobian(self, link: int, p) -> np.ndarray:
        """``dP/dq`` of the point ``p`` (m) fixed on ``link``, shape (2, n); zero for the ground."""
        out = np.zeros((2, self.n))
        for k, column in self._columns(link, p):
            out[:, k] = column
        return out

    def velocity(self, link: int, p) -> np.ndarray:
        """``J qd`` of the point ``p`` of ``link``, m/s."""
        return np.array(self._velocity(link, p))

    def bias_acceleration(self, link: int, p, v) -> np.ndarray:
        """``Jdot qd`` of the point ``p`` of ``link`` moving at ``v`` (m/s), m/s^2."""
        return np.array(self._bias(link, p, v))

    def angle_jacobian(self, link: int) -> np.ndarray:
        """``d theta_link / dq``, shape (n,): 1 at the revolute joints that carry the link."""
        out = np.zeros(self.n)
        if link != GROUND:
            for k in self.carriers[link]:
                out[k] = 1.0 if self.revolute[k] else 0.0
        return out

    def position(self, link: int, local) -> np.ndarray:
        """World position of ``(s, w)`` in the frame of ``link`` (the ground: ``local`` itself)."""
        s, w = local
        if link == GROUND:
            return np.array((float(s), float(w)))
        c, sn = math.cos(self.theta[link]), math.sin(self.theta[link])
        ox, oy = self.origin_xy[link]
        return np.array((ox + c * s - sn * w, oy + sn * s + c * w))


def forward_kinematics(model: Model, q: np.ndarray, qd: np.ndarray | None = None) -> Kinematics:
    """:class:`Kinematics` of ``model`` at ``q`` moving at ``qd`` (at rest when omitted)."""
    return Kinematics(model, q, qd)


def point_positions(kin: Kinematics, links: np.ndarray, local: np.ndarray) -> np.ndarray:
    """World positions of points given in link frames.

    Parameters
    ----------
    kin : Kinematics
    links : ndarray of int, shape (m,)
        Link of each point (``-1``: ground, then ``local`` is the world position).
    local : ndarray, shape (m, 2)
        ``(s, w)`` in the link frame, m.

    Returns
    -------
    ndarray, shape (m, 2)
        m.
    """
    out = [kin.position(int(k), loc) for k, loc in zip(links, local, strict=True)]
    return np.array(out).reshape(-1, 2)


def point_motion(
    kin: Kinematics, links: np.ndarray, local: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities and bias accelerations (``Jdot qd``) of link points.

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
    p = point_positions(kin, links, local).reshape(-1, 2)
    v = np.array([kin.velocity(int(k), x) for k, x in zip(links, p, strict=True)]).reshape(-1, 2)
    a = np.array([kin.bias_acceleration(int(k), x, w) for k, x, w in zip(links, p, v, strict=True)])
    return p, v, a.reshape(-1, 2)


def point_jacobians(model: Model, kin: Kinematics, links: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Translational Jacobians ``dP/dq`` of points fixed on links.

    Parameters
    ----------
    model : Model
    kin : Kinematics
    links : ndarray of int, shape (m,)
        Link of each point (``-1``: ground, a zero Jacobian).
    p : ndarray, shape (m, 2)
        World positions, m.

    Returns
    -------
    ndarray, shape (m, 2, n)
    """
    return np.array([kin.jacobian(int(k), x) for k, x in zip(links, p, strict=True)]).reshape(
        len(links), 2, model.n
    )
