"""The per-tick messages of a whole block of ticks as MCAP records, built and indexed in bulk.

The messages of one topic at every tick have fixed layouts whose bytes differ only in numbers
(:class:`vjm_ros.logs.cdr.FixedLayout`): a block's records are written as rows of one byte image
per tick (``/joint_states``, ``constraint_forces``, each ``closures/<name>/wrench``, ``energy``,
``/clock``, in that order) with the sequence numbers, times, stamps and values written column by
column, plus the ``markers`` record after the other messages of every ``marker_every``-th tick.
The bytes equal those of the per-message encoders (test/test_log_blocks.py).

:class:`BlockWriter` is the ``mcap`` writer (1.6, pinned) taking such runs of records: its chunk
builder keeps the message indexes as arrays and writes them in one piece; statistics and indexes
are those the writer keeps for messages added one by one.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np
from mcap._chunk_builder import ChunkBuilder
from mcap.opcode import Opcode
from mcap.records import Message
from mcap.writer import Writer

from vjm_ros.logs import cdr, messages

RECORD_HEADER = struct.Struct("<BQHIQQ")
"""Opcode, record length, channel id, sequence, log time, publish time of a Message record."""
_SEQUENCE, _LOG_TIME, _PUBLISH_TIME = 11, 15, 23
"""Byte offsets of the sequence and the two times in a Message record."""
NS_PER_S = 1_000_000_000


class BulkIndex:
    """Message index of one channel in the open chunk: log times and offsets as arrays."""

    def __init__(self, channel_id: int):
        self.channel_id = channel_id
        self.times: list[np.ndarray] = []
        self.offsets: list[np.ndarray] = []

    def add(self, times: np.ndarray, offsets: np.ndarray) -> None:
        """Entries of messages at ``times`` (ns) and chunk ``offsets`` (bytes), in file order."""
        self.times.append(times)
        self.offsets.append(offsets)

    def write(self, stream) -> None:
        """The MessageIndex record, as :class:`mcap.records.MessageIndex` writes it."""
        entries = np.empty((sum(len(t) for t in self.times), 2), dtype="<u8")
        entries[:, 0] = np.concatenate(self.times)
        entries[:, 1] = np.concatenate(self.offsets)
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(entries.nbytes)
        stream.write(entries.tobytes())
        stream.finish_record()


class BlockChunkBuilder(ChunkBuilder):
    """The ``mcap`` chunk builder with message indexes kept as arrays, and runs of records."""

    def add_message(self, message: Message) -> None:
        offset = self.record_writer.count
        message.write(self.record_writer)
        self._note(np.array([message.channel_id]), np.array([message.log_time]),
                   np.array([offset]))

    def add_records(self, data, channels: np.ndarray, times: np.ndarray,
                    offsets: np.ndarray) -> None:
        """Append Message records ``data`` (bytes) holding messages of ``channels`` at ``times``
        (ns) starting at ``offsets`` (bytes into ``data``, increasing)."""
        base = self.record_writer.count
        self.record_writer.write(data)
        self._note(channels, times, offsets + base)

    def _note(self, channels: np.ndarray, times: np.ndarray, offsets: np.ndarray) -> None:
        if len(times) == 0:
            return
        lo, hi = int(times.min()), int(times.max())
        self.message_start_time = lo if self.num_messages == 0 else min(
            self.message_start_time, lo)
        self.message_end_time = max(self.message_end_time, hi)
        self.num_messages += len(times)
        ids, first = np.unique(channels, return_index=True)
        for channel in ids[np.argsort(first)].tolist():  # in order of first appearance
            mask = channels == channel
            index = self.message_indices.get(channel)
            if index is None:
                index = self.message_indices[channel] = BulkIndex(channel)
            index.add(times[mask], offsets[mask])


class BlockWriter(Writer):
    """``mcap.writer.Writer`` that also takes runs of Message records (:meth:`add_records`).

    Reaches into the writer's private statistics and chunk state (``mcap`` 1.6.0, pinned in
    ``requirements/lock.txt``); the logs it writes are read back by rosbags and the ``mcap``
    reader in the tests.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._builder = BlockChunkBuilder()
        self._Writer__chunk_builder = self._builder

    def add_records(self, data, channels: np.ndarray, times: np.ndarray,
                    offsets: np.ndarray) -> None:
        """Add Message records to the open chunk (see :meth:`BlockChunkBuilder.add_records`);
        statistics as :meth:`add_message` keeps them; the chunk is closed when over its size."""
        if len(times) == 0:
            return
        stats = self._Writer__statistics
        lo, hi = int(times.min()), int(times.max())
        stats.message_start_time = lo if stats.message_count == 0 else min(
            stats.message_start_time, lo)
        stats.message_end_time = max(stats.message_end_time, hi)
        ids, counts = np.unique(channels, return_counts=True)
        for channel, count in zip(ids.tolist(), counts.tolist(), strict=True):
            stats.channel_message_counts[channel] += count
        stats.message_count += len(times)
        self._builder.add_records(data, channels, times, offsets)
        self._Writer__maybe_finalize_chunk()


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
    """

    def __init__(self, model, channels: dict[str, int], topics: messages.Topics,
                 marker_every: int, force_scale: float):
        k = len(model.closures)
        self.force_scale = float(force_scale)
        self.marker_every = int(marker_every)
        self.kinds = [
            _Kind(channels[topics.joint_states],
                  cdr.joint_state_layout(model.joint_names, messages.FRAME_ID)),
            _Kind(channels[topics.constraint_forces], cdr.multi_array_layout(
                messages.labelled_layout(model.closure_names, len(messages.FORCE_COMPONENTS)),
                3 * k)),
        ]
        wrench = cdr.wrench_stamped_layout(messages.FRAME_ID)
        self.kinds += [_Kind(channels[topics.wrench(name)], wrench)
                       for name in model.closure_names]
        self.kinds += [
            _Kind(channels[topics.energy], cdr.multi_array_layout(
                messages.labelled_layout(messages.ENERGY_LABELS, 1),
                len(messages.ENERGY_LABELS))),
            _Kind(channels[topics.clock], cdr.CLOCK_LAYOUT),
        ]
        self.starts = np.cumsum([0] + [len(kd.image) for kd in self.kinds])
        self.image = np.concatenate([kd.image for kd in self.kinds])
        self.marker_channel = channels.get(topics.markers)
        self.markers: _Kind | None = None  # from the first block's geometry

    def _values(self, block, rows: int) -> list[list[np.ndarray]]:
        """The float64 runs of each per-tick record, in the order of :attr:`kinds`."""
        force = block.force[:rows]
        effort = np.broadcast_to(block.effort, block.q[:rows].shape)
        values = [[block.q[:rows], block.qd[:rows], effort],
                  [force.reshape(rows, -1)] if force.shape[1] else []]
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

    def encode(self, block, ns: np.ndarray, first: int) -> tuple:
        """Records of the block's rows (``len(ns)``) logged at ``ns`` (ns), the first being
        sample number ``first`` of the recording.

        Returns
        -------
        data : bytes
            The Message records, tick after tick.
        channels, times, offsets : ndarray, shape (messages,)
            Channel id, log time (ns) and byte offset in ``data`` of every message, in order.
        tick_starts : ndarray of int, shape (rows + 1,)
            Byte offset in ``data`` where each tick's records start (and the end).
        """
        rows = len(ns)
        seq = (first + np.arange(rows)) & 0xFFFFFFFF
        sec, nsec = np.divmod(ns, NS_PER_S)
        table = np.empty((rows, len(self.image)), dtype=np.uint8)
        table[:] = self.image
        for kind, start, values in zip(self.kinds, self.starts, self._values(block, rows),
                                       strict=False):
            kind.fill(table, int(start), seq, ns, sec, nsec, values)
        ticks = np.arange(rows)
        marked = (np.nonzero((first + ticks) % self.marker_every == 0)[0]
                  if self.marker_every > 0 else ticks[:0])
        pieces, size = [table], len(self.image)
        marker_size = 0
        if len(marked):
            mrows = self._marker_rows(block, marked, seq, ns, sec, nsec)
            marker_size = mrows.shape[1]
            pieces, prev = [], 0
            for g, i in enumerate(marked.tolist()):
                pieces += [table[prev : i + 1], mrows[g]]
                prev = i + 1
            pieces.append(table[prev:])
        before = np.searchsorted(marked, ticks, side="left")  # markers before each tick
        tick_starts = np.empty(rows + 1, dtype=np.int64)
        tick_starts[:-1] = ticks * size + before * marker_size
        tick_starts[-1] = rows * size + len(marked) * marker_size
        offsets = [tick_starts[:-1] + int(s) for s in self.starts[:-1]]
        channels = [np.full(rows, kd.channel) for kd in self.kinds]
        times = [ns] * len(self.kinds)
        if len(marked):
            offsets.append(tick_starts[marked] + size)
            channels.append(np.full(len(marked), self.marker_channel))
            times.append(ns[marked])
        offsets = np.concatenate(offsets)
        order = np.argsort(offsets, kind="stable")
        return (b"".join(pieces), np.concatenate(channels)[order], np.concatenate(times)[order],
                offsets[order], tick_starts)

    def _marker_rows(self, block, marked, seq, ns, sec, nsec) -> np.ndarray:
        """Records of the markers at ticks ``marked`` (G, record size)."""
        if self.markers is None:
            sample = block.sample(int(marked[0]))
            layout = cdr.markers_layout(messages.markers(sample, 0, self.force_scale))
            self.markers = _Kind(self.marker_channel, layout)
        kind = self.markers
        mrows = np.empty((len(marked), len(kind.image)), dtype=np.uint8)
        mrows[:] = kind.image
        values = self._marker_values(block, marked)
        kind.fill(mrows, 0, seq[marked], ns[marked], sec[marked], nsec[marked], values)
        return mrows
