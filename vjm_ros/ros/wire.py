"""The per-tick messages as serialized CDR, refilled in place and published as bytes.

rclpy's ``publish(msg)`` converts a Python message field by field (a Python getter per field,
nested messages included), allocates the C message and serializes it: with a subscriber in
another process, 5 per-tick messages took 34-41 µs here against 21-24 µs for the same bytes
published with ``publish(bytes)`` (measured in one run on five_bar). :class:`TickWire` keeps one
serialized message per per-tick topic and writes only what changes from tick to tick (the stamp
and the numbers) into it at fixed offsets; everything else (frame, joint names, array layout)
stays as written once.

The bytes and offsets are the messages' one layout, :class:`vjm_ros.logs.cdr.FixedLayout`, which
the logs write too; test/test_cdr_rosbags.py checks it against rosbags' and rclpy's serializers
byte for byte, and test/test_tick_wire.py reads the refilled bytes back with rclpy.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from vjm_ros.logs import cdr
from vjm_ros.logs import messages as layouts

if TYPE_CHECKING:
    from vjm_ros.sim.samples import Sample

_pack_stamp = cdr.STAMP.pack_into
_AT = cdr.STAMP_OFFSET


class _Buffer:
    """One serialized message, a copy of its layout's template, and numpy views of its runs."""

    def __init__(self, layout: cdr.FixedLayout):
        self.data = bytearray(layout.template)
        self.runs = [np.frombuffer(self.data, dtype="<f8", count=count, offset=offset)
                     for offset, count in layout.arrays]


class TickWire:
    """Serialized per-tick messages, refilled in place.

    Each per-tick message starts as its layout's template (:mod:`vjm_ros.logs.cdr`); each tick
    writes the new stamp and numbers at the layout's offsets through numpy views and the node
    publishes the bytes as they are.

    Parameters
    ----------
    joint_names : sequence of str
        ``Model.joint_names``.
    force_names : sequence of str
        ``Model.force_names``: the closures, then the stops.
    """

    def __init__(self, joint_names: Sequence[str], force_names: Sequence[str]):
        k = len(force_names)
        self.joint = _Buffer(cdr.joint_state_layout(joint_names, layouts.FRAME_ID))
        self._q, self._qd, self._effort = self.joint.runs
        self.forces = _Buffer(cdr.multi_array_layout(
            layouts.labelled_layout(force_names, len(layouts.FORCE_COMPONENTS)),
            len(layouts.FORCE_COMPONENTS) * k, align_empty=True))  # rclpy's bytes
        self._forces = (self.forces.runs[0] if k else np.zeros(0)).reshape(
            k, len(layouts.FORCE_COMPONENTS))
        self.energy = _Buffer(cdr.multi_array_layout(
            layouts.labelled_layout(layouts.ENERGY_LABELS, 1), len(layouts.ENERGY_LABELS)))
        (self._energy,) = self.energy.runs
        wrench = cdr.wrench_stamped_layout(layouts.FRAME_ID)
        self.wrenches = [_Buffer(wrench) for _ in force_names]
        self._linear = [w.runs[0] for w in self.wrenches]
        self._torque = [w.runs[1] for w in self.wrenches]
        self.clock = _Buffer(cdr.CLOCK_LAYOUT)
        self._stamped = [b.data for b in (self.joint, *self.wrenches, self.clock)]
        self._ns: int | None = None

    def set_time(self, t: float) -> None:
        """Stamp every message with simulated time ``t``, s (rounded to the nanosecond)."""
        ns = layouts.seconds_to_ns(t)
        if ns != self._ns:
            self._ns = ns
            sec, nanosec = divmod(ns, 1_000_000_000)
            for data in self._stamped:
                _pack_stamp(data, _AT, sec, nanosec)

    def joint_state(self, t: float, q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> bytes:
        """Serialized ``joint_states`` (t in s, q, qd, effort shape (n,))."""
        self.set_time(t)
        self._q[:] = q
        self._qd[:] = qd
        self._effort[:] = effort
        return bytes(self.joint.data)

    def constraint_forces(self, forces: np.ndarray) -> bytes:
        """Serialized ``~/constraint_forces`` (forces shape (k, 3): N, N, N m)."""
        self._forces[:] = forces
        return bytes(self.forces.data)

    def energy_values(self, values: np.ndarray) -> bytes:
        """Serialized ``~/energy`` (values shape (4,), J)."""
        self._energy[:] = values
        return bytes(self.energy.data)

    def wrench(self, index: int, force: np.ndarray, t: float) -> bytes:
        """Serialized ``~/closures/<name>/wrench`` of closure ``index`` (force shape (3,))."""
        self.set_time(t)
        self._linear[index][:] = force[:2]
        self._torque[index][0] = force[2]
        return bytes(self.wrenches[index].data)

    def clock_at(self, t: float) -> bytes:
        """Serialized ``/clock`` at ``t`` seconds."""
        self.set_time(t)
        return bytes(self.clock.data)


class MarkerWire:
    """``~/markers`` as serialized CDR, refilled in place of a template.

    Built as rclpy messages (a ``Point`` object per point) and serialized by ``publish``, the
    markers of three_chain with its tip traces (205 points) took 1.4 ms of the tick loop, longer
    than a tick at 1 kHz: at 30 Hz the loop was late some 30 times a second. The message keeps
    its layout while the markers keep their kinds and point counts (the tip traces have a
    constant length, :class:`~vjm_ros.ros.conversions.TipTrace`); this class makes the layout
    once per change with the logs' encoder (:func:`vjm_ros.logs.cdr.markers_layout`, checked
    against rosbags byte for byte) and then writes only the stamps and the points
    (:meth:`~vjm_ros.logs.cdr.FixedLayout.encode`).

    Parameters
    ----------
    force_scale : float
        Length of the constraint-force arrows, m/N.
    """

    def __init__(self, force_scale: float = layouts.FORCE_SCALE):
        self.force_scale = float(force_scale)
        self._key: tuple | None = None
        self._layout: cdr.FixedLayout | None = None

    def markers(self, sample: Sample, t: float, trace: Sequence[np.ndarray] = ()) -> bytes:
        """Serialized ``visualization_msgs/MarkerArray`` of ``sample`` stamped ``t`` (s), with the
        tip traces ``trace``."""
        specs = layouts.marker_specs(sample, self.force_scale, trace=trace)
        key = tuple((ns, i, kind, len(points), scale, rgba)
                    for ns, i, kind, points, scale, rgba in specs)
        if key != self._key:
            self._layout = cdr.markers_layout(
                layouts.markers(sample, 0, self.force_scale, trace=trace))
            self._key = key
        points = [np.column_stack((spec[3], np.zeros(len(spec[3])))) for spec in specs]
        return self._layout.encode(layouts.seconds_to_ns(t), *points)  # z stays 0.0
