"""The per-tick messages of a whole block of ticks as MCAP records, built and indexed in bulk.

The messages of one topic at every tick have fixed layouts whose bytes differ only in numbers
(:class:`vjm_ros.logs.cdr.FixedLayout`): a block's records are written as rows of one byte image
per tick (``/joint_states``, ``constraint_forces``, each ``closures/<name>/wrench``, ``energy``,
``/clock``, in that order) with the sequence numbers, times, stamps and values written column by
column, plus the ``markers`` record after the other messages of every ``marker_every``-th tick.
The bytes are those rosbags' serializer writes (test/test_log_blocks.py).

:class:`BlockWriter` is the ``mcap`` writer (1.6, pinned) taking such runs of records: its chunk
builder copies them into one buffer kept for the whole file and keeps the message indexes as runs
of arrays; each chunk is written with its indexes in one call to the file. Statistics and indexes
are those the writer keeps for messages added one by one. The encoder, too, writes every block
into buffers it keeps, in place: a long run allocates no memory per block (fresh pages cost the
operating system a fault and a clearing each).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import zstandard
from mcap._chunk_builder import ChunkBuilder
from mcap.opcode import Opcode
from mcap.records import ChunkIndex, Message
from mcap.writer import CompressionType, IndexType, Writer

from vjm_ros.logs import cdr, messages

if TYPE_CHECKING:
    from mcap.data_stream import RecordBuilder

    from vjm_ros.core.model import Model
    from vjm_ros.sim.samples import SampleBlock

RECORD_HEADER = struct.Struct("<BQHIQQ")
"""Opcode, record length, channel id, sequence, log time, publish time of a Message record."""
_SEQUENCE, _LOG_TIME, _PUBLISH_TIME = 11, 15, 23
"""Byte offsets of the sequence and the two times in a Message record."""
NS_PER_S = 1_000_000_000


class BulkIndex:
    """Message index of one channel in the open chunk: runs of log times and chunk offsets."""

    def __init__(self, channel_id: int):
        self.channel_id = channel_id
        self.runs: list[tuple] = []
        self.count = 0

    def add(self, times: Sequence[int] | np.ndarray, offsets: Sequence[int] | np.ndarray,
            shift: int = 0) -> None:
        """Entries of messages at ``times`` (ns) and chunk offsets ``offsets + shift`` (bytes),
        in file order (arrays or sequences of int, kept until :meth:`record`)."""
        self.runs.append((times, offsets, shift))
        self.count += len(times)

    def record(self) -> bytes:
        """The MessageIndex record, as :class:`mcap.records.MessageIndex` writes it."""
        entries = np.empty((self.count, 2), dtype="<u8")
        at = 0
        for times, offsets, shift in self.runs:
            n = len(times)
            entries[at : at + n, 0] = times
            entries[at : at + n, 1] = offsets
            if shift:
                entries[at : at + n, 1] += shift
            at += n
        return MESSAGE_INDEX_HEADER.pack(Opcode.MESSAGE_INDEX, 6 + entries.nbytes,
                                         self.channel_id, entries.nbytes) + entries.tobytes()

    def write(self, stream: RecordBuilder) -> None:
        """Write :meth:`record` to ``stream`` (the ``mcap`` writer's record builder)."""
        stream.write(self.record())


MESSAGE_INDEX_HEADER = struct.Struct("<BQHI")
"""Opcode, record length, channel id and byte length of the entries of a MessageIndex record."""
CHUNK_HEADER = struct.Struct("<BQQQQI")
"""Opcode, record length, message start and end times, uncompressed size and CRC of a Chunk."""


class BlockChunkBuilder(ChunkBuilder):
    """The ``mcap`` chunk builder taking runs of records, copied into one buffer kept for the
    whole file (so a chunk's records are never joined from pieces, nor written into fresh
    memory), with message indexes kept as runs of arrays."""

    def __init__(self) -> None:
        super().__init__()
        self.buffer = bytearray(1 << 16)
        self.size = 0

    @property
    def count(self) -> int:
        return self.size + self.record_writer.count

    def _append(self, data) -> None:
        """Copy ``data`` (bytes-like) to the end of the chunk's records."""
        end = self.size + len(data)
        if end > len(self.buffer):
            grown = bytearray(max(end, 2 * len(self.buffer)))
            grown[: self.size] = memoryview(self.buffer)[: self.size]
            self.buffer = grown
        memoryview(self.buffer)[self.size : end] = data
        self.size = end

    def reserve(self, size: int) -> None:
        """Hold at least ``size`` bytes of records without growing (the buffer's pages are
        written once, now)."""
        if size > len(self.buffer):
            grown = bytearray(size)  # zero-filled: every page mapped here
            grown[: self.size] = memoryview(self.buffer)[: self.size]
            self.buffer = grown

    def _take_records(self) -> None:
        """Move what the records writer holds (schemas, channels, single messages) to the
        buffer."""
        if self.record_writer.count:
            self._append(self.record_writer.end())

    def add_message(self, message: Message) -> None:
        offset = self.count
        message.write(self.record_writer)
        self._span(message.log_time, message.log_time, 1)
        self._index(message.channel_id).add((message.log_time,), (offset,))

    def add_run(self, data: memoryview, times: np.ndarray, starts: np.ndarray,
                columns: Sequence[tuple[int, int]], markers: tuple | None) -> None:
        """Append the Message records ``data`` of ticks logged at ``times`` (ns, never
        decreasing), each tick's records starting at byte ``starts`` of ``data``, with one
        message per tick on each channel of ``columns`` (``(channel id, byte offset in the
        tick)``), then the ``markers`` ``(channel id, log times, offsets into data)``, if any."""
        self._take_records()
        base = self.size
        self._append(data)
        self._span(int(times[0]), int(times[-1]), len(times) * len(columns))
        for channel, at in columns:
            self._index(channel).add(times, starts, base + at)
        if markers is not None:
            channel, mtimes, offsets = markers
            self.num_messages += len(mtimes)
            self._index(channel).add(mtimes, offsets, base)

    def end(self) -> memoryview:
        """The chunk's records (a view of the buffer: valid until the next record is added)."""
        self._take_records()
        return memoryview(self.buffer)[: self.size]

    def reset(self) -> None:
        super().reset()
        self.size = 0

    def _span(self, lo: int, hi: int, count: int) -> None:
        """Count ``count`` messages logged from ``lo`` to ``hi`` (ns) in the chunk."""
        self.message_start_time = lo if self.num_messages == 0 else min(
            self.message_start_time, lo)
        self.message_end_time = max(self.message_end_time, hi)
        self.num_messages += count

    def _index(self, channel: int) -> BulkIndex:
        index = self.message_indices.get(channel)
        if index is None:
            index = self.message_indices[channel] = BulkIndex(channel)
        return index


ZSTD_LEVEL = -3
"""zstd level of the chunks: the C++ ``mcap`` writer's ``CompressionLevel::Fast`` (rosbag2's
MCAP storage writes level 1, its ``Default``, unless a preset asks for another). On the
four-bar's 10 s log (40 chunks, 7.3 MB before compression) the chunks compress in 3.4 ms against
5.0 ms at level 1 and 7.0 ms at the Python writer's level 3, and come to 1.37 MB against 1.28 MB
and 1.36 MB (the file: 2.2 MB with its indexes, 4 % more than at level 1). Every zstd reader
decompresses any level."""


class BlockWriter(Writer):
    """``mcap.writer.Writer`` that also takes runs of Message records (:meth:`add_records`) and
    compresses chunks with zstd at ``zstd_level`` (a compressor kept for the whole file).

    Reaches into the writer's private statistics and chunk state (``mcap`` 1.6.0, pinned in
    ``requirements/lock.txt``); the logs it writes are read back by rosbags and the ``mcap``
    reader in the tests, and at the writer's own level (3) the file is the writer's, byte for
    byte (test/test_mcap_compression.py).
    """

    def __init__(self, *args, zstd_level: int = ZSTD_LEVEL, **kwargs):
        super().__init__(*args, **kwargs)
        self._builder = BlockChunkBuilder()
        self._Writer__chunk_builder = self._builder
        self._zstd = zstandard.ZstdCompressor(level=zstd_level)

    def add_run(self, data: memoryview, times: np.ndarray, starts: np.ndarray,
                columns: Sequence[tuple[int, int]], markers: tuple | None) -> None:
        """Add a run of ticks' Message records to the open chunk (see
        :meth:`BlockChunkBuilder.add_run`); statistics as :meth:`add_message` keeps them; the
        chunk is closed when over its size."""
        stats = self._Writer__statistics
        lo, hi, ticks = int(times[0]), int(times[-1]), len(times)
        counts = stats.channel_message_counts
        for channel, _ in columns:
            counts[channel] += ticks
        added = ticks * len(columns)
        if markers is not None:
            counts[markers[0]] += len(markers[1])
            added += len(markers[1])
        stats.message_start_time = lo if stats.message_count == 0 else min(
            stats.message_start_time, lo)
        stats.message_end_time = max(stats.message_end_time, hi)
        stats.message_count += added
        self._builder.add_run(data, times, starts, columns, markers)
        self._Writer__maybe_finalize_chunk()

    def reserve(self, size: int) -> None:
        """Let the open chunk hold ``size`` bytes of records without growing."""
        self._builder.reserve(size)

    def _Writer__finalize_chunk(self) -> None:  # noqa: N802 - the writer's private name
        """The writer's ``__finalize_chunk`` with zstd at :attr:`zstd_level`: the chunk record,
        its chunk index and its message indexes, the bytes the writer writes, packed whole and
        handed to the file in one call."""
        builder = self._builder
        if builder.num_messages == 0:
            return
        self._Writer__statistics.chunk_count += 1
        chunk_data = builder.end()
        compression = self._Writer__compression
        if compression == CompressionType.ZSTD:
            name, compressed = "zstd", self._zstd.compress(chunk_data)
        elif compression == CompressionType.LZ4:
            import lz4.frame

            name, compressed = "lz4", lz4.frame.compress(chunk_data)
        else:
            name, compressed = "", chunk_data
        crc = zlib.crc32(chunk_data) if self._Writer__enable_crcs else 0
        label = name.encode()
        length = CHUNK_HEADER.size - 9 + 4 + len(label) + 8 + len(compressed)
        head = CHUNK_HEADER.pack(Opcode.CHUNK, length, builder.message_start_time,
                                 builder.message_end_time, len(chunk_data), crc)
        head += struct.pack("<I", len(label)) + label + struct.pack("<Q", len(compressed))
        self._Writer__flush()
        stream = self._Writer__stream
        chunk_start_offset = stream.tell()
        index_start = chunk_start_offset + 9 + length
        offsets: dict[int, int] = {}
        indexes: list[bytes] = []
        if self._Writer__index_types & IndexType.MESSAGE:
            at = index_start
            for channel, index in builder.message_indices.items():
                offsets[channel] = at
                indexes.append(index.record())
                at += len(indexes[-1])
        index_data = b"".join(indexes)
        self._write_data(b"".join((head, compressed, index_data)))  # one call to the OS
        self._Writer__chunk_indices.append(ChunkIndex(
            message_start_time=builder.message_start_time,
            message_end_time=builder.message_end_time,
            chunk_start_offset=chunk_start_offset,
            chunk_length=9 + length,
            message_index_offsets=offsets,
            message_index_length=len(index_data),
            compression=name,
            compressed_size=len(compressed),
            uncompressed_size=len(chunk_data),
        ))
        builder.reset()

    def _write_data(self, data) -> None:
        """Hand ``data`` to the file, as the writer's ``__flush`` does (with its data-section
        CRC when the writer keeps one)."""
        if self._Writer__enable_data_crcs:
            self._Writer__data_section_crc = zlib.crc32(data, self._Writer__data_section_crc)
        self._Writer__stream.write(data)


# ---------------------------------------------------------------- records of a block
def _put(rows: np.ndarray, at: int, dtype: str, values) -> None:
    """Write ``values`` (one per row) as ``dtype`` at byte ``at`` of every row."""
    rows[:, at : at + np.dtype(dtype).itemsize].view(dtype)[:, 0] = values


class _Kind:
    """Records of one topic for many ticks: one byte image and where its numbers go."""

    def __init__(self, channel: int, layout: cdr.FixedLayout):
        self.channel = channel
        self.layout = layout
        head = RECORD_HEADER.pack(Opcode.MESSAGE, RECORD_HEADER.size - 9 + len(layout.template),
                                  channel, 0, 0, 0)
        self.image = np.frombuffer(head + layout.template, dtype=np.uint8)

    def fill(self, rows: np.ndarray, at: int, seq, ns, sec, nsec, values: Sequence) -> None:
        """Write the numbers of one record per row at byte ``at`` of ``rows`` (T, ...).

        ``values`` holds one array (T, count) per float64 run of the layout.
        """
        _put(rows, at + _SEQUENCE, "<u4", seq)
        _put(rows, at + _LOG_TIME, "<u8", ns)
        _put(rows, at + _PUBLISH_TIME, "<u8", ns)
        body = at + RECORD_HEADER.size
        for stamp in self.layout.stamps:
            _put(rows, body + stamp, "<i4", sec)
            _put(rows, body + stamp + 4, "<u4", nsec)
        for (offset, count), v in zip(self.layout.arrays, values, strict=True):
            start = body + offset
            rows[:, start : start + 8 * count].view("<f8")[:] = v


def _xyz(points: np.ndarray) -> np.ndarray:
    """Planar points (G, m, 2) as ``x, y, 0`` runs (G, 3 m)."""
    out = np.zeros(points.shape[:2] + (3,))
    out[..., :2] = points
    return out.reshape(len(points), -1)


class BlockEncoder:
    """Message records of the per-tick topics (and markers) for whole blocks of ticks.

    Parameters
    ----------
    model : Model
    channels : dict
        Channel id per topic name.
    topics : messages.Topics
    marker_every : int
        Markers on samples whose count is a multiple of it (0: none).
    force_scale : float
        Length of the constraint-force arrows, m/N.
    measured : bool
        The blocks carry sensor measurements: ``/joint_states`` from them, followed by the
        exact state on ``/<node>/ground_truth/joint_states``.
    """

    def __init__(self, model: Model, channels: dict[str, int], topics: messages.Topics,
                 marker_every: int, force_scale: float, measured: bool = False):
        k = len(model.force_names)
        self.force_scale = float(force_scale)
        self.marker_every = int(marker_every)
        self.measured = bool(measured)
        joints = cdr.joint_state_layout(model.joint_names, messages.FRAME_ID)
        self.kinds = [_Kind(channels[topics.joint_states], joints)]
        if self.measured:
            self.kinds.append(_Kind(channels[topics.ground_truth_joint_states], joints))
        self.kinds += [
            _Kind(channels[topics.constraint_forces], cdr.multi_array_layout(
                messages.labelled_layout(model.force_names, len(messages.FORCE_COMPONENTS)),
                3 * k)),
        ]
        wrench = cdr.wrench_stamped_layout(messages.FRAME_ID)
        self.kinds += [_Kind(channels[topics.wrench(name)], wrench)
                       for name in model.force_names]
        self.kinds += [
            _Kind(channels[topics.energy], cdr.multi_array_layout(
                messages.labelled_layout(messages.ENERGY_LABELS, 1),
                len(messages.ENERGY_LABELS))),
            _Kind(channels[topics.clock], cdr.CLOCK_LAYOUT),
        ]
        self.starts = np.cumsum([0] + [len(kd.image) for kd in self.kinds])
        self.image = np.concatenate([kd.image for kd in self.kinds])
        self.columns = [(kd.channel, int(at)) for kd, at in zip(self.kinds, self.starts,
                                                                strict=False)]
        """Channel id and byte offset in a tick's records of each per-tick message."""
        self.marker_channel = channels.get(topics.markers)
        self.markers: _Kind | None = None  # from the first block's geometry
        self._table = np.empty(0, dtype=np.uint8)
        self._out = np.empty(0, dtype=np.uint8)

    def block_bytes(self, rows: int) -> int:
        """Bytes of the records of a block of ``rows`` ticks, markers included (an upper bound
        before the first markers are laid out: each as large as a tick's other records)."""
        marker = len(self.markers.image) if self.markers is not None else len(self.image)
        marked = -(-rows // self.marker_every) + 1 if self.marker_every > 0 else 0
        return rows * len(self.image) + marked * marker

    def reserve(self, rows: int) -> None:
        """Buffers for blocks of ``rows`` ticks, their pages touched now."""
        size = rows * len(self.image)
        if len(self._table) < size:
            self._table = np.zeros(size, dtype=np.uint8)
            self._table.fill(0)  # np.zeros maps its pages only when first written
        total = self.block_bytes(rows)
        if len(self._out) < total:
            self._out = np.zeros(total, dtype=np.uint8)
            self._out.fill(0)

    def _values(self, block, rows: int) -> list[list[np.ndarray]]:
        """The float64 runs of each per-tick record, in the order of :attr:`kinds`."""
        force = block.force[:rows]
        effort = (block.effort[:rows] if block.effort.ndim == 2  # one row per tick
                  else np.broadcast_to(block.effort, block.q[:rows].shape))
        values = [[block.q[:rows], block.qd[:rows], effort]]
        if self.measured:
            m = block.measured[:rows]
            values.insert(0, [m[:, 0], m[:, 1], m[:, 2]])
        values.append([force.reshape(rows, -1)] if force.shape[1] else [])
        values += [[force[:, j, :2], force[:, j, 2:]] for j in range(force.shape[1])]
        return values + [[block.energy[:rows]], []]

    def _marker_values(self, block, ticks: np.ndarray) -> list[np.ndarray]:
        """Points of the markers (links, joints, one arrow per closure) at ``ticks``, as
        :func:`vjm_ros.logs.messages.marker_specs` draws them."""
        seg = block.segments[ticks]
        g = len(ticks)
        joints = np.concatenate((seg[:, :, 0, :], block.points[ticks].reshape(g, -1, 2)), axis=1)
        out = [_xyz(seg.reshape(g, -1, 2)), _xyz(joints)]
        cp, f = block.cpoints[ticks], block.force[ticks]
        for j in range(cp.shape[1]):
            arrow = np.stack((cp[:, j], cp[:, j] + self.force_scale * f[:, j, :2]), axis=1)
            out.append(_xyz(arrow))
        return out

    def encode(self, block: SampleBlock, ns: np.ndarray, first: int) -> EncodedBlock:
        """Records of the block's rows (``len(ns)``) logged at ``ns`` (ns), the first being
        sample number ``first`` of the recording (valid until the next call: the records are
        written into buffers the encoder keeps)."""
        rows = len(ns)
        seq = (first + np.arange(rows)) & 0xFFFFFFFF
        sec, nsec = np.divmod(ns, NS_PER_S)
        size = len(self.image)
        self._table = _at_least(self._table, rows * size)
        table = self._table[: rows * size].reshape(rows, size)
        table[:] = self.image
        for kind, start, values in zip(self.kinds, self.starts, self._values(block, rows),
                                       strict=False):
            kind.fill(table, int(start), seq, ns, sec, nsec, values)
        ticks = np.arange(rows)
        marked = (np.nonzero((first + ticks) % self.marker_every == 0)[0]
                  if self.marker_every > 0 else ticks[:0])
        tick_starts = np.empty(rows + 1, dtype=np.int64)
        if len(marked) == 0:
            tick_starts[:-1] = ticks * size
            tick_starts[-1] = rows * size
            return EncodedBlock(table.reshape(-1), ns, tick_starts, self.columns,
                                self.marker_channel, marked, size)
        mrows = self._marker_rows(block, marked, seq, ns, sec, nsec)
        msize = mrows.shape[1]
        tick_starts[:-1] = ticks * size + np.searchsorted(marked, ticks) * msize
        tick_starts[-1] = rows * size + len(marked) * msize
        out = self._out = _at_least(self._out, int(tick_starts[-1]))
        # [ticks up to the first marked one][markers] [every ticks][markers] ... [the rest]
        prefix, every = int(marked[0]) + 1, self.marker_every
        groups = len(marked) - 1
        out[: prefix * size] = table[:prefix].reshape(-1)
        at = prefix * size
        out[at : at + msize] = mrows[0]
        at += msize
        period = every * size + msize
        region = out[at : at + groups * period].reshape(groups, period)
        region[:, : every * size] = table[prefix : prefix + groups * every].reshape(
            groups, every * size)
        region[:, every * size :] = mrows[1:]
        at += groups * period
        rest = prefix + groups * every
        out[at : at + (rows - rest) * size] = table[rest:].reshape(-1)
        return EncodedBlock(out[: int(tick_starts[-1])], ns, tick_starts, self.columns,
                            self.marker_channel, marked, size)

    def _marker_rows(self, block, marked, seq, ns, sec, nsec) -> np.ndarray:
        """Records of the markers at ticks ``marked`` (G, record size)."""
        if self.markers is None:  # every tick's markers have the first one's layout
            sample = block.sample(int(marked[0]))
            layout = cdr.markers_layout(messages.markers(sample, 0, self.force_scale))
            self.markers = _Kind(self.marker_channel, layout)
        kind = self.markers
        mrows = np.empty((len(marked), len(kind.image)), dtype=np.uint8)
        mrows[:] = kind.image
        values = self._marker_values(block, marked)
        kind.fill(mrows, 0, seq[marked], ns[marked], sec[marked], nsec[marked], values)
        return mrows


def _at_least(buffer: np.ndarray, size: int) -> np.ndarray:
    """``buffer`` if it holds ``size`` bytes, else a larger one (kept by the caller)."""
    return buffer if len(buffer) >= size else np.empty(max(size, 2 * len(buffer)), np.uint8)


class EncodedBlock:
    """The Message records of a block of ticks and where each message lies.

    Parameters
    ----------
    data : ndarray of uint8
        The records, tick after tick.
    ns : ndarray of int, shape (rows,)
        Log time of each tick, ns.
    tick_starts : ndarray of int, shape (rows + 1,)
        Byte offset where each tick's records start in ``data`` (and the end).
    columns : list of (int, int)
        Channel id and byte offset in its tick of each per-tick record, in order.
    marker_channel : int or None
    marked : ndarray of int
        Ticks that carry a markers record, right after their per-tick records.
    marker_at : int
        Byte offset of the markers record in its tick.
    """

    def __init__(self, data: np.ndarray, ns: np.ndarray, tick_starts: np.ndarray,
                 columns: list, marker_channel: int | None, marked: np.ndarray,
                 marker_at: int):
        self.data = memoryview(data)
        self.ns = ns
        self.tick_starts = tick_starts
        self.columns = columns
        self.marker_channel = marker_channel
        self.marked = marked
        self.marker_at = marker_at

    def run(self, start: int, stop: int) -> tuple:
        """The records of ticks ``start .. stop - 1`` as the arguments of
        :meth:`BlockWriter.add_run`: ``(records, log times, offsets of the ticks in the records,
        columns, markers)``, ``markers`` being ``(channel id, log times, offsets)`` or None."""
        lo = int(self.tick_starts[start])
        starts = self.tick_starts[start:stop] - lo
        first, last = np.searchsorted(self.marked, (start, stop))
        markers = None
        if last > first:
            ticks = self.marked[first:last]
            markers = (self.marker_channel, self.ns[ticks],
                       self.tick_starts[ticks] - lo + self.marker_at)
        return (self.data[lo : int(self.tick_starts[stop])], self.ns[start:stop], starts,
                self.columns, markers)
