"""The per-tick messages as serialized CDR, refilled in place and published as bytes.

rclpy's ``publish(msg)`` converts a Python message field by field (a Python getter per field,
nested messages included), allocates the C message and serializes it: with a subscriber in
another process, 5 per-tick messages took 34-41 µs here against 21-24 µs for the same bytes
published with ``publish(bytes)`` (measured in one run on five_bar). :class:`TickWire` keeps one
serialized message per per-tick topic and writes only what changes from tick to tick (the stamp
and the numbers) into it at fixed offsets; everything else (frame, joint names, array layout)
stays as rclpy's own serializer wrote it.

The templates and offsets come from rclpy itself: each message is filled through
:class:`~vjm_ros.ros.conversions.TickMessages` with sentinel values and serialized with
``rclpy.serialization.serialize_message``; the offsets are where the sentinels' bytes are. At
construction every buffer is filled with test values and compared byte for byte with rclpy's
serialization of the same message: same length, and read back by rclpy's deserializer, the same
message (:class:`WireLayoutError` otherwise; padding bytes are left out of the comparison, rclpy
leaves them uninitialized). A layout this module does not understand is refused rather than
published wrong.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np
from rclpy.serialization import deserialize_message, serialize_message

from vjm_ros.logs import cdr
from vjm_ros.logs import messages as layouts
from vjm_ros.ros.conversions import TickMessages

STAMP_OFFSET = 4
"""Offset of the first header's stamp (``int32 sec``, ``uint32 nanosec``) in every per-tick
message: right after the 4-byte encapsulation header, since the header (or, in ``Clock``, the
stamp itself) is the first field."""
_STAMP = struct.Struct("<iI")


class WireLayoutError(RuntimeError):
    """rclpy serializes a per-tick message in a layout :class:`TickWire` cannot refill."""


class _Buffer:
    """One serialized message: its bytes and numpy views of its number fields."""

    def __init__(self, template: bytes):
        self.data = bytearray(template)

    def view(self, offset: int, count: int) -> np.ndarray:
        """Writable float64 view of ``count`` doubles at ``offset`` (CDR little endian)."""
        return np.frombuffer(self.data, dtype="<f8", count=count, offset=offset)

    def find(self, values: Sequence[float]) -> int:
        """Offset of the packed doubles ``values`` (sentinels), which must occur exactly once."""
        packed = np.asarray(values, dtype="<f8").tobytes()
        if not packed:
            return 0  # nothing to refill (a scene without closures)
        at = self.data.find(packed)
        if at < 0 or self.data.find(packed, at + 1) >= 0:
            raise WireLayoutError("a per-tick message's numbers are not where expected")
        return at


def _sentinels(count: int, first: int) -> np.ndarray:
    """Distinct doubles that occur nowhere else in a message (not round, not small integers)."""
    return np.pi * 1e7 + np.arange(first, first + count) * np.e


class TickWire:
    """Serialized per-tick messages, refilled in place.

    Each per-tick message is serialized once by rclpy (from :class:`~.conversions.TickMessages`)
    with distinct marker values, which locate its numbers in the bytes; each tick writes the new
    numbers there through numpy views and the node publishes the bytes as they are. The
    constructor checks the refill against rclpy's own serialization of test values.

    Parameters
    ----------
    joint_names : sequence of str
        ``Model.joint_names``.
    closure_names : sequence of str
        ``Model.closure_names``.

    Raises
    ------
    WireLayoutError
        rclpy's serialization of a message differs from this class's refill of it.
    """

    def __init__(self, joint_names: Sequence[str], closure_names: Sequence[str]):
        n, k = len(joint_names), len(closure_names)
        m = TickMessages(joint_names, closure_names)
        q, qd, effort = _sentinels(n, 0), _sentinels(n, n), _sentinels(n, 2 * n)
        self.joint = _Buffer(serialize_message(m.fill_joint_state(0.0, q, qd, effort)))
        self._q = self.joint.view(self.joint.find(q), n)
        self._qd = self.joint.view(self.joint.find(qd), n)
        self._effort = self.joint.view(self.joint.find(effort), n)
        forces = _sentinels(3 * k, 3 * n).reshape(k, 3)
        self.forces = _Buffer(serialize_message(m.fill_constraint_forces(forces)))
        self._forces = self.forces.view(self.forces.find(forces.reshape(-1)), 3 * k).reshape(k, 3)
        energy = _sentinels(4, 3 * n + 3 * k)
        self.energy = _Buffer(serialize_message(m.fill_energy(energy)))
        self._energy = self.energy.view(self.energy.find(energy), 4)
        self.wrenches, self._linear, self._torque = [], [], []
        for i, force in enumerate(forces):
            w = _Buffer(serialize_message(m.fill_wrench(i, force, 0.0)))
            self.wrenches.append(w)
            self._linear.append(w.view(w.find(force[:2]), 2))
            self._torque.append(w.view(w.find(force[2:]), 1))
        self.clock = _Buffer(serialize_message(m.fill_clock(0.0)))
        self._stamped = [self.joint, *self.wrenches, self.clock]
        self._ns: int | None = None
        self._check(m, n, k)

    def _check(self, m: TickMessages, n: int, k: int) -> None:
        """Refill with test values and compare with rclpy's serialization of the same."""
        rng = np.random.default_rng(7)
        t = 1234.5678901
        q, qd, effort, energy = (rng.normal(size=n), rng.normal(size=n), rng.normal(size=n),
                                 rng.normal(size=4))
        forces = rng.normal(size=(k, 3))
        pairs = [(self.joint_state(t, q, qd, effort), m.fill_joint_state(t, q, qd, effort)),
                 (self.constraint_forces(forces), m.fill_constraint_forces(forces)),
                 (self.energy_values(energy), m.fill_energy(energy)),
                 (self.clock_at(t), m.fill_clock(t))]
        pairs += [(self.wrench(i, forces[i], t), m.fill_wrench(i, forces[i], t))
                  for i in range(k)]
        for raw, msg in pairs:
            # padding bytes are not part of the contract (rclpy leaves them uninitialized):
            # same length, and the same message when read back
            if (len(raw) != len(serialize_message(msg))
                    or deserialize_message(raw, type(msg)) != msg):
                raise WireLayoutError(
                    f"{type(msg).__name__}: refilled bytes do not read back as rclpy's message")
        self._ns = None

    def set_time(self, t: float) -> None:
        """Stamp every message with simulated time ``t``, s (rounded to the nanosecond)."""
        ns = layouts.seconds_to_ns(t)
        if ns != self._ns:
            self._ns = ns
            sec, nanosec = divmod(ns, 1_000_000_000)
            for buf in self._stamped:
                _STAMP.pack_into(buf.data, STAMP_OFFSET, sec, nanosec)

    def joint_state(self, t: float, q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> bytes:
        """Serialized ``joint_states`` (as :func:`~vjm_ros.ros.conversions.joint_state`;
        t in s, q, qd, effort shape (n,))."""
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

    Built as rclpy messages (:func:`~vjm_ros.ros.conversions.markers`: a ``Point`` object per
    point) and serialized by ``publish``, the markers of three_chain with its tip traces (205
    points) took 1.4 ms of the tick loop, longer than a tick at 1 kHz: at 30 Hz the loop was
    late some 30 times a second. The message keeps its layout while the markers keep their
    kinds and point counts (the tip traces have a constant length,
    :class:`~vjm_ros.ros.conversions.TipTrace`); this class writes the template once per layout
    with the logs' encoder (:func:`vjm_ros.logs.cdr.markers_layout`, checked against rosbags
    byte for byte) and then only the stamps and the points.

    Parameters
    ----------
    force_scale : float
        Length of the constraint-force arrows, m/N.
    """

    def __init__(self, force_scale: float = layouts.FORCE_SCALE):
        self.force_scale = float(force_scale)
        self._key: tuple | None = None
        self._layout: cdr.FixedLayout | None = None

    def markers(self, sample, t: float, trace: Sequence[np.ndarray] = ()) -> bytes:
        """Serialized ``visualization_msgs/MarkerArray`` of ``sample`` stamped ``t`` (s), with the
        tip traces ``trace`` (as :func:`~vjm_ros.ros.conversions.markers`)."""
        specs = layouts.marker_specs(sample, self.force_scale, trace=trace)
        key = tuple((ns, i, kind, len(points), scale, rgba)
                    for ns, i, kind, points, scale, rgba in specs)
        if key != self._key:
            self._layout = cdr.markers_layout(
                layouts.markers(sample, 0, self.force_scale, trace=trace))
            self._key = key
        layout = self._layout
        data = bytearray(layout.template)
        sec, nanosec = divmod(layouts.seconds_to_ns(t), 1_000_000_000)
        for at in layout.stamps:
            _STAMP.pack_into(data, at, sec, nanosec)
        out = np.frombuffer(data, dtype=np.uint8)
        for (start, count), spec in zip(layout.arrays, specs, strict=True):
            xyz = out[start : start + 8 * count].view("<f8").reshape(-1, 3)
            xyz[:, :2] = spec[3]  # z stays 0.0, as in the template
        return bytes(data)
