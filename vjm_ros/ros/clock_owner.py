"""The simulator's ``/clock`` publisher, and a watch for other publishers of ``/clock``.

``/clock`` is an absolute topic: several simulators in one graph (one namespace each) that all
publish it interleave their simulated times, and every subscriber sees time step back whenever
a message of one follows a message of the other. Exactly one node
of a graph may publish it; the others run with ``publish_clock:=false``, and then hold no
``/clock`` publisher at all, so that the graph shows who owns the clock.

:class:`ClockOwner` holds the node's publisher while ``publish_clock`` is true (opened and
closed by the tick loop's thread, the only one that publishes on it) and, every
:data:`CHECK_PERIOD` seconds in the executor's thread (never in a tick), looks up the other
publishers of ``/clock`` in the ROS graph (``get_publishers_info_by_topic``, about 0.1 ms): each
one that appears is reported once (:class:`RivalWatch`), by name and namespace from the first look
at which the graph knows its node (discovery can show a publisher before the node that holds it).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

from rclpy.clock import Clock as WallClock
from rclpy.clock import ClockType
from rosgraph_msgs.msg import Clock

from vjm_ros.ros.runtime import raw_publish

if TYPE_CHECKING:
    from rclpy.node import Node

TOPIC = "/clock"
CHECK_PERIOD = 1.0
"""Seconds (steady clock) between two looks at the other publishers of ``/clock``."""
CONFLICT = "clock_conflict"
"""Kind of the notice that names another publisher of ``/clock``."""
UNKNOWN_NODE = ("_NODE_NAMESPACE_UNKNOWN_", "_NODE_NAME_UNKNOWN_")
"""Namespace and name the graph gives the node of a publisher it has discovered before that node
(rmw_dds_common's graph cache, in Humble, Jazzy and Kilted alike): not a name to report."""
UNNAMED = "a publisher whose node is not in the graph"
"""How a rival is reported whose node the graph still does not name at the next look (a DDS
participant that is not a ROS node, for one)."""


def _unnamed(publisher: tuple[str, str]) -> bool:
    return publisher[0] == UNKNOWN_NODE[0] or publisher[1] == UNKNOWN_NODE[1]


def rivals(publishers: Iterable[tuple[str, str]], own: tuple[str, str]) -> list[str]:
    """Full names of the publishers of ``/clock`` besides this node's own one.

    Parameters
    ----------
    publishers : iterable of (namespace, name)
        Every publisher of ``/clock`` in the graph, by the node that holds it.
    own : (namespace, name)
        This node; one publisher of its name is its own (another node of the very same name
        and namespace is still a rival).

    Returns
    -------
    list of str
        Sorted full names (``/ns/name``; ``/name`` in the root namespace), one per other
        publisher whose node the graph knows (one it does not, :data:`UNKNOWN_NODE`, is left
        out until it does).
    """
    count = Counter(p for p in publishers if not _unnamed(p))
    if count[own]:
        count[own] -= 1
    return sorted(f"{ns.rstrip('/')}/{name}" for (ns, name), k in count.items() for _ in range(k))


class RivalWatch:
    """Which other publishers of ``/clock`` to report at each look at the graph: each one once,
    by name from the first look at which the graph names its node, or as :data:`UNNAMED` when
    the graph does not name it at two looks in a row."""

    def __init__(self) -> None:
        self._reported: frozenset[str] = frozenset()
        self._unnamed_before = False

    def look(self, publishers: Iterable[tuple[str, str]], own: tuple[str, str]) -> list[str]:
        """The rivals to report now (sorted), from this look's publishers of ``/clock``
        (``(namespace, name)`` of the node of each, as :func:`rivals` takes them)."""
        publishers = list(publishers)
        found = rivals(publishers, own)
        unnamed = any(_unnamed(p) for p in publishers)
        if unnamed and self._unnamed_before:
            found.append(UNNAMED)
        self._unnamed_before = unnamed
        new = sorted(set(found) - self._reported)
        self._reported = frozenset(found)
        return new


class ClockOwner:
    """The ``/clock`` publisher of a node and the watch for others.

    Parameters
    ----------
    node : rclpy.node.Node
    notice : callable
        ``notice(kind, text)``: reports :data:`CONFLICT` (the node logs a warning and publishes
        it on ``~/events``).
    publish : bool
        Open the publisher now (``publish_clock`` at start).
    """

    def __init__(self, node: Node, notice: Callable[[str, str], None], publish: bool) -> None:
        self._node = node
        self._notice = notice
        self.publisher = None
        self.send: Callable[[bytes], None] | None = None
        """Publish one serialized ``rosgraph_msgs/Clock``; None while closed."""
        self._watch = RivalWatch()
        if publish:
            self.open()
        self._timer = node.create_timer(CHECK_PERIOD, self.check,
                                        clock=WallClock(clock_type=ClockType.STEADY_TIME))

    def open(self) -> Callable[[bytes], None]:
        """Create the publisher if it is closed (tick loop's thread); return :attr:`send`."""
        if self.send is None:
            self.publisher = self._node.create_publisher(Clock, TOPIC, 10)
            self.send = raw_publish(self.publisher)
        return self.send

    def close(self) -> None:
        """Destroy the publisher if it is open (tick loop's thread, after its last publish)."""
        if self.publisher is not None:
            self.send = None
            self._node.destroy_publisher(self.publisher)
            self.publisher = None

    def check(self) -> None:
        """Report each other publisher of ``/clock`` that appeared since the last look (only
        while this node publishes it)."""
        if self.send is None:
            self._watch = RivalWatch()
            return
        node = self._node
        new = self._watch.look(((i.node_namespace, i.node_name)
                                for i in node.get_publishers_info_by_topic(TOPIC)),
                               (node.get_namespace(), node.get_name()))
        if new:
            self._notice(CONFLICT, (
                f"/clock is also published by {', '.join(new)}: subscribers would see "
                "simulated time step back; set publish_clock:=false on every simulator but one"))
