"""``vjm_ct_controller``: task-space computed torque for closed chains, redundant ones included.

It drives a named point (default: the scene's first, a chain tip) along a circle or a
figure-eight that starts where the point is, with feed-forward and PD in task space::

    xdd_cmd = xdd_d + kd (xd_d - xd) + kp (x_d - x)
    tau     = inverse_dynamics(q, qd, point, xdd_cmd)         (vjm_ros.control)

With more actuators than degrees of freedom (three_chain: 3 for 2) the efforts are the
minimum-norm distribution, plus an optional antagonistic ``preload``. The model comes from the
simulator's ``<simulator>/scene_description`` (what it really simulates, initial positions
included), else from the ``scene`` parameter. It talks to the simulator only through topics:
``joint_states`` in, ``<simulator>/effort_commands`` out, and ``<simulator>/events`` to start the
path over after a reset. Run it beside ``vjm_sim_node``::

    vjm_sim_node --ros-args -p scene:=five_bar -p closure:=exact -p wait_for_command:=true \\
        -p initial_positions.left_elbow:=0.9 -p initial_positions.right_elbow:=-0.9 &
    vjm_ct_controller --ros-args -p path:=circle -p size:=0.05

Parameters: ``scene`` (fallback model), ``simulator`` (name), ``path`` (``circle`` or
``figure8``), ``size`` (radius or half-width, m), ``period`` (s), ``approach_time`` (s), ``kp``
(1/s^2), ``kd`` (1/s), ``preload`` (N m or N), ``point`` (named point; first by default),
``description_timeout`` (s), ``closure_tolerance`` (m: closures of the measured state),
``compensate_plant`` (compensate the scene's joint damping, armature, friction and loads in the
inverse dynamics: :class:`~vjm_ros.control.closed_model.ClosedChainModel` ``plant_terms``).
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from vjm_ros.control import ClosedChainModel, InfeasibleEffortsError
from vjm_ros.control.paths import PATHS
from vjm_ros.core.errors import VjmError
from vjm_ros.ros.controller_base import ControllerNode
from vjm_ros.ros.conversions import joint_arrays, seconds
from vjm_ros.ros.runtime import run_node_until_signal
from vjm_ros.ros.scene_client import wait_for_scene_description

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.parameter import Parameter


class ComputedTorqueNode(ControllerNode):
    """Task-space computed torque (see the module documentation)."""

    def __init__(self, *, context: Context | None = None,
                 parameter_overrides: list[Parameter] | None = None) -> None:
        super().__init__("vjm_ct_controller", {
            "scene": "", "simulator": "vjm_sim_node", "path": "circle", "size": 0.05,
            "period": 2.0, "approach_time": 1.0, "kp": 400.0, "kd": 40.0, "preload": 0.0,
            "point": "", "description_timeout": 10.0, "closure_tolerance": 1e-2,
            "compensate_plant": False,
        }, context=context, parameter_overrides=parameter_overrides)
        p = self.params
        if p["path"] not in PATHS:
            raise ValueError(f"path: expected one of {sorted(PATHS)}, found {p['path']!r}")
        text = wait_for_scene_description(self, p["simulator"], p["description_timeout"])
        kwargs = {"closure_tolerance": p["closure_tolerance"],
                  "plant_terms": bool(p["compensate_plant"])}
        if text is not None:
            self.cm = ClosedChainModel.from_yaml(text, **kwargs)
            origin = f"{p['simulator']}/scene_description"
        elif p["scene"]:
            self.cm = ClosedChainModel.from_scene(p["scene"], **kwargs)
            origin = f"scene {p['scene']}"
        else:
            raise ValueError(f"no {p['simulator']}/scene_description within "
                             f"{p['description_timeout']} s and no scene parameter")
        model = self.cm.model
        self.point = p["point"] or model.points[0].name
        self.path = None
        self.t0 = 0.0
        self.connect(p["simulator"])
        self.get_logger().info(
            f"{model.name} from {origin}: {p['path']} of {p['size']} m for {self.point}, "
            f"{model.actuator_names} -> {self.publisher.topic_name}")

    def on_joint_state(self, msg: JointState) -> None:
        """One command per joint state."""
        try:
            q, qd, _ = joint_arrays(msg, self.cm.model.joint_names)
        except KeyError:
            return  # another robot's joints
        t = seconds(msg.header.stamp)
        if self.path is None or self.restart:
            self.restart = False
            p = self.params
            start = tuple(self.cm.forward_kinematics(q, self.point))
            self.path = PATHS[p["path"]](start, p["size"], p["period"], p["approach_time"])
            self.t0 = t
        try:
            tau = self.efforts(q, qd, t - self.t0)
        except (VjmError, np.linalg.LinAlgError) as exc:
            self.get_logger().warning(f"no command at t = {t:.4f} s: {exc}",
                                      throttle_duration_sec=1.0)
            return
        limits = self.cm.limits
        if np.any(np.abs(tau) > limits):
            self.get_logger().warning(
                f"t = {t:.4f} s: efforts {np.round(tau, 3).tolist()} clamped to the limits "
                f"{limits.tolist()}", throttle_duration_sec=1.0)
            tau = np.clip(tau, -limits, limits)
        self.publisher.publish(Float64MultiArray(data=tau.tolist()))

    def efforts(self, q: np.ndarray, qd: np.ndarray, t: float) -> np.ndarray:
        """The computed-torque law at path time ``t`` (s); efforts in actuator order."""
        cm, p = self.cm, self.params
        x_d, v_d, a_d = self.path.at(t)
        x = cm.forward_kinematics(q, self.point)
        v = cm.task_jacobian(q, self.point) @ qd[cm.independent]
        xdd = a_d + p["kd"] * (v_d - v) + p["kp"] * (x_d - x)
        try:
            return cm.inverse_dynamics(q, qd, point=self.point, xdd=xdd, preload=p["preload"])
        except InfeasibleEffortsError:  # the closest the actuators can do: clamped (caller warns)
            return cm.inverse_dynamics(q, qd, point=self.point, xdd=xdd, preload=p["preload"],
                                       respect_limits=False)


def main(args: list[str] | None = None) -> int:
    """Console entry point ``vjm_ct_controller``; runs until SIGINT or SIGTERM (exit code 0)."""
    return run_node_until_signal(ComputedTorqueNode, "vjm_ct_controller", args)


if __name__ == "__main__":
    sys.exit(main())
