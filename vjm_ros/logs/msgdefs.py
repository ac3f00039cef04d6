"""ROS 2 message definitions (``ros2msg`` schema text) and type hashes of the types the logs carry.

An MCAP file of the ROS 2 profile stores, for each channel, the ``.msg`` text of its type followed
by the text of every type it depends on, each introduced by a line of 80 ``=`` and a
``MSG: <package>/<Type>`` line (the layout rosbag2 writes, which rerun's and Foxglove's readers
expect). The texts come from the typestore of rosbags (a pure-Python ROS bag library) for ROS 2
Kilted, the distro of the ROS 2 wheels the package is tested with, so the logs can be written
without a ROS installation and no definition is kept by hand. Types are written fully qualified
(``geometry_msgs/Vector3``) and without comments or default values, which every reader accepts.
"""

from __future__ import annotations

import functools

LOGGED_TYPES: tuple[str, ...] = (
    "sensor_msgs/msg/JointState",
    "std_msgs/msg/Float64MultiArray",
    "geometry_msgs/msg/WrenchStamped",
    "rosgraph_msgs/msg/Clock",
    "std_msgs/msg/String",
    "visualization_msgs/msg/MarkerArray",
)
"""Every type a log's channel may have."""

SEPARATOR = "=" * 80


@functools.cache
def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_KILTED)


@functools.cache
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
    if type_name not in known_types():
        raise KeyError(f"{type_name!r}: not a type the logs carry ({', '.join(LOGGED_TYPES)})")
    text, _ = _typestore().generate_msgdef(type_name, ros_version=2)
    return text


def dependencies(type_name: str) -> list[str]:
    """Every type ``type_name`` depends on, as the schema text lists them (full names).

    Parameters
    ----------
    type_name : str

    Returns
    -------
    list of str
    """
    text, _ = _typestore().generate_msgdef(type_name, ros_version=2)
    return [
        line[5:].replace("/", "/msg/", 1)
        for line in text.split("\n")
        if line.startswith("MSG: ")
    ]


@functools.cache
def type_hash(type_name: str) -> str:
    """The ROS 2 type hash (``RIHS01_<sha256>``) of a type, as Jazzy and later record it."""
    return _typestore().hash_rihs01(type_name)


@functools.cache
def known_types() -> tuple[str, ...]:
    """The logged types and every type they depend on, sorted."""
    names = set(LOGGED_TYPES)
    for t in LOGGED_TYPES:
        names.update(dependencies(t))
    return tuple(sorted(names))
