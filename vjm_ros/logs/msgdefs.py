"""ROS 2 message definitions (``ros2msg`` schema text) and type hashes of the types the logs carry.

An MCAP file of the ROS 2 profile stores, for each channel, the ``.msg`` text of its type followed
by the text of every type it depends on, each introduced by a line of 80 ``=`` and a
``MSG: <package>/<Type>`` line (the layout rosbag2 writes, which rerun's and Foxglove's readers
expect). The texts and the RIHS01 type hashes are those of the typestore of rosbags (a
pure-Python ROS bag library) for ROS 2 Kilted, the distro of the ROS 2 wheels the package is
tested with, so the logs can be written without a ROS installation and no definition is kept by
hand. They are read from ``ros2_types.json`` beside this module, which
``python -m vjm_ros.logs.msgdefs`` writes from that typestore: building the typestore takes
0.3-0.4 s, which every log would otherwise spend opening. ``test/test_cdr_rosbags.py`` checks the
file against the typestore. Types are written fully qualified (``geometry_msgs/Vector3``) and
without comments or default values, which every reader accepts.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

LOGGED_TYPES: tuple[str, ...] = (
    "sensor_msgs/msg/JointState",
    "std_msgs/msg/Float64MultiArray",
    "geometry_msgs/msg/WrenchStamped",
    "rosgraph_msgs/msg/Clock",
    "std_msgs/msg/String",
    "visualization_msgs/msg/MarkerArray",
)
"""Every type a log's channel may have."""

TYPES_FILE = Path(__file__).with_name("ros2_types.json")
"""``{type name: {"definition": schema text, "hash": RIHS01 hash}}`` of the logged types and
every type they depend on."""


@functools.cache
def _types() -> dict[str, dict[str, str]]:
    return json.loads(TYPES_FILE.read_text(encoding="utf-8"))


def definition(type_name: str) -> str:
    """Full ``ros2msg`` schema text of a type, dependencies included.

    Parameters
    ----------
    type_name : str
        Full ROS 2 type name, e.g. ``"geometry_msgs/msg/WrenchStamped"``.

    Returns
    -------
    str

    Raises
    ------
    KeyError
        For a type the logs do not carry (nor depend on).
    """
    if type_name not in _types():
        raise KeyError(f"{type_name!r}: not a type the logs carry ({', '.join(LOGGED_TYPES)})")
    return _types()[type_name]["definition"]


def dependencies(type_name: str) -> list[str]:
    """Every type ``type_name`` depends on, as the schema text lists them (full names)."""
    return [line[5:].replace("/", "/msg/", 1)
            for line in definition(type_name).split("\n") if line.startswith("MSG: ")]


def type_hash(type_name: str) -> str:
    """The ROS 2 type hash (``RIHS01_<sha256>``) of a type, as Jazzy and later record it."""
    definition(type_name)  # a clear error for an unknown type
    return _types()[type_name]["hash"]


def known_types() -> tuple[str, ...]:
    """The logged types and every type they depend on, sorted."""
    return tuple(sorted(_types()))


def from_typestore() -> dict[str, dict[str, str]]:
    """The content of :data:`TYPES_FILE` as rosbags' ROS 2 Kilted typestore gives it."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    names = set(LOGGED_TYPES)
    for t in LOGGED_TYPES:
        text, _ = store.generate_msgdef(t, ros_version=2)
        names.update(line[5:].replace("/", "/msg/", 1)
                     for line in text.split("\n") if line.startswith("MSG: "))
    return {t: {"definition": store.generate_msgdef(t, ros_version=2)[0],
                "hash": store.hash_rihs01(t)} for t in sorted(names)}


if __name__ == "__main__":  # python -m vjm_ros.logs.msgdefs: rewrite TYPES_FILE
    TYPES_FILE.write_text(json.dumps(from_typestore(), indent=1) + "\n", encoding="utf-8")
    print(f"wrote {TYPES_FILE}")
