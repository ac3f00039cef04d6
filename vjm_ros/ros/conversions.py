"""Conversions between ROS 2 messages and arrays (message types only; rclpy is not started).

The per-tick messages as rclpy message objects (the floor of :mod:`benchmarks.bare_publish` and
the tests' oracle; the node publishes their bytes, :mod:`vjm_ros.ros.wire`); their layouts are
those of :mod:`vjm_ros.logs.messages`, so a live topic and its MCAP log carry the same data:

* ``/joint_states``: every joint in scene order; position (rad or m), velocity (rad/s or m/s),
  effort = the applied generalized effort (N m or N; zero on passive joints);
* ``~/constraint_forces``: ``data[3 i : 3 i + 3] = (fx, fy, mz)`` of closure ``i`` (N, N, N m),
  world frame, acting on the closure's point; ``layout.dim[i]`` has ``label`` = closure name,
  ``size = stride = 3``;
* ``~/closures/<name>/wrench``: the same force as ``WrenchStamped`` in frame ``world`` (force
  ``(fx, fy, 0)``, torque ``(0, 0, mz)``; it acts at the closure's point, not at the origin);
* ``~/energy``: ``(kinetic, potential, constraint, total)`` in J, one labelled dimension each;
* every header stamp is simulated time.
"""

from __future__ import annotations

import array
import math
from collections.abc import Iterable, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout
from visualization_msgs.msg import Marker, MarkerArray

from vjm_ros.logs import messages as layouts
from vjm_ros.sim.samples import Sample

FRAME_ID = layouts.FRAME_ID


# ---------------------------------------------------------------- time
def stamp(t: float) -> Time:
    """``builtin_interfaces/Time`` of ``t`` seconds (rounded to the nanosecond)."""
    sec, nanosec = divmod(layouts.seconds_to_ns(t), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def seconds(msg_stamp: Time) -> float:
    """Seconds of a ``builtin_interfaces/Time``."""
    return msg_stamp.sec + 1e-9 * msg_stamp.nanosec


def nanoseconds(msg_stamp: Time) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time``."""
    return msg_stamp.sec * 1_000_000_000 + msg_stamp.nanosec


def _doubles(values: np.ndarray) -> array.array:
    return array.array("d", np.ascontiguousarray(values, dtype=float).tobytes())


# ---------------------------------------------------------------- per-tick outputs
def joint_state(
    names: Sequence[str], t: float, q: np.ndarray, qd: np.ndarray, effort: np.ndarray
) -> JointState:
    """``sensor_msgs/JointState`` of every joint.

    Parameters
    ----------
    names : sequence of str
        Joint names in coordinate order (``Model.joint_names``).
    t : float
        Simulated time, s.
    q, qd, effort : ndarray, shape (n,)
        Positions (rad or m), rates (rad/s or m/s), applied generalized efforts (N m or N).
    """
    msg = JointState()
    msg.header.frame_id = FRAME_ID
    msg.name = list(names)
    _set_stamp(msg.header.stamp, t)
    msg.position = _doubles(q)
    msg.velocity = _doubles(qd)
    msg.effort = _doubles(effort)
    return msg


def labelled_layout(labels: Sequence[str], size: int) -> MultiArrayLayout:
    """``std_msgs/MultiArrayLayout`` with one dimension per label, ``size = stride = size``."""
    return MultiArrayLayout(
        dim=[MultiArrayDimension(label=str(lb), size=int(size), stride=int(size)) for lb in labels],
        data_offset=0,
    )


def constraint_forces(layout: MultiArrayLayout, forces: np.ndarray) -> Float64MultiArray:
    """``~/constraint_forces`` from the closure forces.

    Parameters
    ----------
    layout : MultiArrayLayout
        ``labelled_layout(closure_names, 3)``.
    forces : ndarray, shape (k, 3)
        ``(fx, fy, mz)`` per closure, N, N, N m.
    """
    return Float64MultiArray(layout=layout, data=_doubles(forces.reshape(-1)))


def energy(layout: MultiArrayLayout, values: np.ndarray) -> Float64MultiArray:
    """``~/energy`` from ``(kinetic, potential, constraint, total)``, J.

    Parameters
    ----------
    layout : MultiArrayLayout
        ``labelled_layout(ENERGY_LABELS, 1)``.
    values : ndarray, shape (4,)
    """
    return Float64MultiArray(layout=layout, data=_doubles(values))


ENERGY_LABELS = layouts.ENERGY_LABELS
FORCE_COMPONENTS = layouts.FORCE_COMPONENTS


def wrench(force: np.ndarray, t: float) -> WrenchStamped:
    """``geometry_msgs/WrenchStamped`` of one closure, frame ``world``.

    Parameters
    ----------
    force : ndarray, shape (3,)
        ``(fx, fy, mz)``: N, N, N m.
    t : float
        Simulated time, s.
    """
    msg = WrenchStamped()
    msg.header.frame_id = FRAME_ID
    _set_stamp(msg.header.stamp, t)
    msg.wrench.force.x = float(force[0])
    msg.wrench.force.y = float(force[1])
    msg.wrench.torque.z = float(force[2])
    return msg


def clock(t: float) -> Clock:
    """``rosgraph_msgs/Clock`` at ``t`` seconds."""
    msg = Clock()
    _set_stamp(msg.clock, t)
    return msg


def _set_stamp(msg_stamp: Time, t: float) -> None:
    msg_stamp.sec, msg_stamp.nanosec = divmod(layouts.seconds_to_ns(t), 1_000_000_000)


def wrench_topic(closure: str) -> str:
    """Private topic of a closure's wrench, ``~/closures/<name>/wrench``."""
    return f"~/closures/{layouts.ros_name(closure)}/wrench"


# ---------------------------------------------------------------- markers
def _marker(when: Time, namespace: str, marker_id: int, kind: int, points: np.ndarray,
            scale: tuple[float, float, float], rgba: tuple[float, float, float, float]) -> Marker:
    m = Marker()
    m.header.stamp = when
    m.header.frame_id = FRAME_ID
    m.ns = namespace
    m.id = marker_id
    m.type = kind
    m.action = Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in scale)
    m.color.r, m.color.g, m.color.b, m.color.a = rgba
    m.points = [Point(x=x, y=y, z=0.0) for x, y in np.asarray(points, dtype=float).tolist()]
    return m


class TipTrace:
    """Recent positions of the chain tips, for the trace marker.

    The last ``length`` positions of each tip, kept ``spacing`` simulated seconds apart, in a
    ring. Until ``length`` positions are kept the first one fills the rest: a strip always has
    ``length`` points once it has one (the first drawn again, where there were fewer), so the
    markers message keeps one layout and the node refills it (:class:`vjm_ros.ros.wire.MarkerWire`).

    Parameters
    ----------
    count : int
        Number of chain tips (the first ``count`` named points of a sample).
    length : int
        Positions kept per tip.
    spacing : float
        Simulated seconds between two kept positions.
    """

    def __init__(self, count: int, length: int = 100, spacing: float = 0.05):
        self.count = count
        self.spacing = spacing
        self._ring = np.zeros((count, max(int(length), 2), 2))
        self._head = 0  # where the next position goes: the oldest one
        self._empty = True
        self._next = -math.inf

    def add(self, sample: Sample) -> None:
        """Keep the tips of ``sample`` if ``spacing`` has passed since the last kept ones."""
        if sample.t < self._next - self.spacing:  # time went back: a reset
            self.clear()
        if sample.t + 1e-12 < self._next:
            return
        self._next = sample.t + self.spacing
        tips = np.asarray(sample.points[: self.count], dtype=float)
        if self._empty:
            self._ring[:] = tips[:, None, :]
            self._empty = False
            self._head = 0
            return
        self._ring[:, self._head] = tips
        self._head = (self._head + 1) % self._ring.shape[1]

    def clear(self) -> None:
        """Forget every position."""
        self._empty = True
        self._head = 0
        self._next = -math.inf

    def strips(self) -> list[np.ndarray]:
        """One array of shape (length, 2) per tip, oldest first (none kept yet: (0, 2)), m."""
        if self._empty:
            return [np.zeros((0, 2)) for _ in range(self.count)]
        ring, head = self._ring, self._head
        ordered = np.concatenate((ring[:, head:], ring[:, :head]), axis=1)
        return list(ordered)


def markers(
    sample: Sample,
    t: float,
    trace: Iterable[np.ndarray] = (),
    force_scale: float = layouts.FORCE_SCALE,
) -> MarkerArray:
    """``visualization_msgs/MarkerArray`` of the mechanism, frame ``world``.

    The markers of :func:`vjm_ros.logs.messages.marker_specs` (links, joints, constraint-force
    arrows and one ``LINE_STRIP`` per chain tip in namespace ``tip_trace``), filled field by
    field.

    Parameters
    ----------
    sample, trace, force_scale
        As in :func:`~vjm_ros.logs.messages.marker_specs`.
    t : float
        Stamp, simulated s.
    """
    when = stamp(t)
    specs = layouts.marker_specs(sample, force_scale, trace=list(trace))
    return MarkerArray(markers=[_marker(when, *spec) for spec in specs])


# ---------------------------------------------------------------- diagnostics
def diagnostics(report: dict, level: int, message: str, t: float, name: str, hardware_id: str) -> DiagnosticArray:
    """``diagnostic_msgs/DiagnosticArray`` with one status holding every figure of ``report``.

    Parameters
    ----------
    report : dict
        Name to number (see :meth:`vjm_ros.realtime.monitor.Monitor.report`).
    level : int
        0 OK, 1 WARN, 2 ERROR.
    message : str
    t : float
        Simulated time of the header, s.
    name, hardware_id : str
    """
    status = DiagnosticStatus(
        level=bytes([level]),
        name=name,
        message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=k, value=_text(v)) for k, v in report.items()],
    )
    out = DiagnosticArray(status=[status])
    out.header.stamp = stamp(t)
    return out


def _text(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


# ---------------------------------------------------------------- inputs
def joint_arrays(msg: JointState, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities and efforts of ``msg`` in the order of ``names``.

    Returns
    -------
    q, qd, effort : ndarray, shape (len(names),)
        Missing fields are nan.

    Raises
    ------
    KeyError
        A name in ``names`` is not in the message.
    """
    index = {n: i for i, n in enumerate(msg.name)}
    order = [index[n] for n in names]

    def pick(values) -> np.ndarray:
        v = np.asarray(values, dtype=float)
        return v[order] if v.size == len(index) else np.full(len(order), np.nan)

    return pick(msg.position), pick(msg.velocity), pick(msg.effort)
