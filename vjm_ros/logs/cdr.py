"""CDR (XCDR1, little endian) encoding of the messages the logs and the node carry.

Each message of every tick (``JointState``, the two ``Float64MultiArray``, ``WrenchStamped``,
``Clock`` and the decimated ``MarkerArray``) has one byte layout here, a :class:`FixedLayout`
written by :class:`CdrWriter`: its bytes with zero stamps and numbers and the offsets of both.
The node refills a copy of it in place (:class:`vjm_ros.ros.wire.TickWire`, published as
bytes); :meth:`FixedLayout.encode` writes one message (the node's markers, a log's first
sample), :mod:`vjm_ros.logs.mcap_block` a whole block of them; the events' ``String`` is
:func:`encode_string`. test/test_cdr_rosbags.py checks every layout against rosbags and rclpy
byte for byte. CDR layout, for reading the code: every
primitive is aligned to its size, counted from the end of the 4-byte encapsulation header;
strings are a ``uint32`` length that counts the terminating NUL, then the bytes and the NUL;
sequences are a ``uint32`` count, then the elements.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

_ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR_LE, no options
_U32 = struct.Struct("<I").pack
_I32 = struct.Struct("<i").pack
_F32X4 = struct.Struct("<4f").pack
_ZEROS = bytes(8)


# ---------------------------------------------------------------- markers, by hand
class CdrWriter:
    """Appends aligned CDR fields to a buffer that starts with the encapsulation header."""

    __slots__ = ("buf",)

    def __init__(self) -> None:
        self.buf = bytearray(_ENCAPSULATION)

    def align(self, size: int) -> None:
        """Pad with zeros so that the next field starts at a multiple of ``size``."""
        pad = -(len(self.buf) - 4) % size
        if pad:
            self.buf += _ZEROS[:pad]

    def uint32(self, value: int) -> None:
        """Write an unsigned 32-bit integer."""
        self.align(4)
        self.buf += _U32(value)

    def int32(self, value: int) -> None:
        """Write a signed 32-bit integer."""
        self.align(4)
        self.buf += _I32(value)

    def uint8(self, value: int) -> None:
        """Write one byte (also ``bool``)."""
        self.buf.append(int(value) & 0xFF)

    def float64s(self, values: Sequence[float]) -> None:
        """Write consecutive doubles (a fixed group of fields, e.g. ``x, y, z``)."""
        self.align(8)
        self.buf += struct.pack(f"<{len(values)}d", *values)

    def float32x4(self, values: Sequence[float]) -> None:
        """Write four floats (a ``ColorRGBA``)."""
        self.align(4)
        self.buf += _F32X4(*values)

    def string(self, value: str) -> None:
        """Write a string (length with the NUL, bytes, NUL)."""
        data = value.encode("utf-8")
        self.uint32(len(data) + 1)
        self.buf += data
        self.buf.append(0)

    def bytes_seq(self, values: bytes) -> None:
        """Write a ``uint8[]`` sequence."""
        self.uint32(len(values))
        self.buf += values

    def getvalue(self) -> bytes:
        """The encoded message."""
        return bytes(self.buf)


# ---------------------------------------------------------------- nested types
def _time(w: CdrWriter, t: dict) -> None:
    w.int32(t["sec"])
    w.uint32(t["nanosec"])


def _header(w: CdrWriter, h: dict) -> None:
    _time(w, h["stamp"])
    w.string(h["frame_id"])


def _xyz(w: CdrWriter, v: dict) -> None:
    w.float64s((v["x"], v["y"], v["z"]))


def _color(w: CdrWriter, c: dict) -> None:
    w.float32x4((c["r"], c["g"], c["b"], c["a"]))


def _marker(w: CdrWriter, m: dict, marks: list[int] | None = None) -> None:
    """One Marker; with ``marks``, append the byte offsets of its stamp and of its points."""
    if marks is not None:
        w.align(4)  # where the stamp's int32 goes (no padding beyond what it would write)
        marks.append(len(w.buf))
    _header(w, m["header"])
    w.string(m["ns"])
    w.int32(m["id"])
    w.int32(m["type"])
    w.int32(m["action"])
    pose = m["pose"]
    _xyz(w, pose["position"])
    q = pose["orientation"]
    w.float64s((q["x"], q["y"], q["z"], q["w"]))
    _xyz(w, m["scale"])
    _color(w, m["color"])
    _time(w, m["lifetime"])
    w.uint8(m["frame_locked"])
    points = m["points"]
    w.uint32(len(points))
    if marks is not None:
        if points:
            w.align(8)  # where the first point's float64 goes
        marks.append(len(w.buf))
    for p in points:
        _xyz(w, p)
    colors = m["colors"]
    w.uint32(len(colors))
    for c in colors:
        _color(w, c)
    w.string(m["texture_resource"])
    tex = m["texture"]
    _header(w, tex["header"])
    w.string(tex["format"])
    w.bytes_seq(bytes(tex["data"]))
    uv = m["uv_coordinates"]
    w.uint32(len(uv))
    for c in uv:
        w.align(4)
        w.buf += struct.pack("<2f", c["u"], c["v"])
    w.string(m["text"])
    w.string(m["mesh_resource"])
    mesh = m["mesh_file"]
    w.string(mesh["filename"])
    w.bytes_seq(bytes(mesh["data"]))
    w.uint8(m["mesh_use_embedded_materials"])


def encode_markers(message: dict) -> bytes:
    """``visualization_msgs/MarkerArray`` from its dict, hand-written for speed.

    Written every tenth tick of a recording; 5x faster than rosbags from the dict (29 us against
    140-155 us for the four-bar's markers, measured here in one run), and checked against rosbags byte
    for byte in test/test_cdr_rosbags.py.
    """
    return _marker_array(message).getvalue()


def _marker_array(message: dict, marks: list[int] | None = None) -> CdrWriter:
    """A ``MarkerArray`` written; with ``marks``, the offsets of :func:`_marker`."""
    w = CdrWriter()
    w.uint32(len(message["markers"]))
    for marker in message["markers"]:
        _marker(w, marker, marks)
    return w


# ---------------------------------------------------------------- fixed layouts
STAMP_OFFSET = len(_ENCAPSULATION)
"""Byte offset of the header stamp (``int32`` sec, ``uint32`` nanosec) in a stamped message."""
STAMP = struct.Struct("<iI")
"""``builtin_interfaces/Time`` as CDR: ``int32`` sec, ``uint32`` nanosec."""
NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class FixedLayout:
    """The one byte layout of a per-tick message: its bytes with zero stamps and numbers, and
    where the stamps and numbers go. The node refills a copy in place
    (:class:`vjm_ros.ros.wire.TickWire`); :meth:`encode` writes one message, and
    :mod:`vjm_ros.logs.mcap_block` many at once.

    Attributes
    ----------
    template : bytes
        The message (encapsulation header included) with stamps 0 and every number 0.0.
    stamps : tuple of int
        Byte offsets of the header stamps (``int32`` sec, ``uint32`` nanosec), all of which
        carry the message's time.
    arrays : tuple of (int, int)
        ``(byte offset, count)`` of each run of ``float64`` values, in the order of
        :meth:`encode`'s arguments.
    """

    template: bytes
    stamps: tuple[int, ...]
    arrays: tuple[tuple[int, int], ...]

    def encode(self, ns: int, *runs) -> bytes:
        """The message stamped ``ns`` (ns since the epoch of the run's clock) with the values of
        ``runs`` (one array-like per run of :attr:`arrays`, in order).

        One message at a time (the first sample of a log, the node's markers); many at once:
        :mod:`vjm_ros.logs.mcap_block`.
        """
        data = bytearray(self.template)
        sec, nanosec = divmod(int(ns), NS_PER_S)
        for at in self.stamps:
            STAMP.pack_into(data, at, sec, nanosec)
        out = np.frombuffer(data, dtype=np.uint8)
        for (offset, count), values in zip(self.arrays, runs, strict=True):
            out[offset : offset + 8 * count].view("<f8")[:] = np.ravel(values)
        return bytes(data)


def _stamped(w: CdrWriter, frame_id: str) -> list[int]:
    """Write a ``std_msgs/Header`` stamped 0; the offset of its stamp, as a list."""
    _header(w, {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": frame_id})
    return [STAMP_OFFSET]


def _float64_run(w: CdrWriter, count: int, arrays: list[tuple[int, int]],
                 align_empty: bool = False) -> None:
    """Write ``count`` zero doubles; note ``(offset, count)`` in ``arrays`` if any. An empty run
    is aligned only with ``align_empty`` (see :func:`multi_array_layout`)."""
    if count or align_empty:
        w.align(8)
    if count:
        arrays.append((len(w.buf), count))
        w.buf += bytes(8 * count)


def joint_state_layout(names: Sequence[str], frame_id: str = "world") -> FixedLayout:
    """``sensor_msgs/JointState`` for a fixed list of joints: runs position, velocity, effort
    (``len(names)`` each)."""
    w, arrays = CdrWriter(), []
    stamps = _stamped(w, frame_id)
    w.uint32(len(names))
    for name in names:
        w.string(name)
    for _ in range(3):
        w.uint32(len(names))
        _float64_run(w, len(names), arrays)
    return FixedLayout(w.getvalue(), tuple(stamps), tuple(arrays))


def multi_array_layout(layout: dict, size: int, align_empty: bool = False) -> FixedLayout:
    """``std_msgs/Float64MultiArray`` with the ``std_msgs/MultiArrayLayout`` ``layout``: one run
    of ``size`` values.

    With ``size`` 0 and ``align_empty``, the empty ``data`` is padded to 8 bytes as rclpy's
    serializer (Fast CDR) writes it; rosbags, and so the logs, do not pad it. Either reads
    back as the same message in both.
    """
    w, arrays = CdrWriter(), []
    w.uint32(len(layout["dim"]))
    for dim in layout["dim"]:
        w.string(dim["label"])
        w.uint32(dim["size"])
        w.uint32(dim["stride"])
    w.uint32(layout["data_offset"])
    w.uint32(size)
    _float64_run(w, size, arrays, align_empty)
    return FixedLayout(w.getvalue(), (), tuple(arrays))


def wrench_stamped_layout(frame_id: str = "world") -> FixedLayout:
    """Planar ``geometry_msgs/WrenchStamped``: runs ``(force.x, force.y)`` and ``(torque.z,)``
    (the zero ``force.z`` and ``torque.x, y`` between them stay as in the template)."""
    w, arrays = CdrWriter(), []
    stamps = _stamped(w, frame_id)
    _float64_run(w, 6, arrays)
    ((offset, _),) = arrays
    return FixedLayout(w.getvalue(), tuple(stamps), ((offset, 2), (offset + 5 * 8, 1)))


CLOCK_LAYOUT = FixedLayout(_ENCAPSULATION + bytes(8), (STAMP_OFFSET,), ())
"""``rosgraph_msgs/Clock``: its stamp only."""


def encode_string(text: str) -> bytes:
    """``std_msgs/String`` holding ``text`` (the events)."""
    w = CdrWriter()
    w.string(text)
    return w.getvalue()


def markers_layout(message: dict) -> FixedLayout:
    """:class:`FixedLayout` of a ``MarkerArray`` whose markers keep their count, strings and
    number of points: one stamp per marker and one run of ``3 m`` values (``x, y, z`` of ``m``
    points) per marker, in marker order.

    Parameters
    ----------
    message : dict
        A ``visualization_msgs/MarkerArray`` dict (e.g. :func:`vjm_ros.logs.messages.markers`);
        its stamps and points become zeros in the template.
    """
    marks: list[int] = []
    buf = bytearray(_marker_array(message, marks).getvalue())
    markers = message["markers"]
    stamps, arrays = tuple(marks[0::2]), []
    for marker, stamp, start in zip(markers, stamps, marks[1::2], strict=True):
        count = 3 * len(marker["points"])
        buf[stamp : stamp + 8] = bytes(8)
        buf[start : start + 8 * count] = bytes(8 * count)
        arrays.append((start, count))
    return FixedLayout(bytes(buf), stamps, tuple(arrays))
