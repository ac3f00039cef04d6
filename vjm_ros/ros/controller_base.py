"""What every example controller shares: its parameters, its three topics, reset handling.

A controller commands one simulator: it publishes ``<simulator>/effort_commands``, subscribes
``joint_states`` and ``<simulator>/events``. Topic names are relative, so a namespace
(``-r __ns:=/robot1``) or a remap places the controller beside its simulator.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.parameter import Parameter


class ControllerNode(Node):
    """A node named ``name`` whose ROS parameters are ``defaults`` (name -> default value).

    The values are in :attr:`params`. Subclasses call :meth:`connect` once their model is
    ready and implement ``on_joint_state(msg)``; :attr:`restart` turns True at the simulator's
    reset notice (``reset:`` on its events topic), for the subclass to start its motion over.
    """

    def __init__(self, name: str, defaults: dict, *, context: Context | None = None,
                 parameter_overrides: list[Parameter] | None = None) -> None:
        super().__init__(name, context=context, parameter_overrides=parameter_overrides)
        self.params = {key: self.declare_parameter(key, value).value
                       for key, value in defaults.items()}
        self.restart = False

    def connect(self, simulator: str) -> str:
        """Create the effort publisher and the two subscriptions; return the command topic."""
        topic = f"{simulator}/effort_commands"
        self.publisher = self.create_publisher(Float64MultiArray, topic, 10)
        # Depth 1: when a state arrives before the previous one was handled, only the newest
        # counts (a controller that falls behind skips states instead of acting on old ones).
        self.create_subscription(JointState, "joint_states", self.on_joint_state, 1)
        self.create_subscription(String, f"{simulator}/events", self.on_event, 10)
        return topic

    def on_joint_state(self, msg: JointState) -> None:  # pragma: no cover - subclass duty
        raise NotImplementedError

    def on_event(self, msg: String) -> None:
        """Start the motion over at the next state after the simulator's reset."""
        if msg.data.startswith("reset:"):
            self.restart = True
