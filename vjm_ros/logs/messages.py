"""Pure functions from simulation samples to ROS 2 message dicts, and the topic names.

The dicts have exactly the fields of the ROS 2 types (nested dicts, lists of floats), so the same
layout serves the MCAP recorder (:mod:`vjm_ros.logs.cdr` encodes them), the live node (copy
them into rclpy messages) and tests. Nothing here imports ROS.

Topics (docs/design.md section 5), with ``<node>`` the node name (default ``vjm_sim_node``):

==========================================  ==================================  =================
topic                                       type                                rate
==========================================  ==================================  =================
``/joint_states``                           ``sensor_msgs/msg/JointState``      every tick
``/<node>/ground_truth/joint_states``        ``sensor_msgs/msg/JointState``      every tick (*)
``/<node>/constraint_forces``               ``std_msgs/msg/Float64MultiArray``  every tick
``/<node>/closures/<closure>/wrench``       ``geometry_msgs/msg/WrenchStamped`` every tick
``/<node>/energy``                          ``std_msgs/msg/Float64MultiArray``  every tick
``/clock``                                  ``rosgraph_msgs/msg/Clock``         every tick
``/<node>/markers``                         ``visualization_msgs/msg/MarkerArray`` decimated
``/<node>/events``                          ``std_msgs/msg/String``             on events
==========================================  ==================================  =================

(*) Only for a scene with sensors: ``/joint_states`` then carries the measured state and this
topic the exact one.

The stop of a joint with a ``range`` is reported as a closure named ``<joint>_stop``
(``Model.force_names``): an entry of ``constraint_forces`` and a ``closures/<joint>_stop/wrench``.

Times are integer nanoseconds; every header uses the frame ``world`` (x right, y up, z out of the
plane, metres).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from vjm_ros.sim.samples import Sample

FRAME_ID = "world"
ENERGY_LABELS = ("kinetic", "potential", "constraint", "total")
"""Entries of the energy message, J."""
FORCE_COMPONENTS = ("fx", "fy", "mz")
"""Entries per closure in the constraint-force message: N, N, N m."""

JOINT_STATE = "sensor_msgs/msg/JointState"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
CLOCK = "rosgraph_msgs/msg/Clock"
STRING = "std_msgs/msg/String"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"

# visualization_msgs/Marker constants
ARROW, LINE_STRIP, LINE_LIST, SPHERE_LIST = 0, 4, 5, 7
ADD = 0


def ros_name(name: str) -> str:
    """``name`` with every character that a ROS topic token may not hold replaced by ``_``."""
    out = "".join(ch if (ch.isascii() and (ch.isalnum() or ch == "_")) else "_" for ch in name)
    return out if out and not out[0].isdigit() else f"_{out}"


def _private_topic(name: str) -> property:
    """A :class:`Topics` property for the node's own topic ``<namespace>/<node>/<name>``."""
    return property(lambda self: f"{self.private}/{name}", doc=f"``<namespace>/<node>/{name}``.")


@dataclass(frozen=True)
class Topics:
    """Topic names of one node, as ROS 2 resolves them.

    ``joint_states`` is relative (``<namespace>/joint_states``), ``/clock`` and ``/diagnostics``
    are absolute by convention, the node's own topics are private
    (``<namespace>/<node>/...``).

    Parameters
    ----------
    node : str
        Node name.
    namespace : str
        Node namespace, ``""`` or ``"/"`` for the root, else ``"/a"`` or ``"/a/b"``.
    """

    node: str = "vjm_sim_node"
    namespace: str = ""

    clock: str = "/clock"

    @property
    def _ns(self) -> str:
        return self.namespace.rstrip("/")

    @property
    def joint_states(self) -> str:
        """``<namespace>/joint_states``."""
        return f"{self._ns}/joint_states"

    @property
    def private(self) -> str:
        """``<namespace>/<node>``, the prefix of the node's own topics."""
        return f"{self._ns}/{self.node}"

    constraint_forces = _private_topic("constraint_forces")
    energy = _private_topic("energy")
    markers = _private_topic("markers")
    events = _private_topic("events")
    ground_truth_joint_states = _private_topic("ground_truth/joint_states")

    def wrench(self, closure: str) -> str:
        """``<namespace>/<node>/closures/<closure>/wrench``."""
        return f"{self.private}/closures/{ros_name(closure)}/wrench"


# ---------------------------------------------------------------- building blocks
def stamp(ns: int) -> dict:
    """``builtin_interfaces/Time`` of ``ns`` nanoseconds."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def header(ns: int, frame_id: str = FRAME_ID) -> dict:
    """``std_msgs/Header`` stamped at ``ns`` nanoseconds."""
    return {"stamp": stamp(ns), "frame_id": frame_id}


def seconds_to_ns(t: float) -> int:
    """Seconds to integer nanoseconds (rounded, so ticks of 1 ms stay exact)."""
    return int(round(t * 1e9))


def labelled_layout(labels: Sequence[str], size: int) -> dict:
    """``std_msgs/MultiArrayLayout`` with one dimension per label.

    Dimension ``i`` has ``label = labels[i]``, ``size = stride = size``: entry ``i`` occupies
    ``data[size * i : size * (i + 1)]``, ``data_offset`` is 0.
    """
    return {
        "dim": [{"label": str(lb), "size": int(size), "stride": int(size)} for lb in labels],
        "data_offset": 0,
    }


# ---------------------------------------------------------------- per-tick messages
def joint_state(joint_names: Sequence[str], sample: Sample, ns: int) -> dict:
    """``sensor_msgs/JointState`` of every joint.

    Parameters
    ----------
    joint_names : sequence of str
        ``Model.joint_names`` (coordinate order).
    sample : Sample
        ``q`` (rad or m), ``qd`` (rad/s or m/s), ``effort`` (applied generalized force, N m or N).
    ns : int
        Header stamp, ns.
    """
    return {
        "header": header(ns),
        "name": list(joint_names),
        "position": sample.q.tolist(),
        "velocity": sample.qd.tolist(),
        "effort": sample.effort.tolist(),
    }


def constraint_forces(force_names: Sequence[str], sample: Sample) -> dict:
    """``std_msgs/Float64MultiArray`` of the constraint force of every closure, then of every
    stop.

    Layout: one dimension per entry, ``dim[i].label`` = its name, ``dim[i].size`` =
    ``dim[i].stride`` = 3, ``data_offset`` = 0; entry ``i`` holds
    ``data[3 i : 3 i + 3] = (fx, fy, mz)``: the world-frame force (N, N) and moment (N m, angle
    closures) that the closure applies to its point ``Pa``; for the stop of a joint with a
    ``range`` (named ``<joint>_stop``), what the stop applies to the joint's link at the joint:
    a moment (revolute) or a force along the slide (prismatic).

    Parameters
    ----------
    force_names : sequence of str
        ``Model.force_names``.
    sample : Sample
        ``closure_force``, shape (k + s, 3).
    """
    return {
        "layout": labelled_layout(force_names, len(FORCE_COMPONENTS)),
        "data": sample.closure_force.reshape(-1).tolist(),
    }


def energy(sample: Sample) -> dict:
    """``std_msgs/Float64MultiArray`` ``[kinetic, potential, constraint, total]``, J.

    Layout: one dimension per entry, labelled ``kinetic``, ``potential``, ``constraint``,
    ``total``, each ``size = stride = 1``.
    """
    return {"layout": labelled_layout(ENERGY_LABELS, 1), "data": sample.energy.tolist()}


def wrench(sample: Sample, index: int, ns: int) -> dict:
    """``geometry_msgs/WrenchStamped`` of closure ``index``, frame ``world``.

    The wrench acts at the closure's point ``Pa`` (``sample.closure_points[index]``), not at the
    frame origin: force ``(fx, fy, 0)`` N, torque ``(0, 0, mz)`` N m.
    """
    fx, fy, mz = (float(v) for v in sample.closure_force[index])
    return {
        "header": header(ns),
        "wrench": {
            "force": {"x": fx, "y": fy, "z": 0.0},
            "torque": {"x": 0.0, "y": 0.0, "z": mz},
        },
    }


def clock(ns: int) -> dict:
    """``rosgraph_msgs/Clock`` at ``ns`` nanoseconds."""
    return {"clock": stamp(ns)}


def event(text: str) -> dict:
    """``std_msgs/String`` holding ``text``."""
    return {"data": str(text)}


# ---------------------------------------------------------------- markers
def _point(p) -> dict:
    return {"x": float(p[0]), "y": float(p[1]), "z": 0.0}


def _rgba(r: float, g: float, b: float, a: float = 1.0) -> dict:
    return {"r": r, "g": g, "b": b, "a": a}


def marker(
    ns_stamp: int,
    namespace: str,
    marker_id: int,
    kind: int,
    points: np.ndarray,
    scale: tuple[float, float, float],
    color: dict,
) -> dict:
    """A complete ``visualization_msgs/Marker`` dict in the ``world`` frame.

    Parameters
    ----------
    ns_stamp : int
        Header stamp, ns.
    namespace : str
        Marker namespace (``ns`` field).
    marker_id : int
    kind : int
        Marker type (``ARROW``, ``LINE_LIST``, ``SPHERE_LIST``).
    points : ndarray, shape (m, 2)
        Planar points, m (z = 0).
    scale : tuple of float
        Marker scale, m (line width, sphere diameter, or arrow shaft/head diameters).
    color : dict
        ``std_msgs/ColorRGBA``.
    """
    return {
        "header": header(ns_stamp),
        "ns": namespace,
        "id": int(marker_id),
        "type": int(kind),
        "action": ADD,
        "pose": {
            "position": {"x": 0.0, "y": 0.0, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
        "scale": {"x": scale[0], "y": scale[1], "z": scale[2]},
        "color": color,
        "lifetime": {"sec": 0, "nanosec": 0},
        "frame_locked": False,
        "points": [_point(p) for p in points],
        "colors": [],
        "texture_resource": "",
        "texture": {"header": header(0, ""), "format": "", "data": []},
        "uv_coordinates": [],
        "text": "",
        "mesh_resource": "",
        "mesh_file": {"filename": "", "data": []},
        "mesh_use_embedded_materials": False,
    }


LINE_WIDTH = 0.01
"""Width of the link lines, m."""
FORCE_SCALE = 0.01
"""Length of the constraint-force arrows per newton, m/N."""


def marker_specs(
    sample: Sample, force_scale: float = FORCE_SCALE, trace: Sequence[np.ndarray] = ()
) -> list[tuple]:
    """What the mechanism's markers draw, once for the logs and the node.

    Markers: ``links`` (id 0, ``LINE_LIST``: start and end of every link), ``joints`` (id 1,
    ``SPHERE_LIST``: link origins and named points such as chain tips), ``constraint_forces``
    (ids 0..k-1, one ``ARROW`` per closure from its point along ``force_scale * (fx, fy)``) and,
    when ``trace`` is given, ``tip_trace`` (one ``LINE_STRIP`` per chain tip with two or more
    positions). Links are drawn :data:`LINE_WIDTH` wide.

    Parameters
    ----------
    sample : Sample
        ``segments`` (n, 2, 2), ``points`` (n_points, 2), ``closure_points`` (k, 2),
        ``closure_force`` (k, 3).
    force_scale : float
        Arrow length per newton, m/N.
    trace : sequence of ndarray, shape (m, 2)
        Recent positions of each chain tip, m.

    Returns
    -------
    list of tuple
        ``(namespace, id, kind, points (m, 2) in m, scale (3,) in m, rgba (4,))`` per marker.
    """
    w = LINE_WIDTH
    segments = np.asarray(sample.segments)
    joints = np.vstack((segments[:, 0, :], np.asarray(sample.points).reshape(-1, 2)))
    specs = [
        ("links", 0, LINE_LIST, segments.reshape(-1, 2), (w, 0.0, 0.0), (0.2, 0.4, 0.9, 1.0)),
        ("joints", 1, SPHERE_LIST, joints, (3 * w,) * 3, (0.1, 0.1, 0.1, 1.0)),
    ]
    for i, (p, f) in enumerate(zip(sample.closure_points, sample.closure_force, strict=True)):
        arrow = np.array([p, np.asarray(p) + force_scale * np.asarray(f[:2])])
        specs.append(
            ("constraint_forces", i, ARROW, arrow, (w, 2 * w, 0.0), (0.9, 0.2, 0.1, 1.0))
        )
    for i, strip in enumerate(trace):
        if len(strip) >= 2:
            specs.append(
                ("tip_trace", i, LINE_STRIP, np.asarray(strip), (0.5 * w, 0.0, 0.0),
                 (0.1, 0.6, 0.2, 0.8))
            )
    return specs


def markers(sample: Sample, ns: int, force_scale: float = FORCE_SCALE,
            trace: Sequence[np.ndarray] = ()) -> dict:
    """``visualization_msgs/MarkerArray`` drawing the mechanism (:func:`marker_specs`).

    Parameters
    ----------
    sample, force_scale, trace
        As for :func:`marker_specs` (``trace``: the node's ``tip_trace`` markers).
    ns : int
        Header stamp, ns.
    """
    specs = marker_specs(sample, force_scale, trace)
    return {"markers": [marker(ns, namespace, marker_id, kind, points, scale, _rgba(*rgba))
                        for namespace, marker_id, kind, points, scale, rgba in specs]}
