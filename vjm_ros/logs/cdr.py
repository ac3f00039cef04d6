"""CDR (XCDR1, little endian) encoding of the messages the logs and the node carry.

Each message of every tick (``JointState``, the two ``Float64MultiArray``, ``WrenchStamped``,
``Clock`` and the decimated ``MarkerArray``) has one byte layout here, a :class:`FixedLayout`
written by :class:`CdrWriter`: its bytes with zero stamps and numbers and the offsets of both.
The node refills a copy of it in place (:class:`vjm_ros.ros.wire.TickWire`,
:class:`vjm_ros.ros.wire.MarkerWire`, published as bytes), the recorder packs one message
(:attr:`FixedLayout.packer`, behind :func:`joint_state_encoder` and its siblings) or a whole
block (:mod:`vjm_ros.logs.mcap_block`); the events' ``String`` is :func:`encode_string`.
Measured here in one run (``pytest -m bench test/bench_logging.py``): a JointState of three
joints costs 1.7 us on its fast path against 12-14 us through rosbags' schema-driven serializer
from the dict, a WrenchStamped 0.4 us against 12-17 us, the four-bar's MarkerArray 29 us
against 140-155 us. test/test_cdr_rosbags.py checks every layout against rosbags and rclpy
byte for byte. CDR layout, for reading the code: every
primitive is aligned to its size, counted from the end of the 4-byte encapsulation header;
strings are a ``uint32`` length that counts the terminating NUL, then the bytes and the NUL;
sequences are a ``uint32`` count, then the elements.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Callable, Sequence
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


def _floats(values) -> list[float]:
    """``values`` (array-like of numbers) as a list of Python floats."""
    return np.asarray(values, dtype=np.float64).tolist()


@dataclass(frozen=True)
class FixedLayout:
    """The one byte layout of a per-tick message: its bytes with zero stamps and numbers, and
    where the stamps and numbers go. The node refills a copy in place
    (:class:`vjm_ros.ros.wire.TickWire`), the logs pack one message (:attr:`packer`) or many at once
    (:mod:`vjm_ros.logs.mcap_block`).

    Attributes
    ----------
    template : bytes
        The message (encapsulation header included) with stamps 0 and every number 0.0.
    stamps : tuple of int
        Byte offsets of the header stamps (``int32`` sec, ``uint32`` nanosec), all of which
        carry the message's time.
    arrays : tuple of (int, int)
        ``(byte offset, count)`` of each run of ``float64`` values, in the order of the
        per-message encoder's arguments.
    """

    template: bytes
    stamps: tuple[int, ...]
    arrays: tuple[tuple[int, int], ...]

    @functools.cached_property
    def packer(self) -> tuple[struct.Struct, tuple[bytes, ...]]:
        """The whole message as one ``struct`` and its constant pieces, for one-call encoders.

        The format holds, in byte order, a constant piece (``s``), a stamp (``iI``) or a run
        (``d`` per value), ..., a last constant piece: ``pack(c0, sec, nanosec, c1, *run, ...)``
        with ``c0, c1, ...`` the pieces returned writes the message. The stamps come before the
        runs in every layout built here but :func:`markers_layout`'s (refilled in place).
        """
        fields = sorted([(at, 8, "iI") for at in self.stamps]
                        + [(offset, 8 * count, f"{count}d") for offset, count in self.arrays])
        fmt, pieces, pos = "<", [], 0
        for at, size, code in fields:
            pieces.append(self.template[pos:at])
            fmt += f"{at - pos}s{code}"
            pos = at + size
        pieces.append(self.template[pos:])
        return struct.Struct(fmt + f"{len(self.template) - pos}s"), tuple(pieces)


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


def joint_state_encoder(
    names: Sequence[str], frame_id: str = "world"
) -> Callable[[int, np.ndarray, np.ndarray, np.ndarray], bytes]:
    """Encoder of ``sensor_msgs/JointState`` messages for a fixed list of joints
    (:func:`joint_state_layout`).

    Parameters
    ----------
    names : sequence of str
        Joint names (their number fixes the array lengths).
    frame_id : str

    Returns
    -------
    callable
        ``f(ns, position, velocity, effort) -> bytes`` with arrays of shape (len(names),); the
        result equals :func:`encode` of the corresponding dict.
    """
    packer, pieces = joint_state_layout(names, frame_id).packer
    pack = packer.pack
    if not names:
        c0, c1 = pieces
        return lambda ns, position, velocity, effort: pack(c0, *divmod(int(ns), NS_PER_S), c1)
    c0, c1, c2, c3, c4 = pieces

    def encode_joint_state(ns: int, position, velocity, effort) -> bytes:
        sec, nanosec = divmod(int(ns), NS_PER_S)
        # Python floats: struct takes them several times faster than numpy's scalars
        return pack(c0, sec, nanosec, c1, *_floats(position), c2, *_floats(velocity), c3,
                    *_floats(effort), c4)

    return encode_joint_state


def multi_array_encoder(layout: dict, size: int) -> Callable[[np.ndarray], bytes]:
    """Encoder of ``std_msgs/Float64MultiArray`` messages with a fixed layout and length
    (:func:`multi_array_layout`).

    Returns
    -------
    callable
        ``f(data) -> bytes`` with ``data`` of shape (size,).
    """
    fixed = multi_array_layout(layout, size)
    if not size:
        return lambda data: fixed.template
    packer, (c0, c1) = fixed.packer
    pack = packer.pack
    return lambda data: pack(c0, *_floats(data), c1)


def wrench_stamped_encoder(frame_id: str = "world") -> Callable[[int, float, float, float], bytes]:
    """Encoder of planar ``geometry_msgs/WrenchStamped`` messages (:func:`wrench_stamped_layout`).

    Returns
    -------
    callable
        ``f(ns, fx, fy, mz) -> bytes``: force ``(fx, fy, 0)`` N, torque ``(0, 0, mz)`` N m.
    """
    packer, (c0, c1, c2, c3) = wrench_stamped_layout(frame_id).packer
    pack = packer.pack

    def encode_wrench(ns: int, fx: float, fy: float, mz: float) -> bytes:
        sec, nanosec = divmod(int(ns), NS_PER_S)
        return pack(c0, sec, nanosec, c1, fx, fy, c2, mz, c3)

    return encode_wrench


_CLOCK = CLOCK_LAYOUT.packer[0].pack
_CLOCK_PIECES = CLOCK_LAYOUT.packer[1]


def encode_string(text: str) -> bytes:
    """``std_msgs/String`` holding ``text`` (the events)."""
    w = CdrWriter()
    w.string(text)
    return w.getvalue()


def encode_clock(ns: int) -> bytes:
    """``rosgraph_msgs/Clock`` at ``ns`` nanoseconds (:data:`CLOCK_LAYOUT`)."""
    sec, nanosec = divmod(int(ns), NS_PER_S)
    return _CLOCK(_CLOCK_PIECES[0], sec, nanosec, _CLOCK_PIECES[1])


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
