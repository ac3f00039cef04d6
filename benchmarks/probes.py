"""A probe node for measurements: watches ``/joint_states`` and commands the simulator.

The benchmarks (:mod:`benchmarks.latency`, :mod:`benchmarks.flood` and others) run the
simulator as a separate process, as users do, and talk to it through this probe: a node in a
context of its own, spun in a background thread, so that it can be opened and closed inside any
process (including a test) without touching the global rclpy context.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from visualization_msgs.msg import MarkerArray

from vjm_ros.ros.node import NODE_NAME
from vjm_ros.ros.runtime import Spinner


def probe_executor(context: rclpy.Context):
    """rclpy's ``EventsExecutor`` where it exists (Kilted on), else a ``SingleThreadedExecutor``.

    A probe takes thousands of messages per second (every topic of a 1 kHz node). The
    ``SingleThreadedExecutor`` rebuilds its wait set in Python for each one, which cost more
    than a core on a slow machine; the events executor dispatches from C++. Either is spun by
    :class:`~vjm_ros.ros.runtime.Spinner` with ``spin_once(timeout_sec=...)`` (idle, the probe then
    takes 0.3 % of a core), never by ``spin()``: the loop of ``spin_once`` calls is what lets
    :meth:`~vjm_ros.ros.runtime.Spinner.stop` end it.
    """
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return SingleThreadedExecutor(context=context)
    return EventsExecutor(context=context)


class GraphProbe:
    """A node of its own that watches ``/joint_states`` and publishes effort commands.

    Parameters
    ----------
    name : str
        Node name of the probe.
    on_state : callable, optional
        Called with each ``sensor_msgs/JointState`` received (in the probe's executor thread).
    depth : int
        Keep-last depth of the (reliable) ``/joint_states`` subscription.
    commands : bool
        Create publishers on the simulator's ``~/effort_commands`` and ``~/joint_commands``.
    sim_node : str
        Name of the simulator node.
    """

    def __init__(
        self,
        name: str,
        on_state: Callable[[JointState], None] | None = None,
        depth: int = 1000,
        commands: bool = False,
        sim_node: str = NODE_NAME,
    ) -> None:
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.ctx)
        self._array, self._named = Float64MultiArray(), JointState()  # reused: publish copies
        self.efforts = self.named = None
        if commands:
            self.efforts = self.node.create_publisher(
                Float64MultiArray, f"/{sim_node}/effort_commands", 10)
            self.named = self.node.create_publisher(JointState, f"/{sim_node}/joint_commands", 10)
        if on_state is not None:
            self.node.create_subscription(
                JointState, "/joint_states", on_state,
                QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE))
        self.executor = probe_executor(self.ctx)
        self.executor.add_node(self.node)
        self.spinner = Spinner(self.executor).start()

    def commands_matched(self) -> bool:
        """Whether the simulator subscribes to every command topic of the probe."""
        pubs = [p for p in (self.efforts, self.named) if p is not None]
        return bool(pubs) and all(p.get_subscription_count() > 0 for p in pubs)

    def wait_for_commands_delivered(self, timeout: float) -> bool:
        """Wait until the simulator has acknowledged every command published (reliable QoS), at
        most ``timeout`` s; True when it has. A process that exits right after publishing would
        otherwise take the commands still queued in its writer with it."""
        from rclpy.duration import Duration

        pubs = [p for p in (self.efforts, self.named)
                if p is not None and hasattr(p, "wait_for_all_acked")]
        return all(p.wait_for_all_acked(Duration(nanoseconds=int(timeout * 1e9))) for p in pubs)

    def publish_efforts(self, values: Sequence[float]) -> None:
        """One ``~/effort_commands`` message (values in the scene's actuator order, N m or N)."""
        self._array.data = values
        self.efforts.publish(self._array)

    def publish_named(self, names: Sequence[str], values: Sequence[float]) -> None:
        """One ``~/joint_commands`` message (efforts matched by joint name)."""
        self._named.name, self._named.effort = names, values
        self.named.publish(self._named)

    def close(self) -> None:
        """Stop spinning and shut the probe's context down."""
        self.spinner.stop()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)

    def __enter__(self) -> GraphProbe:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class TopicSink(GraphProbe):
    """A probe that subscribes to every topic the simulator publishes and counts the messages.

    The counting subscriptions take each message's serialized bytes (``raw``), as a recorder
    does: the simulator sends and the sink receives every message through DDS as with a typed
    subscription, but the sink's executor does not build a Python message it never reads. Typed,
    seven 1 kHz topics cost the sink more than a core on a slow machine; it then fell behind, its
    reliable queues filled, and the studies measured the sink instead of the simulator.

    Parameters
    ----------
    name : str
        Node name of the sink.
    closures : sequence of str
        Closure names of the scene (one wrench topic each).
    sim_node : str
        Name of the simulator node.
    on_state, commands
        As in :class:`GraphProbe` (a controller that also watches every topic).
    """

    def __init__(self, name: str, closures: Sequence[str], sim_node: str = NODE_NAME,
                 on_state: Callable[[JointState], None] | None = None,
                 commands: bool = False) -> None:
        super().__init__(name, sim_node=sim_node, on_state=on_state, commands=commands)
        from vjm_ros.ros.conversions import wrench_topic

        private = f"/{sim_node}"
        topics = [("/clock", Clock), ("/joint_states", JointState), ("/diagnostics", DiagnosticArray),
                  (f"{private}/constraint_forces", Float64MultiArray),
                  (f"{private}/energy", Float64MultiArray), (f"{private}/markers", MarkerArray),
                  (f"{private}/events", String)]
        topics += [(wrench_topic(c).replace("~", private, 1), WrenchStamped) for c in closures]
        self.counts = dict.fromkeys((topic for topic, _ in topics), 0)
        for topic, kind in topics:
            self.node.create_subscription(kind, topic, self._counter(topic), 1000, raw=True)

    def _counter(self, topic: str) -> Callable:
        def count(_msg) -> None:
            self.counts[topic] += 1
        return count
