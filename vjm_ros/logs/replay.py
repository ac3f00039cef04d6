"""Replay and repair of MCAP logs.

* :func:`replay` rebuilds a rerun recording from an MCAP log alone: the scene comes from the
  ``scene.yaml`` attachment, the poses from ``/joint_states``; the mechanism is redrawn with the
  package's kinematics, the constraint forces and energies come from their topics.
* :func:`recover` rewrites the readable part of a log that was never finalized (a writer killed
  with SIGKILL, a full disk) into a complete file.

Both read the file sequentially and stop at the first record that cannot be parsed, so they accept
truncated logs.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import closing
from dataclasses import dataclass, field
from itertools import chain
from pathlib import Path

import numpy as np
from mcap.records import Attachment, Channel, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import MCAP0_MAGIC, CompressionType, Writer

from vjm_ros.core.kinematics import link_segments, point_positions
from vjm_ros.core.mechanism import Mechanism
from vjm_ros.core.model import Model
from vjm_ros.logs import rosbag2
from vjm_ros.logs.mcap_recorder import BAG_METADATA, SCENE_ATTACHMENT, SETTINGS_METADATA
from vjm_ros.logs.messages import ENERGY_LABELS, Topics
from vjm_ros.scene.loader import parse_scene
from vjm_ros.sim.samples import Sample


# ---------------------------------------------------------------- reading
def iter_records(path: str | Path, emit_chunks: bool = False,
                 damage: list[str] | None = None) -> Iterator[object]:
    """MCAP records of a file in order, ending quietly at an unreadable tail.

    Records inside a chunk are yielded only when the whole chunk could be read and its CRC
    matches, so a truncated or damaged chunk contributes nothing.

    Parameters
    ----------
    path : str or Path
    emit_chunks : bool
        Yield chunks as ``Chunk`` records instead of the records inside them.
    damage : list of str, optional
        Receives one line naming the file, the byte where reading stopped and why, when the file
        ends before its footer or a record cannot be read (the records before it are yielded).

    Yields
    ------
    mcap.records.McapRecord

    Raises
    ------
    ValueError
        When the file does not start with the MCAP magic.
    """
    with open(path, "rb") as f:
        magic = f.read(len(MCAP0_MAGIC))
        if magic != MCAP0_MAGIC:
            raise ValueError(f"{path}: not an MCAP file (magic {magic!r})")
        f.seek(0)
        reader = StreamReader(f, emit_chunks=emit_chunks, validate_crcs=not emit_chunks)
        records = iter(reader.records)
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except Exception as exc:  # any parse failure marks the end of the readable part
                if damage is not None:
                    size = Path(path).stat().st_size
                    damage.append(
                        f"{path}: reading stopped at byte {f.tell()} of {size} "
                        f"({type(exc).__name__}: {str(exc) or 'the file ends inside a record'}); "
                        "the records before it are used, the rest of the file is not")
                return
            yield record


@dataclass
class LogInfo:
    """The parts of a log outside its chunks (see :func:`read_info`).

    Attributes
    ----------
    scene_text : str
        The ``scene.yaml`` attachment ("" when missing).
    settings : dict
        The ``run_settings`` metadata, JSON values decoded.
    complete : bool
        Whether the file ends with a footer (it was finalized).
    """

    scene_text: str = ""
    settings: dict = field(default_factory=dict)
    complete: bool = False


def _decode_value(text: str):
    try:
        return json.loads(text)
    except ValueError:
        return text


def read_info(path: str | Path) -> LogInfo:
    """Scene attachment, run settings and completeness of a log, without decompressing chunks.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    LogInfo
    """
    info = LogInfo()
    for record in iter_records(path, emit_chunks=True):
        if isinstance(record, Attachment) and record.name == SCENE_ATTACHMENT:
            info.scene_text = record.data.decode("utf-8")
        elif isinstance(record, Metadata) and record.name == SETTINGS_METADATA:
            info.settings = {k: _decode_value(v) for k, v in record.metadata.items()}
        elif isinstance(record, Footer):
            info.complete = True
    return info


def _matches(topic: str, wanted: tuple[str, ...]) -> bool:
    return any(topic == w or topic.endswith(w) for w in wanted)


def iter_messages(
    path: str | Path, topics: tuple[str, ...], counts: dict[str, int] | None = None,
    damage: list[str] | None = None,
) -> Iterator[tuple[str, int, object]]:
    """Decoded ROS 2 messages of some topics, in file order.

    Parameters
    ----------
    path : str or Path
    topics : tuple of str
        Topic names, or suffixes such as ``"/energy"`` (matched with ``str.endswith``).
    counts : dict, optional
        Filled with the number of messages of every topic in the file.
    damage : list of str, optional
        As in :func:`iter_records`.

    Yields
    ------
    topic : str
    log_time : int
        ns.
    message : object
        Decoded by ``mcap_ros2`` (attributes named as the fields).
    """
    from mcap_ros2.decoder import DecoderFactory

    counts = {} if counts is None else counts
    schemas: dict[int, Schema] = {}
    channels: dict[int, tuple] = {}
    factory = DecoderFactory()
    for record in iter_records(path, damage=damage):
        if isinstance(record, Message):
            topic, decode = channels.get(record.channel_id, ("", None))
            counts[topic] = counts.get(topic, 0) + 1
            if decode is not None:
                yield topic, record.log_time, decode(record.data)
        elif isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel) and record.id not in channels:
            decode = None
            if _matches(record.topic, topics):
                schema = schemas.get(record.schema_id)
                decode = factory.decoder_for(record.message_encoding, schema)
            channels[record.id] = (record.topic, decode)
            counts.setdefault(record.topic, 0)


# ---------------------------------------------------------------- replay
def _force_array(model: Model, msg) -> np.ndarray:
    """``(k + s, 3)`` closure and stop forces from a labelled Float64MultiArray, matched by name
    (``model.force_names``)."""
    out = np.full((len(model.force_names), 3), np.nan)
    index = {name: i for i, name in enumerate(model.force_names)}
    offset = int(msg.layout.data_offset)
    for d, dim in enumerate(msg.layout.dim):
        i = index.get(dim.label)
        start = offset + d * int(dim.stride)
        if i is not None and int(dim.size) >= 3:
            out[i] = msg.data[start : start + 3]
    return out


def _energy_array(msg) -> np.ndarray:
    labels = [d.label for d in msg.layout.dim]
    out = np.full(len(ENERGY_LABELS), np.nan)
    for j, name in enumerate(ENERGY_LABELS):
        if name in labels:
            out[j] = msg.data[labels.index(name)]
    return out


class _Poser:
    """Rebuilds drawable observables of a model from joint positions."""

    def __init__(self, model: Model):
        self.model = model
        self.mech = Mechanism.reader(model)
        self.point_links = np.array([p.ref.link for p in model.points], dtype=int)
        self.point_local = np.array([p.ref.local for p in model.points], dtype=float).reshape(-1, 2)
        self.index = {name: i for i, name in enumerate(model.joint_names)}

    def sample(self, ns: int, js, forces: np.ndarray, energy: np.ndarray) -> Sample:
        model, n = self.model, self.model.n
        q, qd = model.initial_state()
        effort = np.zeros(n)
        for j, name in enumerate(js.name):
            i = self.index.get(name)
            if i is None:
                continue
            q[i] = js.position[j]
            if j < len(js.velocity):
                qd[i] = js.velocity[j]
            if j < len(js.effort):
                effort[i] = js.effort[j]
        dyn, terms = self.mech.terms(q, jacobian=False)  # one kernel call, no dynamics
        kin = dyn.kin
        points = (
            point_positions(kin, self.point_links, self.point_local)
            if len(self.point_links)
            else np.zeros((0, 2))
        )
        return Sample(
            t=ns * 1e-9,
            q=q,
            qd=qd,
            qdd=np.full(n, np.nan),
            effort=effort,
            theta=kin.theta[:n].copy(),
            points=points,
            closure_force=forces,
            closure_error=self.mech.closures.errors(terms),
            closure_points=np.concatenate((terms.points, kin.origin[model.stop_joints])),
            energy=energy,
            power_in=float(effort @ qd),
            dissipation=float("nan"),
            joint_loss=float("nan"),
            segments=link_segments(model, kin),
        )


def _ticks(mcap_path: str | Path, joint_topic: str, counts: dict, events: list,
           damage: list[str]) -> Iterator:
    """``(ns, joint_state, forces, energy)`` per tick, streamed; events collected on the side.

    A tick's messages share one log time and follow its joint state in the file, so a tick is
    complete when the next joint state arrives.
    """
    wanted = (joint_topic, "/constraint_forces", "/energy", "/events")
    pending: dict[int, list] = {}

    def complete(before: float) -> Iterator:
        for ns in sorted(k for k in pending if k < before):
            js, forces, energy = pending.pop(ns)
            if js is not None:
                yield ns, js, forces, energy

    for topic, ns, msg in iter_messages(mcap_path, wanted, counts, damage):
        if topic == joint_topic:
            yield from complete(ns)
            pending.setdefault(ns, [None, None, None])[0] = msg
        elif topic.endswith("/constraint_forces"):
            pending.setdefault(ns, [None, None, None])[1] = msg
        elif topic.endswith("/energy"):
            pending.setdefault(ns, [None, None, None])[2] = msg
        elif topic.endswith("/events"):
            events.append((ns, str(msg.data)))
    yield from complete(float("inf"))


def replay(mcap_path: str | Path, rrd_path: str | Path, geometry_every: int = 10) -> dict:
    """Rebuild a rerun recording from an MCAP log.

    The log is streamed (memory does not grow with its length); the model comes from its
    ``scene.yaml`` attachment, the poses from ``/joint_states``, forces and energies from
    ``/<node>/constraint_forces`` and ``/<node>/energy`` at the same log time; the closure error
    is recomputed from the poses.

    Parameters
    ----------
    mcap_path : str or Path
        A log written by :class:`vjm_ros.logs.McapRecorder` (finalized or truncated).
    rrd_path : str or Path
        Output recording (see :class:`vjm_ros.logs.RerunRecorder` for its entities).
    geometry_every : int
        Draw every ``geometry_every``-th joint state.

    Returns
    -------
    dict
        ``rrd`` (path), ``scene``, ``samples`` (joint states replayed), ``start`` and ``end``
        (log time of the first and last, s), ``events``, ``complete`` (the log was finalized),
        ``messages`` (count per topic) and ``damage`` (lines from :func:`iter_records`: where
        reading stopped in a truncated or damaged log, and why).

    Raises
    ------
    ValueError
        When the log has no ``scene.yaml`` attachment or no ``/joint_states`` message.
    """
    from vjm_ros.logs.rerun_recorder import RerunRecorder

    info = read_info(mcap_path)
    if not info.scene_text:
        raise ValueError(f"{mcap_path}: no {SCENE_ATTACHMENT} attachment; cannot rebuild the model")
    model = parse_scene(info.scene_text, source=f"{mcap_path}:{SCENE_ATTACHMENT}").model
    topics = Topics(str(info.settings.get("node", "vjm_sim_node")),
                    str(info.settings.get("namespace", "")))
    # the exact state: with sensors, /joint_states holds what they measured
    joint_topic = (topics.ground_truth_joint_states if info.settings.get("sensors")
                   else topics.joint_states)
    poser = _Poser(model)
    no_force = np.full((len(model.force_names), 3), np.nan)
    no_energy = np.full(len(ENERGY_LABELS), np.nan)
    settings = {  # the replayed samples are the exact states: no measurements
        k: v for k, v in info.settings.items()
        if k not in ("scene", "node", "namespace", "time", "sensors")
    }
    settings["replayed_from"] = str(mcap_path)
    counts: dict[str, int] = {}
    events: list[tuple[int, str]] = []
    damage: list[str] = []
    ticks = _ticks(mcap_path, joint_topic, counts, events, damage)
    first = next(ticks, None)
    if first is None:
        raise ValueError(f"{mcap_path}: no {joint_topic} messages to replay")
    end = first[0]
    with RerunRecorder(
        rrd_path, model, settings, geometry_every=geometry_every, scene_text=info.scene_text
    ) as rec:
        for end, js, f, e in chain([first], ticks):
            forces = _force_array(model, f) if f is not None else no_force
            energy = _energy_array(e) if e is not None else no_energy
            rec.write(poser.sample(end, js, forces, energy))
        for ns, text in events:
            rec.note(text, t=ns * 1e-9)
    return {
        "rrd": str(rrd_path),
        "scene": model.name,
        "samples": rec.samples,
        "start": first[0] * 1e-9,
        "end": end * 1e-9,
        "events": len(events),
        "complete": info.complete,
        "messages": counts,
        "damage": damage,
    }


# ---------------------------------------------------------------- recovery
def recover(in_path: str | Path, out_path: str | Path, damage: list[str] | None = None) -> int:
    """Write a finalized copy of the readable part of a (possibly truncated) MCAP log.

    Header, schemas, channels, attachments, metadata and every message of every complete chunk
    are copied; the first record that cannot be read ends the copy. The output has a summary,
    chunk and message indexes, a Statistics record and a ``rosbag2`` metadata record counting the
    messages saved, so seeking readers (``ros2 bag``, rosbags, Foxglove) accept it.

    Parameters
    ----------
    in_path : str or Path
        The damaged log.
    out_path : str or Path
        The repaired copy (overwritten; must differ from ``in_path``).
    damage : list of str, optional
        Receives where reading stopped and why, if it stopped before the footer
        (:func:`iter_records`).

    Returns
    -------
    int
        Number of messages saved.

    Raises
    ------
    ValueError
        When ``in_path`` is not an MCAP file or is ``out_path``.
    """
    if Path(in_path).resolve() == Path(out_path).resolve():
        raise ValueError("recover: the output must be a different file than the input")
    schemas: dict[int, int] = {0: 0}
    schema_names: dict[int, str] = {}
    channels: dict[int, int] = {}
    topics: dict[int, rosbag2.TopicRecord] = {}
    bag = rosbag2.BagInfo()
    count = 0
    source = iter_records(in_path, damage=damage)
    first = next(source, None)
    records = source if isinstance(first, Header) else chain([first] if first else [], source)
    with open(out_path, "wb") as out, closing(source):
        writer = Writer(out, compression=CompressionType.ZSTD)
        if isinstance(first, Header):
            writer.start(profile=first.profile, library=first.library)
        else:
            writer.start()
        for r in records:
            if isinstance(r, Message):
                channel = channels.get(r.channel_id)
                if channel is not None:
                    writer.add_message(channel, r.log_time, r.data, r.publish_time, r.sequence)
                    bag.note(topics[channel], r.log_time)
                    count += 1
            elif isinstance(r, Schema) and r.id not in schemas:
                schemas[r.id] = writer.register_schema(r.name, r.encoding, r.data)
                schema_names[r.id] = r.name
            elif isinstance(r, Channel) and r.id not in channels:
                schema = schemas.get(r.schema_id, 0)
                channels[r.id] = writer.register_channel(
                    r.topic, r.message_encoding, schema, r.metadata
                )
                topics[channels[r.id]] = rosbag2.TopicRecord(
                    r.topic,
                    schema_names.get(r.schema_id, ""),
                    r.metadata.get("offered_qos_profiles", ""),
                    r.metadata.get("topic_type_hash", ""),
                )
                bag.topics.append(topics[channels[r.id]])
            elif isinstance(r, Attachment):
                writer.add_attachment(r.create_time, r.log_time, r.name, r.media_type, r.data)
            elif isinstance(r, Metadata) and r.name != BAG_METADATA:  # recounted below
                writer.add_metadata(r.name, r.metadata)
            elif isinstance(r, DataEnd):
                break
        document = bag.metadata(Path(out_path).name)
        writer.add_metadata(BAG_METADATA,
                            {"serialized_metadata": rosbag2.serialized_metadata(document)})
        writer.finish()
    return count
