"""For controllers and tools: the simulated scene, from the simulator node itself.

The node publishes its scene (YAML, with the assembled initial state) on
``<namespace>/<node>/scene_description`` with transient-local durability, so a node that starts
later still receives it, as with robot_state_publisher's ``robot_description``::

    text = wait_for_scene_description(node)          # before spinning the node elsewhere
    scene = parse_scene(text, source="scene_description")
    model = scene.model                               # what the simulator runs
"""

from __future__ import annotations

import time

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

SCENE_DESCRIPTION_QOS = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
"""The QoS the simulator publishes its scene description with (a late joiner gets the last one)."""


def wait_for_scene_description(
    node: Node, simulator: str = "vjm_sim_node", timeout: float = 10.0
) -> str | None:
    """The scene YAML the simulator publishes, or None if none arrived within ``timeout``.

    Spins ``node`` (call it before the node is added to an executor that spins elsewhere).

    Parameters
    ----------
    node : rclpy.node.Node
    simulator : str
        Name of the simulator node (in the caller's namespace): the topic is
        ``<simulator>/scene_description``, relative to that namespace.
    timeout : float
        Longest wait, wall s.
    """
    received: list[str] = []
    sub = node.create_subscription(
        String, f"{simulator}/scene_description", lambda m: received.append(m.data),
        SCENE_DESCRIPTION_QOS,
    )
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + timeout
        while not received and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=min(0.05, max(deadline - time.monotonic(), 0.0)))
    finally:
        executor.remove_node(node)
        executor.shutdown()
        node.destroy_subscription(sub)
    return received[-1] if received else None
