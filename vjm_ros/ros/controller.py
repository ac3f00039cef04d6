"""``vjm_pd_controller``: an example controller for ``vjm_sim_node``, and a template for yours.

It drives the tip (the pin) of the ``five_bar`` scene around a circle with the two base actuators,
talking to the simulator only through topics, as a controller on real hardware would::

    /joint_states  (sensor_msgs/JointState)  ──>  controller  ──>  /vjm_sim_node/effort_commands
                                                                   (std_msgs/Float64MultiArray)

Run it next to the simulator (or use ``launch/sim.launch.py``)::

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST vjm_sim_node --ros-args -p scene:=five_bar \
        -p wait_for_command:=true &
    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST vjm_pd_controller

``wait_for_command`` keeps the five-bar in its start pose until the controller's first command
arrives: from that pose (both chains stretched, an unstable equilibrium) the mechanism falls
within a second, and discovery between two freshly started processes can take that long.

The control law is joint-space PD with gravity compensation on the actuated joints,

    tau = G(q) + Kp (q_d - q) + Kd (qd_d - qd),

where

* ``q_d(t)``, ``qd_d(t)``: the desired joint motion, from the five-bar's inverse kinematics of a
  tip circle (after a smooth approach from wherever the mechanism starts);
* ``G(q)``: the actuator efforts that hold the mechanism still at ``q`` against gravity, from
  vjm_ros's model of the closed mechanism (open-chain gravity terms balanced by the actuators and
  an exact pin force: the static equilibrium ``S tau + A^T lambda = g(q)``).

The controller answers every joint state with one command, so it also works with the simulator
in lockstep mode (``-p lockstep:=true``: every tick waits for the controller's answer).

To write your own controller, keep the node part (:class:`PdControllerNode`) and replace
:class:`PdGravityLaw` with your law: it receives the time and the joint state in the scene's
joint order and returns one effort per actuator in the scene's actuator order.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from vjm_ros.core.compiled import make_mechanism
from vjm_ros.core.constraints import ExactClosure
from vjm_ros.core.model import HINGE, Model
from vjm_ros.core.readers import forward_kinematics
from vjm_ros.ros.controller_base import ControllerNode
from vjm_ros.ros.conversions import joint_arrays, seconds
from vjm_ros.ros.runtime import run_node_until_signal
from vjm_ros.scene.loader import load_scene

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.parameter import Parameter

# ---------------------------------------------------------------------------------------------
# 1. Geometry: inverse kinematics of a five-bar (two two-link revolute chains sharing a tip pin)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FiveBarGeometry:
    """What the inverse kinematics needs to know about the mechanism.

    Attributes
    ----------
    bases : ndarray, shape (2, 2)
        Base joint position of each chain, m.
    ground_angles : ndarray, shape (2,)
        Ground angle ``theta1`` of each chain, rad (the base joint angle is measured from it).
    proximal, distal : ndarray, shape (2,)
        Link lengths of each chain, m.
    base_joints, elbow_joints : tuple of int
        Joint (coordinate) index of each chain's base and elbow.
    elbow_side : ndarray, shape (2,)
        +1 or -1 per chain: which of the two inverse kinematics solutions (elbow to the left or
        to the right of the base-to-tip line) is used.
    """

    bases: np.ndarray
    ground_angles: np.ndarray
    proximal: np.ndarray
    distal: np.ndarray
    base_joints: tuple[int, int]
    elbow_joints: tuple[int, int]
    elbow_side: np.ndarray

    @classmethod
    def from_model(cls, model: Model) -> FiveBarGeometry:
        """Read the geometry of a five-bar scene; the elbows point away from each other.

        Raises
        ------
        ValueError
            The scene is not two two-link revolute chains whose tips are pinned together.
        """
        chains = model.chains
        if len(chains) != 2 or any(len(c.links) != 2 for c in chains):
            raise ValueError(f"scene {model.name}: expected two chains of two links (a five-bar)")
        if not all(model.is_revolute) or any(model.locked_slide[c.links[1]] for c in chains):
            raise ValueError(f"scene {model.name}: expected revolute joints, each distal link "
                             "starting at the end of its proximal link")
        tips = {(c.links[1], (model.links[c.links[1]].length, 0.0)) for c in chains}
        pinned = any(
            cl.kind == HINGE
            and {(cl.point.link, tuple(cl.point.local)), (cl.target.link, tuple(cl.target.local))} == tips
            for cl in model.closures
        )
        if not pinned:
            raise ValueError(f"scene {model.name}: expected a hinge closure joining the two chain tips")
        kin = forward_kinematics(model, model.initial_state()[0])
        bases = np.array([kin.origin[c.links[0]] for c in chains])
        # Elbows out (for a pin above the bases): the left chain's elbow lies counter-clockwise
        # of its base-to-pin line, the right chain's clockwise.
        left_first = bases[0, 0] <= bases[1, 0]
        return cls(
            bases=bases,
            ground_angles=np.array([c.angle for c in chains]),
            proximal=np.array([model.length[c.links[0]] for c in chains]),
            distal=np.array([model.length[c.links[1]] for c in chains]),
            base_joints=(chains[0].links[0], chains[1].links[0]),
            elbow_joints=(chains[0].links[1], chains[1].links[1]),
            elbow_side=np.array([1.0, -1.0]) if left_first else np.array([-1.0, 1.0]),
        )

    def _proximal_angle(self, c: int, tip: np.ndarray, side: float) -> float:
        d = np.asarray(tip, dtype=float) - self.bases[c]
        r = float(np.hypot(*d))
        a, b = self.proximal[c], self.distal[c]
        # Law of cosines in the triangle base - elbow - tip; clipped at the workspace boundary.
        cos_beta = np.clip((a * a + r * r - b * b) / (2.0 * a * r), -1.0, 1.0)
        return math.atan2(d[1], d[0]) + side * math.acos(cos_beta)

    def inverse(self, tip: np.ndarray, near: np.ndarray) -> np.ndarray:
        """Joint coordinates that put the pin at ``tip``.

        Parameters
        ----------
        tip : ndarray, shape (2,)
            Pin position, m.
        near : ndarray, shape (n,)
            Joint coordinates (rad) whose angle windings the result keeps (no 2 pi jumps).

        Returns
        -------
        ndarray, shape (n,)
            A copy of ``near`` with the base and elbow angles of both chains solved, rad.
        """
        q = np.array(near, dtype=float)
        for c in range(2):
            theta_p = self._proximal_angle(c, tip, self.elbow_side[c])
            elbow = self.bases[c] + self.proximal[c] * _unit(theta_p)
            d = np.asarray(tip) - elbow
            theta_d = math.atan2(d[1], d[0])
            i, j = self.base_joints[c], self.elbow_joints[c]
            q[i] = _wrap_near(theta_p - self.ground_angles[c], q[i])
            q[j] = _wrap_near(theta_d - theta_p, q[j])
        return q


def _unit(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), math.sin(angle)])


def _wrap_near(angle: float, reference: float) -> float:
    """``angle`` plus the multiple of 2 pi that brings it closest to ``reference``."""
    return reference + (angle - reference + math.pi) % (2.0 * math.pi) - math.pi


# ---------------------------------------------------------------------------------------------
# 2. Desired motion: a smooth approach in joint space, then a circle of the tip
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CircleTrajectory:
    """Desired joint motion: approach the circle, then go round it counter-clockwise.

    Attributes
    ----------
    geometry : FiveBarGeometry
    q_start : ndarray, shape (n,)
        Joint coordinates when the motion starts, rad.
    center : ndarray, shape (2,)
        Circle centre, m.
    radius : float
        m.
    period : float
        Time for one turn, s.
    approach_time : float
        Time to move from ``q_start`` to the top of the circle (quintic blend in joint space,
        zero velocity and acceleration at both ends), s.
    """

    geometry: FiveBarGeometry
    q_start: np.ndarray
    center: np.ndarray
    radius: float
    period: float
    approach_time: float

    def tip(self, t: float) -> np.ndarray:
        """Desired pin position ``t`` seconds after the start (the top of the circle before the
        approach ends), m."""
        phase = math.pi / 2 + 2.0 * math.pi * max(t - self.approach_time, 0.0) / self.period
        return self.center + self.radius * _unit(phase)

    def joints(self, t: float) -> np.ndarray:
        """Desired joint coordinates at ``t``, rad, shape (n,)."""
        on_circle = self.geometry.inverse(self.tip(t), self.q_start)
        if t >= self.approach_time:
            return on_circle
        s = max(t, 0.0) / self.approach_time
        blend = s**3 * (10.0 - 15.0 * s + 6.0 * s * s)
        return self.q_start + blend * (on_circle - self.q_start)

    def desired(self, t: float, h: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
        """Desired joint coordinates (rad) and rates (rad/s, central difference over ``h``)."""
        return self.joints(t), (self.joints(t + h) - self.joints(t - h)) / (2.0 * h)


# ---------------------------------------------------------------------------------------------
# 3. The control law: PD on the actuated joints plus gravity compensation
# ---------------------------------------------------------------------------------------------


class PdGravityLaw:
    """``tau = G(q) + Kp (q_d - q) + Kd (qd_d - qd)`` on the actuated joints.

    Parameters
    ----------
    model : Model
        The scene (joint order, actuators, limits, masses).
    trajectory : CircleTrajectory
    kp : float
        Position gain, N m/rad.
    kd : float
        Velocity gain, N m s/rad.
    """

    def __init__(self, model: Model, trajectory: CircleTrajectory, kp: float, kd: float):
        self.model = model
        self.trajectory = trajectory
        self.kp, self.kd = float(kp), float(kd)
        self.actuated = [a.joint for a in model.actuators]
        self.selection = model.actuator_matrix()
        self.limits = np.array([a.limit for a in model.actuators])
        # The closed mechanism as vjm_ros models it (compiled when numba is installed).
        self.mechanism = make_mechanism(model, ExactClosure(), "auto")

    def gravity_efforts(self, q: np.ndarray) -> np.ndarray:
        """Actuator efforts that hold the mechanism at rest at ``q`` (N m).

        Static equilibrium of the closed mechanism: the open-chain gravity terms
        ``g(q) = b(q, 0)`` are carried by the actuators and the pin force ``lambda``:
        ``[S  A^T] [tau; lambda] = g(q)`` with ``S`` the actuator selection and ``A`` the closure
        Jacobian (least squares, so that a singular pose gives the smallest efforts).
        """
        rest = np.zeros(self.model.n)
        terms = self.mechanism.evaluate(q, rest, rest)  # the simulator's own equations
        g, a = terms.dyn.bias, terms.closure.jacobian
        x = np.linalg.lstsq(np.hstack((self.selection, a.T)), g, rcond=1e-10)[0]
        return x[: self.selection.shape[1]]

    def efforts(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Efforts for the actuators, N m, shape (n_actuators,), within the limits.

        Parameters
        ----------
        t : float
            Time since the motion started, s.
        q, qd : ndarray, shape (n,)
            Measured joint coordinates (rad) and rates (rad/s) in the scene's joint order.
        """
        q_d, qd_d = self.trajectory.desired(t)
        i = self.actuated
        tau = self.gravity_efforts(q) + self.kp * (q_d[i] - q[i]) + self.kd * (qd_d[i] - qd[i])
        return np.clip(tau, -self.limits, self.limits)


def make_law(model: Model, q_start: np.ndarray, center: tuple[float, float] = (0.7071, 0.5),
             radius: float = 0.1,
             period: float = 2.0, approach_time: float = 1.0, kp: float = 150.0,
             kd: float = 8.0) -> PdGravityLaw:
    """The example's control law for ``model`` starting at ``q_start`` (SI units)."""
    geometry = FiveBarGeometry.from_model(model)
    trajectory = CircleTrajectory(geometry, np.asarray(q_start, dtype=float),
                                  np.asarray(center, dtype=float), radius, period, approach_time)
    return PdGravityLaw(model, trajectory, kp, kd)


# ---------------------------------------------------------------------------------------------
# 4. The ROS node: joint states in, effort commands out (keep this part for your controller)
# ---------------------------------------------------------------------------------------------

class PdControllerNode(ControllerNode):
    """Subscribes ``joint_states``, publishes ``<simulator>/effort_commands``.

    Topic names are relative, so a namespace (``-r __ns:=/robot1``) or a remap places the
    controller beside its simulator.

    Parameters (ROS): ``scene`` (the scene the simulator runs, for the model), ``simulator`` (the
    simulator node's name), ``center_x``, ``center_y``, ``radius`` (m), ``period``,
    ``approach_time`` (s), ``kp`` (N m/rad), ``kd`` (N m s/rad).

    The motion starts at the first joint state received (its stamp is time zero) and starts over
    at the first state after the simulator announces a reset on ``<simulator>/events`` (its
    simulated time goes on across a reset).
    """

    def __init__(self, *, context: Context | None = None,
                 parameter_overrides: list[Parameter] | None = None) -> None:
        super().__init__("vjm_pd_controller", {
            "scene": "five_bar", "simulator": "vjm_sim_node", "center_x": 0.7071,
            "center_y": 0.5, "radius": 0.1, "period": 2.0, "approach_time": 1.0, "kp": 150.0,
            "kd": 8.0,
        }, context=context, parameter_overrides=parameter_overrides)
        p = self.params
        self.model = load_scene(p["scene"]).model
        FiveBarGeometry.from_model(self.model)  # refuse a scene that is not a five-bar, now
        self.law: PdGravityLaw | None = None
        self.t0 = 0.0
        self.last_t = -math.inf
        topic = self.connect(p["simulator"])
        self.get_logger().info(
            f"tracking a circle of radius {p['radius']} m around ({p['center_x']}, "
            f"{p['center_y']}) m every {p['period']} s; commands on {topic}")

    def on_joint_state(self, msg: JointState) -> None:
        """One command per joint state: the law at the state's time."""
        t = seconds(msg.header.stamp)
        try:
            q, qd, _ = joint_arrays(msg, self.model.joint_names)
        except KeyError:
            return  # joint states of another robot
        if self.law is None or self.restart or t < self.last_t:  # first state, or after a reset
            self.restart = False
            p = self.params
            self.law = make_law(self.model, q, (p["center_x"], p["center_y"]), p["radius"],
                                p["period"], p["approach_time"], p["kp"], p["kd"])
            self.t0 = t
        self.last_t = t
        tau = self.law.efforts(t - self.t0, q, qd)
        self.publisher.publish(Float64MultiArray(data=tau.tolist()))



def main(args: list[str] | None = None) -> int:
    """Console entry point ``vjm_pd_controller``; runs until SIGINT or SIGTERM (exit code 0)."""
    return run_node_until_signal(PdControllerNode, "vjm_pd_controller", args)


if __name__ == "__main__":
    sys.exit(main())
