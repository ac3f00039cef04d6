"""The node's per-tick messages as rclpy message objects, built field by field.

The floor of :mod:`benchmarks.bare_publish` (the same messages published by bare rclpy) and the
tests' oracle for the bytes the node publishes (:mod:`vjm_ros.ros.wire`), in the layouts
:mod:`vjm_ros.ros.conversions` describes (those of :mod:`vjm_ros.logs.messages`).
"""

from __future__ import annotations

import array
from collections.abc import Iterable, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout
from visualization_msgs.msg import Marker, MarkerArray

from vjm_ros.logs import messages as layouts
from vjm_ros.ros.conversions import stamp
from vjm_ros.sim.samples import Sample

FRAME_ID = layouts.FRAME_ID
ENERGY_LABELS = layouts.ENERGY_LABELS
FORCE_COMPONENTS = layouts.FORCE_COMPONENTS


def _doubles(values: np.ndarray) -> array.array:
    return array.array("d", np.ascontiguousarray(values, dtype=float).tobytes())


def _set_stamp(msg_stamp: Time, t: float) -> None:
    msg_stamp.sec, msg_stamp.nanosec = divmod(layouts.seconds_to_ns(t), 1_000_000_000)


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
