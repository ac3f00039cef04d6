"""What rosbag2 records beside the messages: offered QoS, type hashes, the bag's metadata.

rosbag2's MCAP storage plugin (``rosbag2_storage_mcap``) writes, and its readers and rosbags
(a third-party bag library) use:

* per channel, the metadata ``offered_qos_profiles`` (a YAML list with one QoS profile per
  publisher; each profile has the nine keys history, depth, reliability, durability, deadline,
  lifespan, liveliness, liveliness_lease_duration, avoid_ros_namespace_conventions) and, from
  Iron on, ``topic_type_hash`` (``RIHS01_...``). The enums are written as integers, which every
  distro's reader accepts (Jazzy and later also accept names); a malformed profile makes rosbags
  refuse the whole file;
* a metadata record ``rosbag2`` whose ``serialized_metadata`` is the bag's ``metadata.yaml``
  (``rosbag2_bagfile_information``: topics with message counts, start, duration, files);
* in a bag directory, the same document as ``metadata.yaml`` beside the ``.mcap`` file.

The profiles recorded are the ones the node offers: reliable, volatile, keep-last 10 (the event
topic keeps 100, the scene description is transient-local, depth 1).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path

import yaml

_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
"""libyaml's safe emitter where PyYAML was built with it, else the pure-Python one."""

BAG_METADATA_VERSION = 8
"""``metadata.yaml`` version written: the last whose QoS profiles are integers (Iron and Jazzy
write 8; Kilted reads it), with per-topic type hashes."""

# rmw enums, as integers (rmw/types.h)
HISTORY_KEEP_LAST = 1
RELIABILITY_RELIABLE = 1
DURABILITY_TRANSIENT_LOCAL = 1
DURABILITY_VOLATILE = 2
LIVELINESS_AUTOMATIC = 1


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
EVENTS_QOS = OfferedQos(depth=100)
LATCHED_QOS = OfferedQos(depth=1, durability=DURABILITY_TRANSIENT_LOCAL)


def qos_yaml(profiles: list[OfferedQos]) -> str:
    """The ``offered_qos_profiles`` text of a channel: a YAML list of profiles."""
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
        ``offered_qos_profiles`` text.
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

    def note(self, topic: TopicRecord, ns: int) -> None:
        """Count one message of ``topic`` logged at ``ns``."""
        topic.count += 1
        if self.start_ns is None or ns < self.start_ns:
            self.start_ns = ns
        if self.end_ns is None or ns > self.end_ns:
            self.end_ns = ns

    def note_many(self, topic: TopicRecord, count: int, first_ns: int, last_ns: int) -> None:
        """Count ``count`` messages of ``topic`` logged from ``first_ns`` to ``last_ns``."""
        topic.count += count
        self.start_ns = first_ns if self.start_ns is None else min(self.start_ns, first_ns)
        self.end_ns = last_ns if self.end_ns is None else max(self.end_ns, last_ns)

    def metadata(self, file_name: str) -> dict:
        """The ``rosbag2_bagfile_information`` document for a bag of one file.

        Parameters
        ----------
        file_name : str
            The ``.mcap`` file's name (relative to the bag directory).
        """
        start = self.start_ns or 0
        duration = max(0, (self.end_ns or start) - start)
        count = sum(t.count for t in self.topics)
        return {
            "rosbag2_bagfile_information": {
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
                            "offered_qos_profiles": t.qos,
                            "type_description_hash": t.type_hash,
                        },
                        "message_count": t.count,
                    }
                    for t in self.topics
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
                "custom_data": {},
                "ros_distro": "kilted",
            }
        }


def metadata_yaml(document: dict) -> str:
    """``metadata.yaml`` text of a bag (also the ``rosbag2`` record's ``serialized_metadata``).

    Written by libyaml's emitter where PyYAML has it (2 ms -> 0.3 ms for a four-bar log, once
    per log as it closes): the same document as the pure-Python emitter, which folds long quoted
    strings at other places."""
    return yaml.dump(document, Dumper=_DUMPER, sort_keys=False)


def write_bag_metadata(bag_dir: str | Path, document: dict) -> Path:
    """Write ``metadata.yaml`` into a bag directory; its path."""
    path = Path(bag_dir) / "metadata.yaml"
    path.write_text(metadata_yaml(document), encoding="utf-8")
    return path
