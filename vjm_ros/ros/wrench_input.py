"""``~/external_wrench``: a user's push on the mechanism, taken into the tick loop's wrenches.

``geometry_msgs/WrenchStamped`` with ``header.frame_id`` one of the scene's named points (chain
tips included): its in-plane part (force x, y in the world frame, N; torque z, N m) acts at that
point from the next tick on (:mod:`vjm_ros.realtime.wrenches`), until none has arrived for that
point for ``command_timeout`` seconds. The out-of-plane part cannot act on a planar mechanism: a
wrench that has one is taken without it, with a warning naming the fields.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from geometry_msgs.msg import WrenchStamped

from vjm_ros.realtime.wrenches import WrenchBuffer

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.subscription import Subscription

TOPIC = "~/external_wrench"


def subscribe_external_wrench(node: Node, buffer: Callable[[], WrenchBuffer | None],
                              warn: Callable[[str, str], None]) -> Subscription:
    """Subscribe ``node`` to :data:`TOPIC`, each message submitted to ``buffer()`` (the tick
    loop's wrenches at the time it arrives); refusals and dropped out-of-plane components go to
    ``warn(key, text)``."""

    def on_wrench(msg: WrenchStamped) -> None:
        wrenches = buffer()
        if wrenches is None:
            return
        f, m = msg.wrench.force, msg.wrench.torque
        off_plane = [name for name, v in (("force.z", f.z), ("torque.x", m.x), ("torque.y", m.y))
                     if v != 0.0]
        if off_plane:
            warn(f"{TOPIC} plane", f"{TOPIC}: {', '.join(off_plane)} ignored (a planar "
                 "mechanism takes force x, y and torque z only)")
        why = wrenches.submit(msg.header.frame_id, (f.x, f.y), m.z)
        if why is not None:
            warn(f"{TOPIC} refused", f"{TOPIC}: wrench refused: {why}")

    return node.create_subscription(WrenchStamped, TOPIC, on_wrench, 10)
