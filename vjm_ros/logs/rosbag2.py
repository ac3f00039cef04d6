"""What rosbag2 records beside the messages: offered QoS, type hashes, the bag's metadata.

The layout is rosbag2's metadata version 9, which rosbag2 writes from Jazzy (0.26) through Kilted
(0.32, the distro targeted here): the encoders of ``rosbag2_storage``'s ``yaml.hpp``
(``convert<BagMetadata>``, ``convert<TopicMetadata>``, ``convert<FileInformation>``), ``qos.cpp``
(``convert<rclcpp::QoS>``) and ``bag_metadata.hpp`` (``version = 9``) on rosbag2's ``jazzy``
branch, unchanged in the Kilted releases. Field by field:

* ``metadata.yaml``: ``rosbag2_bagfile_information`` with version, storage_identifier, duration,
  starting_time, message_count, topics_with_message_count (per topic: name, type,
  serialization_format, offered_qos_profiles as a YAML sequence of profiles with the enums by
  their rmw names, type_description_hash; and the message count), compression_format,
  compression_mode, relative_file_paths, files (per file: path, starting_time, duration,
  message_count), custom_data (empty: null, as yaml-cpp writes an empty map) and ros_distro;
* in the MCAP file (``rosbag2_storage_mcap``): a metadata record ``rosbag2`` whose
  ``serialized_metadata`` is the same node without the ``rosbag2_bagfile_information`` key, and
  per channel the metadata ``offered_qos_profiles`` (a YAML list of profiles as text) and
  ``topic_type_hash`` (``RIHS01_...``).

Each profile has the nine keys history, depth, reliability, durability, deadline, lifespan,
liveliness, liveliness_lease_duration, avoid_ros_namespace_conventions. What other distros read:

* Jazzy and Kilted read all of it. Their QoS decoder tells the two enum forms apart per profile
  (integers, as version 8 and earlier wrote them, or names), in the file and in the channels;
* Humble's rosbag2 (metadata version 5) reads ``offered_qos_profiles`` only as a string of
  integer enums: it cannot parse a version 9 ``metadata.yaml`` (nor any Jazzy or Kilted one), and
  it ignores the ``rosbag2`` record. Its MCAP plugin takes the profiles from the channels, so
  those keep integer enums (which Jazzy and Kilted accept too): on Humble, play the ``.mcap``
  file itself rather than the bag directory;
* rosbags (a third-party bag library) reads versions up to 9, both enum forms.

The profiles recorded are the ones the node offers: reliable, volatile, keep-last 10 (the event
topic is transient-local with depth 100, the scene description transient-local with depth 1).
"""

from __future__ import annotations

import copy
import functools
import re
from dataclasses import dataclass, field
from pathlib import Path

import yaml

_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
"""libyaml's safe emitter where PyYAML was built with it, else the pure-Python one."""
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
"""libyaml's safe parser likewise (1 ms -> 0.26 ms per QoS text)."""

BAG_METADATA_VERSION = 9
"""``metadata.yaml`` version written: what rosbag2 writes from Jazzy through Kilted."""
ROS_DISTRO = "kilted"
"""``ros_distro`` of the metadata (rosbag2 writes the ``ROS_DISTRO`` it records under)."""
BAG_KEY = "rosbag2_bagfile_information"
"""Top-level key of ``metadata.yaml`` (absent from the MCAP record's ``serialized_metadata``)."""

# rmw enums, as integers (rmw/types.h)
HISTORY_KEEP_LAST = 1
RELIABILITY_RELIABLE = 1
DURABILITY_TRANSIENT_LOCAL = 1
DURABILITY_VOLATILE = 2
LIVELINESS_AUTOMATIC = 1

POLICY_NAMES = {
    "history": ("system_default", "keep_last", "keep_all", "unknown"),
    "reliability": ("system_default", "reliable", "best_effort", "unknown", "best_available"),
    "durability": ("system_default", "transient_local", "volatile", "unknown", "best_available"),
    "liveliness": ("system_default", "automatic", "unknown", "manual_by_topic", "unknown",
                   "best_available"),
}
"""Name of each rmw enum value (``rmw_qos_*_policy_to_str``; the unknown value, which rmw does
not name, and the withdrawn ``manual_by_node``, liveliness 2, are written ``unknown``)."""
QOS_KEYS = ("history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
            "liveliness_lease_duration", "avoid_ros_namespace_conventions")
"""The keys of a profile, in the order rosbag2 writes them."""


@dataclass(frozen=True)
class OfferedQos:
    """A publisher's QoS profile, as rosbag2 records it.

    Attributes
    ----------
    depth : int
        Keep-last history depth.
    durability : int
        ``DURABILITY_VOLATILE`` or ``DURABILITY_TRANSIENT_LOCAL``.
    """

    depth: int = 10
    durability: int = DURABILITY_VOLATILE

    def as_dict(self) -> dict:
        """The profile with its nine keys (durations of 0 s: the rmw's "infinite")."""
        zero = {"sec": 0, "nsec": 0}
        return {
            "history": HISTORY_KEEP_LAST,
            "depth": self.depth,
            "reliability": RELIABILITY_RELIABLE,
            "durability": self.durability,
            "deadline": dict(zero),
            "lifespan": dict(zero),
            "liveliness": LIVELINESS_AUTOMATIC,
            "liveliness_lease_duration": dict(zero),
            "avoid_ros_namespace_conventions": False,
        }


DEFAULT_QOS = OfferedQos()
EVENTS_QOS = OfferedQos(depth=100, durability=DURABILITY_TRANSIENT_LOCAL)


def policy_name(key: str, value: int | str) -> str:
    """The name metadata version 9 writes for the value of the QoS policy ``key``.

    Parameters
    ----------
    key : str
        ``history``, ``reliability``, ``durability`` or ``liveliness``.
    value : int or str
        The rmw enum value (a name is returned as it is).
    """
    if isinstance(value, str):
        return value
    names = POLICY_NAMES[key]
    return names[value] if 0 <= value < len(names) else "unknown"


def qos_profiles(text: str, topic: str = "") -> list[dict]:
    """A channel's ``offered_qos_profiles`` text as ``metadata.yaml`` holds it (version 9): a list
    of profiles, enums by name, keys in rosbag2's order.

    Raises
    ------
    ValueError
        When ``text`` is not a YAML list of mappings (``topic`` names it in the message).
    """
    profiles = _qos_profiles(text)
    if profiles is None:
        raise ValueError(f"offered_qos_profiles of {topic or 'a channel'}: expected a YAML list "
                         f"of QoS profiles, found {text[:80]!r}")
    return copy.deepcopy(profiles)


@functools.cache
def _qos_profiles(text: str) -> list[dict] | None:
    """The profiles of a text (parsed once per text: every topic of a log has one of two), or
    None when it is not a list of mappings."""
    profiles = yaml.load(text, Loader=_LOADER) if text else []
    if not isinstance(profiles, list) or not all(isinstance(p, dict) for p in profiles):
        return None
    return [
        {k: policy_name(k, p[k]) if k in POLICY_NAMES else p[k] for k in QOS_KEYS if k in p}
        for p in profiles
    ]


def qos_yaml(profiles: list[OfferedQos]) -> str:
    """The ``offered_qos_profiles`` text of a channel: a YAML list of profiles (integer enums,
    which Humble's player needs and every later distro reads)."""
    return _qos_yaml(tuple(profiles))


@functools.cache
def _qos_yaml(profiles: tuple[OfferedQos, ...]) -> str:
    """:func:`qos_yaml`, dumped once per set of profiles (every channel of a log has one of two
    and dumping YAML takes about a millisecond)."""
    return yaml.dump([p.as_dict() for p in profiles], Dumper=_DUMPER, sort_keys=False).strip()


@dataclass
class TopicRecord:
    """One recorded topic, for the bag's metadata.

    Attributes
    ----------
    name, type_name : str
        Topic and full ROS 2 type name.
    qos : str
        ``offered_qos_profiles`` text of the channel (:func:`qos_yaml`).
    type_hash : str
        ``RIHS01_...``.
    count : int
        Messages written.
    """

    name: str
    type_name: str
    qos: str
    type_hash: str
    count: int = 0


@dataclass
class BagInfo:
    """Counts and times of a recording, for ``metadata.yaml`` and the ``rosbag2`` record."""

    topics: list[TopicRecord] = field(default_factory=list)
    start_ns: int | None = None
    end_ns: int | None = None
    _text_key: tuple | None = field(default=None, init=False, repr=False, compare=False)
    _text_parts: list[str] | None = field(default=None, init=False, repr=False, compare=False)

    def note(self, topic: TopicRecord, ns: int) -> None:
        """Count one message of ``topic`` logged at ``ns``."""
        self.note_many(topic, 1, ns, ns)

    def note_many(self, topic: TopicRecord, count: int, first_ns: int, last_ns: int) -> None:
        """Count ``count`` messages of ``topic`` logged from ``first_ns`` to ``last_ns``."""
        topic.count += count
        self.start_ns = first_ns if self.start_ns is None else min(self.start_ns, first_ns)
        self.end_ns = last_ns if self.end_ns is None else max(self.end_ns, last_ns)

    def metadata(self, file_name: str) -> dict:
        """The ``metadata.yaml`` document (version 9) for a bag of one file.

        Parameters
        ----------
        file_name : str
            The ``.mcap`` file's name (relative to the bag directory).
        """
        return self._document(file_name, *self._numbers())

    def _numbers(self) -> tuple[int, int, int, list[int]]:
        """The document's numbers: start (ns), duration (ns), message count, count per topic."""
        start = self.start_ns or 0
        counts = [t.count for t in self.topics]
        return start, max(0, (self.end_ns or start) - start), sum(counts), counts

    def serialized_metadata(self, file_name: str) -> str:
        """``serialized_metadata(self.metadata(file_name))``, the same text, filled in from a
        text made once for this file and these topics: only the times and counts change as
        messages are counted. An MCAP log makes that text as it opens
        (:meth:`prepare_serialized_metadata`); as it closes, filling it in takes some 15 µs
        where dumping the document takes 1.2 ms (PyYAML's representer; a bag of seven topics),
        on the last log's path to its end."""
        start, duration, count, counts = self._numbers()
        values = [start, duration, count, *counts]
        parts = self.prepare_serialized_metadata(file_name)
        if parts is None:  # a marker's digits also stand elsewhere in the text
            return serialized_metadata(self.metadata(file_name))
        return "".join(part if i % 2 == 0 else str(values[int(part) - _MARK])
                       for i, part in enumerate(parts))

    def prepare_serialized_metadata(self, file_name: str) -> list[str] | None:
        """The ``serialized_metadata`` text for ``file_name`` and the topics noted so far, cut at
        its numbers: text, marker, text, ..., each marker :data:`_MARK` plus the number's index
        in ``[start, duration, message count, count of each topic]`` (made again when the file
        name or the topics change; None when the markers cannot be told from the rest)."""
        key = (file_name, tuple((t.name, t.type_name, t.qos, t.type_hash) for t in self.topics))
        if self._text_key != key:
            marks = [_MARK + i for i in range(3 + len(self.topics))]
            text = serialized_metadata(
                self._document(file_name, marks[0], marks[1], marks[2], marks[3:]))
            parts = _MARKS.split(text)
            found = sorted(int(p) - _MARK for p in parts[1::2])
            expected = sorted([0, 0, 1, 1, 2, 2] + list(range(3, len(marks))))
            self._text_parts = parts if found == expected else None
            self._text_key = key
        return self._text_parts

    def _document(self, file_name: str, start: int, duration: int, count: int,
                  counts: list[int]) -> dict:
        """The document of :meth:`metadata` with these times (ns) and counts."""
        return {
            BAG_KEY: {
                "version": BAG_METADATA_VERSION,
                "storage_identifier": "mcap",
                "duration": {"nanoseconds": duration},
                "starting_time": {"nanoseconds_since_epoch": start},
                "message_count": count,
                "topics_with_message_count": [
                    {
                        "topic_metadata": {
                            "name": t.name,
                            "type": t.type_name,
                            "serialization_format": "cdr",
                            "offered_qos_profiles": qos_profiles(t.qos, t.name),
                            "type_description_hash": t.type_hash,
                        },
                        "message_count": n,
                    }
                    for t, n in zip(self.topics, counts, strict=True)
                ],
                "compression_format": "",
                "compression_mode": "",
                "relative_file_paths": [file_name],
                "files": [
                    {
                        "path": file_name,
                        "starting_time": {"nanoseconds_since_epoch": start},
                        "duration": {"nanoseconds": duration},
                        "message_count": count,
                    }
                ],
                "custom_data": None,
                "ros_distro": ROS_DISTRO,
            }
        }


_MARK = 987_654_321_987_654_321_000
"""First of the numbers standing for the times and counts in :meth:`BagInfo.serialized_metadata`'s
text (all of 21 digits, up to 999 topics; PyYAML writes an int as ``str`` writes it)."""
_MARKS = re.compile(rf"({_MARK // 1000}\d{{3}})")
"""A marker in that text, kept by :func:`re.split` (the first 18 of its 21 digits fixed)."""


def metadata_yaml(document: dict) -> str:
    """``metadata.yaml`` text of a bag (:meth:`BagInfo.metadata`).

    Written by libyaml's emitter where PyYAML has it (2 ms -> 0.3 ms for a four-bar log, once
    per log as it closes): the same document as the pure-Python emitter, which folds long quoted
    strings at other places."""
    return yaml.dump(document, Dumper=_DUMPER, sort_keys=False)


def serialized_metadata(document: dict) -> str:
    """The MCAP ``rosbag2`` record's ``serialized_metadata``: the document of
    :meth:`BagInfo.metadata` without its top-level key, as rosbag2's MCAP plugin writes it."""
    return yaml.dump(document[BAG_KEY], Dumper=_DUMPER, sort_keys=False)


def write_bag_metadata(bag_dir: str | Path, document: dict) -> Path:
    """Write ``metadata.yaml`` into a bag directory; its path."""
    path = Path(bag_dir) / "metadata.yaml"
    path.write_text(metadata_yaml(document), encoding="utf-8")
    return path
