"""MCAP log of a simulation in the ROS 2 profile (``cdr`` messages, ``ros2msg`` schemas).

The file carries the topics of the live node (:mod:`vjm_ros.logs.messages`), the scene YAML
as the attachment ``scene.yaml`` (``application/yaml``), and the run settings and package versions
as metadata records ``run_settings`` and ``package_versions``. ``ros2 bag``, Foxglove and rerun
open it; no ROS installation is needed to write it.

Time. Every message is logged (``log_time`` = ``publish_time``) at the simulated time of its tick
in integer nanoseconds since the start of the recording; header stamps and ``/clock`` carry the
same value. After a reset the simulator's clock restarts at 0 while the log time goes on (see
:class:`vjm_ros.logs.Timebase`): the later episode starts one tick after the last message,
and the reset event the node publishes on ``~/events`` (:func:`vjm_ros.logs.events.reset_line`)
is logged on ``/<node>/events`` at that time.

What rosbag2 writes, this writes too (:mod:`vjm_ros.logs.rosbag2`): the ``ros2`` profile,
``ros2msg`` schemas named by their full type, ``cdr`` channels with the metadata
``offered_qos_profiles`` and ``topic_type_hash``, chunk and message indexes, a Statistics record,
and a ``rosbag2`` metadata record holding the bag's metadata (version 9); :meth:`McapRecorder.
bag_metadata` gives that document for a bag directory (``vjm run --bag``). rosbags, the ``mcap``
reader, rerun and Foxglove read every message, in time order.

Blocks. :meth:`McapRecorder.write_block` logs a whole
:class:`~vjm_ros.sim.samples.SampleBlock` (``vjm run``), its messages built and indexed in
bulk (:mod:`vjm_ros.logs.mcap_block`): the file is the one :meth:`McapRecorder.write` of each
row writes, byte for byte.

Durability. Messages are grouped in small compressed chunks; a chunk is closed and handed to the
operating system at least every ``chunk_seconds`` of simulated or wall time, so a process killed
with SIGKILL loses at most that much. Such a truncated file has no summary;
:func:`vjm_ros.logs.replay.recover` rewrites the complete chunks into a finalized copy. Use the
recorder as a context manager (with :func:`vjm_ros.logs.finalize_on_signals` against SIGTERM) so
that the summary, the indexes and the Statistics record are always written. Memory: the writer
keeps one chunk index (with its message-index offsets) per chunk until the file is finalized,
i.e. about 14 MB per recorded hour at 1 kHz (measured over one simulated hour of five_bar:
the resident size grew linearly from 255 to 268 MB; test/bench_logging.py).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import CompressionType, IndexType

from vjm_ros.logs import (
    Recorder,
    Timebase,
    atomic,
    cdr,
    mcap_block,
    messages,
    msgdefs,
    package_versions,
    rosbag2,
    tick_of,
)

if TYPE_CHECKING:
    from vjm_ros.core.model import Model
    from vjm_ros.sim.samples import SampleBlock

INDEX_BYTES_PER_HOUR = 16 * 2**20
"""Bound on what the writer keeps until the file is finalized, per recorded hour at 1 kHz with
the default ``chunk_seconds``: one chunk index per chunk (four a second). Measured 13.5-13.6 MB
per simulated hour (five_bar and six_bar, 14 343 chunks), plus room for scenes with more
closures (one more channel each)."""

SCENE_ATTACHMENT = "scene.yaml"
SCENE_MEDIA_TYPE = "application/yaml"
SETTINGS_METADATA = "run_settings"
VERSIONS_METADATA = "package_versions"

_COMPRESSION = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
CHUNK_BYTES = 1 << 20
"""Largest uncompressed chunk, bytes."""
INDEXES = IndexType.ALL
"""Indexes written: chunk, message, attachment and metadata indexes, as rosbag2 writes them.
Readers that read in time order or by topic (rosbags, rosbag2, Foxglove) need the message
indexes."""
BAG_METADATA = "rosbag2"
"""Name of the metadata record holding the bag's metadata (key ``serialized_metadata``: the node
of ``metadata.yaml`` without its top-level key, :func:`~vjm_ros.logs.rosbag2.serialized_metadata`)."""


def _metadata_values(data: dict) -> dict[str, str]:
    """Metadata records hold strings: keep strings, JSON-encode everything else."""
    return {
        str(k): v if isinstance(v, str) else json.dumps(v, default=str) for k, v in data.items()
    }


class McapRecorder(Recorder):
    """Write simulation samples to an MCAP file, as the ROS 2 node would publish them.

    Parameters
    ----------
    path : str or Path
        Output file (overwritten).
    model : Model
        The simulated model (joint and closure names).
    settings : dict
        Run settings, e.g. ``Simulator.describe()``; stored as metadata. ``dt`` (s) or ``rate``
        (Hz) sets the gap left between episodes after a reset; the private topics are
        ``<namespace>/<node>/...`` with ``settings["node"]`` (else ``vjm_sim_node``) and
        ``settings["namespace"]`` (else the root).
    scene_text : str
        Scene YAML, stored as the attachment ``scene.yaml`` (``model.source_text`` when empty).
    marker_every : int
        Write ``/<node>/markers`` on every ``marker_every``-th sample (and the first); 0 disables.
    chunk_seconds : float
        Longest span of simulated or wall time, s, that a chunk collects before it is written.
    compression : str
        ``"zstd"``, ``"lz4"`` or ``"none"``.

    Attributes
    ----------
    topics : messages.Topics
    message_count : int
        Messages written so far.
    flushed_count : int
        Messages in chunks already handed to the operating system (they survive a SIGKILL).
    """

    def __init__(
        self,
        path: str | Path,
        model: Model,
        settings: dict,
        scene_text: str = "",
        marker_every: int = 10,
        chunk_seconds: float = 0.25,
        compression: str = "zstd",
    ):
        if compression not in _COMPRESSION:
            raise ValueError(
                f"compression: expected one of {sorted(_COMPRESSION)}, found {compression!r}"
            )
        self.path = Path(path)
        self.model = model
        node_name = str(settings.get("node", "vjm_sim_node"))
        self.topics = messages.Topics(node_name, str(settings.get("namespace", "")))
        self.marker_every = int(marker_every)
        self.chunk_ns = int(chunk_seconds * 1e9)
        self.chunk_seconds = float(chunk_seconds)
        self.timebase = Timebase(tick_of(settings))
        self.message_count = 0
        self.flushed_count = 0
        self.samples = 0
        self._closed = False
        self._force_names = list(model.force_names)  # closures, then stops
        self.measured = bool(settings.get("sensors"))
        """A scene with sensors: ``/joint_states`` holds the measured state (as the node
        publishes it) and ``/<node>/ground_truth/joint_states`` the exact one."""
        self._file = open(self.path, "wb")  # closed in close()
        try:
            self._writer = mcap_block.BlockWriter(
                self._file, chunk_size=CHUNK_BYTES, compression=_COMPRESSION[compression],
                index_types=INDEXES,
            )
            self._writer.start(profile=Profile.ROS2, library=self._library())
            self._channels = self._register_channels()
            now = time.time_ns()
            text = scene_text or model.source_text
            self._writer.add_attachment(
                now, 0, SCENE_ATTACHMENT, SCENE_MEDIA_TYPE, text.encode("utf-8")
            )
            meta = {"scene": model.name, **settings, "node": node_name}
            meta["time"] = "log time = simulated time since the recording started, ns"
            self._writer.add_metadata(SETTINGS_METADATA, _metadata_values(meta))
            self._writer.add_metadata(VERSIONS_METADATA, _metadata_values(package_versions()))
            self.bag.prepare_serialized_metadata(self.path.name)  # filled in as the log closes
        except BaseException:
            self._file.close()
            raise
        self._chunk_start_ns: int | None = None
        self._chunk_wall = time.monotonic()
        self._block_encoder = mcap_block.BlockEncoder(  # the per-tick messages and markers
            self.model, self._channels, self.topics, self.marker_every, messages.FORCE_SCALE,
            self.measured)

    @staticmethod
    def _library() -> str:
        from mcap.writer import LIBRARY_IDENTIFIER

        return f"vjm_ros recorder; {LIBRARY_IDENTIFIER}"

    def _register_channels(self) -> dict[str, int]:
        """One schema per type and one channel per topic, all in the first chunk."""
        t = self.topics
        plan = [(t.joint_states, messages.JOINT_STATE)]
        if self.measured:
            plan.append((t.ground_truth_joint_states, messages.JOINT_STATE))
        plan += [
            (t.constraint_forces, messages.FLOAT64_MULTI_ARRAY),
            (t.energy, messages.FLOAT64_MULTI_ARRAY),
            (t.clock, messages.CLOCK),
            (t.events, messages.STRING),
        ]
        plan += [(t.wrench(name), messages.WRENCH_STAMPED) for name in self._force_names]
        if self.marker_every > 0:
            plan.append((t.markers, messages.MARKER_ARRAY))
        schema_ids: dict[str, int] = {}
        channels: dict[str, int] = {}
        self.bag = rosbag2.BagInfo()
        self._records: dict[int, rosbag2.TopicRecord] = {}
        for topic, type_name in plan:
            if type_name not in schema_ids:
                schema_ids[type_name] = self._writer.register_schema(
                    type_name, SchemaEncoding.ROS2, msgdefs.definition(type_name).encode()
                )
            qos = rosbag2.EVENTS_QOS if topic == t.events else rosbag2.DEFAULT_QOS
            record = rosbag2.TopicRecord(
                topic, type_name, rosbag2.qos_yaml([qos]), msgdefs.type_hash(type_name)
            )
            channels[topic] = self._writer.register_channel(
                topic,
                MessageEncoding.CDR,
                schema_ids[type_name],
                {"offered_qos_profiles": record.qos, "topic_type_hash": record.type_hash},
            )
            self.bag.topics.append(record)
            self._records[channels[topic]] = record
        return channels

    # ------------------------------------------------------------------ writing
    def _event(self, text: str, ns: int) -> None:
        """Log ``text`` on ``/<node>/events`` at ``ns``."""
        channel = self._channels[self.topics.events]
        self._writer.add_message(channel, ns, cdr.encode_string(text), ns,
                                 self.samples & 0xFFFFFFFF)
        self.bag.note(self._records[channel], ns)
        self.message_count += 1

    @atomic
    def write_block(self, block: SampleBlock) -> None:
        """Log every row of a :class:`~vjm_ros.sim.samples.SampleBlock`, encoded in bulk.

        The messages, their times, sequence numbers and order do not depend on how the ticks
        are split into blocks, and chunks close after the same ticks (:meth:`_chunk_stop`),
        except that the wall-time condition of ``chunk_seconds`` is checked once per block.
        """
        self._check_open()
        rows = len(block)
        if rows == 0:
            return
        ns = self.timebase.to_ns_array(block.t[:rows])
        encoded = self._block_encoder.encode(block, ns, self.samples)
        start = 0
        while start < rows:
            stop, close = self._chunk_stop(ns, start)
            self._add_run(*encoded.run(start, stop))
            if close:
                self.flush()
            start = stop
        self.samples += rows
        if self._chunk_start_ns is not None and (
                time.monotonic() - self._chunk_wall >= self.chunk_seconds):
            self.flush()

    def reserve(self, block_ticks: int) -> None:
        """Buffers of the block encoder and of the chunks, sized for blocks of ``block_ticks``
        rows and their pages touched (see :meth:`Recorder.reserve`)."""
        self._block_encoder.reserve(block_ticks)
        self._writer.reserve(CHUNK_BYTES + self._block_encoder.block_bytes(block_ticks))

    def _chunk_stop(self, ns: np.ndarray, start: int) -> tuple[int, bool]:
        """End (exclusive) of the ticks from ``start`` that go into the open chunk, and whether
        the chunk closes after them: at the first tick ``chunk_seconds`` of simulated time after
        the chunk's first."""
        first = start
        if self._chunk_start_ns is None:
            self._chunk_start_ns = int(ns[start])
            first = start + 1
        end = max(first, int(np.searchsorted(ns, self._chunk_start_ns + self.chunk_ns)))
        if end < len(ns):
            return end + 1, True
        return len(ns), False

    def _add_run(self, data, times: np.ndarray, starts: np.ndarray, columns: list,
                 markers: tuple | None) -> None:
        """Add a run of ticks' records (:meth:`mcap_block.EncodedBlock.run`) and count them."""
        self._writer.add_run(data, times, starts, columns, markers)
        lo, hi, ticks = int(times[0]), int(times[-1]), len(times)
        note, records = self.bag.note_many, self._records
        for channel, _ in columns:
            note(records[channel], ticks, lo, hi)
        self.message_count += ticks * len(columns)
        if markers is not None:
            channel, mtimes, _ = markers
            note(records[channel], len(mtimes), int(mtimes[0]), int(mtimes[-1]))
            self.message_count += len(mtimes)

    @atomic
    def note(self, text: str) -> None:
        """Log ``text`` on ``/<node>/events`` at the latest recording time."""
        self._check_open()
        ns = self.timebase.last_ns or 0
        self._event(text, ns)

    @atomic
    def note_reset(self, t: float | None = None, tick: float | None = None) -> None:
        """Mark a simulator reset.

        Parameters
        ----------
        t : float, optional
            Simulator time at which the ending episode stopped, s (the last sample's when
            omitted). Later samples are shifted to start one tick after it, where the reset
            event is logged with the text the node publishes (:func:`~vjm_ros.logs.events.
            reset_line`).
        tick : float, optional
            The new episode's control period, s, when the reset changes it.
        """
        self._check_open()
        ns, text = self._reset_event(t, tick)
        self._event(text, ns)

    def flush(self) -> None:
        """Close the current chunk and hand it to the operating system."""
        if self._closed:
            return
        self._writer.flush()
        self.flushed_count = self.message_count
        self._chunk_start_ns = None
        self._chunk_wall = time.monotonic()

    # ------------------------------------------------------------------ closing
    def bag_metadata(self) -> dict:
        """The bag's ``metadata.yaml`` document (:mod:`vjm_ros.logs.rosbag2`) so far, naming
        this file."""
        return self.bag.metadata(self.path.name)

    def _finalize(self) -> None:
        """Write the bag's metadata, the summary (Statistics, indexes) and close the file."""
        try:
            self._writer.add_metadata(
                BAG_METADATA,
                {"serialized_metadata": self.bag.serialized_metadata(self.path.name)},
            )
            self._writer.finish()
            self.flushed_count = self.message_count
        finally:
            self._file.close()
