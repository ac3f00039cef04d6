"""Effort commands read from their serialized bytes (CDR), without building rclpy messages.

The node takes the messages of its two command subscriptions raw (``raw=True``): on a slow
machine rclpy's take of a typed ``std_msgs/Float64MultiArray`` cost 29 µs against 7 µs for its
bytes, and at 1 kHz with a controller in the loop every tick takes one command. This module reads
what the node uses of the two command types:

* ``std_msgs/Float64MultiArray``: ``data`` (the layout is skipped: the node never used it);
* ``sensor_msgs/JointState``: ``name`` and ``effort`` (header, positions and velocities skipped).

The bytes are plain CDR (XCDR1) as ROS 2 middlewares write them: a 4-byte encapsulation header
(``00 01`` little-endian, ``00 00`` big-endian, then two option bytes), then the fields, each
aligned to its size counted from the end of the header. Bytes that do not hold such a message
raise :class:`MalformedCommand` naming the message type, the field and the byte offset.
test/test_command_wire.py checks the reading against rclpy's own serialization.

Reading costs time per element (a layout dimension, a name): a valid message of 200 000 empty
layout dimensions (3.2 MB) took 0.8-1.0 s on a loaded 2-core machine, on the tick loop's
thread. Given the scene's
:class:`~vjm_ros.realtime.commands.SizeBounds`, each sequence's and string's length (the count at
its head) is compared with its bound before any element is read, and a longer one raises
:class:`OversizeCommand` (test/test_command_bounds.py).
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from vjm_ros.realtime.commands import CommandBuffer, SizeBounds, Verdict

_ORDERS = {b"\x00\x00": ">", b"\x00\x01": "<"}
"""Byte order of each plain-CDR encapsulation identifier (CDR_BE, CDR_LE)."""
_HEADER = 4
"""Bytes of the encapsulation header; alignment counts from its end."""
_U32 = {order: struct.Struct(order + "I") for order in _ORDERS.values()}


class MalformedCommand(ValueError):
    """Bytes that do not hold the command message expected."""


class OversizeCommand(ValueError):
    """A command message with a field longer than the scene can need (refused unread)."""


_UNBOUNDED = 1 << 32
"""A bound no CDR length (a uint32) exceeds."""


class _Reader:
    """Reads aligned CDR fields from ``data`` (one message of ``type_name``)."""

    __slots__ = ("data", "pos", "order", "type_name", "_u32")

    def __init__(self, data: bytes, type_name: str):
        self.data = data
        self.type_name = type_name
        order = _ORDERS.get(bytes(data[:2])) if len(data) >= _HEADER else None
        if order is None:
            raise MalformedCommand(
                f"{type_name}: expected a plain CDR encapsulation header (00 00 or 00 01) at "
                f"byte 0, found {bytes(data[:4]).hex(' ') or 'no bytes'}")
        self.order = order
        self._u32 = _U32[order]
        self.pos = _HEADER

    def _need(self, size: int, field: str) -> None:
        if self.pos + size > len(self.data):
            raise MalformedCommand(
                f"{self.type_name}: {field} needs {size} bytes at byte {self.pos}, the message "
                f"has {len(self.data)}")

    def _align(self, size: int) -> None:
        self.pos += -(self.pos - _HEADER) % size

    def uint32(self, field: str) -> int:
        self._align(4)
        self._need(4, field)
        (value,) = self._u32.unpack_from(self.data, self.pos)
        self.pos += 4
        return value

    def skip(self, size: int, field: str) -> None:
        """Skip ``size`` bytes aligned to ``size`` (a fixed-size field)."""
        self._align(size)
        self._need(size, field)
        self.pos += size

    def count(self, field: str, limit: int, what: str) -> int:
        """The length at the head of a sequence or string (``what``: its elements), at most
        ``limit``."""
        value = self.uint32(field)
        if value > limit:
            raise OversizeCommand(
                f"{self.type_name}: {field} holds {value} {what}, more than the {limit} a command "
                "to this scene can need (refused unread)")
        return value

    def text_length(self, field: str, limit: int) -> int:
        """The length at the head of a string (with its terminating NUL), whose text is at most
        ``limit`` bytes."""
        length = self.uint32(field)
        if length > limit + 1:
            raise OversizeCommand(
                f"{self.type_name}: {field} holds {length - 1} bytes, more than the {limit} a "
                "command to this scene can need (refused unread)")
        return length

    def string(self, field: str, limit: int = _UNBOUNDED) -> str:
        """A string of at most ``limit`` UTF-8 bytes."""
        length = self.text_length(field, limit)  # with the terminating NUL
        self._need(length, field)
        raw = self.data[self.pos : self.pos + length]
        if length == 0 or raw[-1] != 0:
            raise MalformedCommand(
                f"{self.type_name}: {field} at byte {self.pos} is not a NUL-terminated string")
        self.pos += length
        try:
            return bytes(raw[:-1]).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise MalformedCommand(f"{self.type_name}: {field} is not UTF-8 ({exc})") from None

    def skip_string(self, field: str, limit: int = _UNBOUNDED) -> None:
        length = self.text_length(field, limit)
        self._need(length, field)
        self.pos += length

    def float64s(self, field: str, limit: int = _UNBOUNDED) -> np.ndarray:
        """A ``float64[]`` sequence of at most ``limit`` values, native byte order, shape
        (count,)."""
        count = self.count(field, limit, "values")
        if count == 0:
            return np.empty(0)
        self._align(8)
        self._need(8 * count, field)
        values = np.frombuffer(self.data, dtype=self.order + "f8", count=count, offset=self.pos)
        self.pos += 8 * count
        return values.astype(float)  # a copy: the bytes are the middleware's, native order

    def skip_float64s(self, field: str) -> None:
        count = self.uint32(field)
        if count:
            self._align(8)
            self._need(8 * count, field)
            self.pos += 8 * count


def multi_array_values(data: bytes, bounds: SizeBounds | None = None) -> np.ndarray:
    """``data`` of a serialized ``std_msgs/Float64MultiArray``.

    Parameters
    ----------
    data : bytes
        The CDR-serialized message.
    bounds : SizeBounds, optional
        The largest layout (``dims``, ``label_bytes``) and ``data`` (``values``) read; None:
        any.

    Returns
    -------
    ndarray, shape (m,)
        The values (N m or N for an effort command).

    Raises
    ------
    MalformedCommand
    OversizeCommand
        A field beyond ``bounds``, before any of its elements is read.
    """
    r = _Reader(data, "std_msgs/Float64MultiArray")
    dims, labels, values = ((bounds.dims, bounds.label_bytes, bounds.values) if bounds is not None
                            else (_UNBOUNDED, _UNBOUNDED, _UNBOUNDED))
    for _ in range(r.count("layout.dim", dims, "dimensions")):
        r.skip_string("layout.dim.label", labels)
        r.uint32("layout.dim.size")
        r.uint32("layout.dim.stride")
    r.uint32("layout.data_offset")
    return r.float64s("data", values)


def joint_state_efforts(data: bytes,
                        bounds: SizeBounds | None = None) -> tuple[list[str], np.ndarray]:
    """``name`` and ``effort`` of a serialized ``sensor_msgs/JointState`` (``data``, the bytes
    a ``raw=True`` subscription takes), as ``(names, efforts)``: a list of str and an array of
    shape (m,), N m or N, of any length (the command buffer judges it against the names).

    ``bounds`` (optional) limits ``name`` (``names``, ``name_bytes``) and ``effort``
    (``values``). Raises :class:`MalformedCommand`, or :class:`OversizeCommand` for a field
    beyond ``bounds`` before any of its elements is read."""
    r = _Reader(data, "sensor_msgs/JointState")
    names_, name_bytes, values = ((bounds.names, bounds.name_bytes, bounds.values)
                                  if bounds is not None else (_UNBOUNDED, _UNBOUNDED, _UNBOUNDED))
    r.skip(4, "header.stamp.sec")
    r.skip(4, "header.stamp.nanosec")
    r.skip_string("header.frame_id")
    names = [r.string("name", name_bytes) for _ in range(r.count("name", names_, "names"))]
    r.skip_float64s("position")
    r.skip_float64s("velocity")
    return names, r.float64s("effort", values)


def submit_effort_bytes(commands: CommandBuffer, data: bytes) -> Verdict:
    """Read a serialized ``~/effort_commands`` message within ``commands.size_bounds`` and offer
    it to ``commands``; bytes refused unread or unreadable are counted there
    (:meth:`~vjm_ros.realtime.commands.CommandBuffer.refuse_oversize`, ``refuse_malformed``)."""
    try:
        return commands.submit_array(multi_array_values(data, commands.size_bounds))
    except OversizeCommand as exc:
        return commands.refuse_oversize(str(exc))
    except MalformedCommand as exc:
        return commands.refuse_malformed(str(exc))


def submit_joint_command_bytes(commands: CommandBuffer, data: bytes) -> Verdict:
    """:func:`submit_effort_bytes` for a serialized ``~/joint_commands`` message
    (``sensor_msgs/JointState``: efforts by name)."""
    try:
        return commands.submit_named(*joint_state_efforts(data, commands.size_bounds))
    except OversizeCommand as exc:
        return commands.refuse_oversize(str(exc))
    except MalformedCommand as exc:
        return commands.refuse_malformed(str(exc))
