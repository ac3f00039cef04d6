"""The bag metadata (``metadata.yaml`` and the MCAP ``rosbag2`` record) in rosbag2's own layout.

The oracle is written here by hand from rosbag2's source, not from our code: the encoders of
``rosbag2_storage/include/rosbag2_storage/yaml.hpp`` (``convert<BagMetadata>``,
``convert<TopicMetadata>``, ``convert<FileInformation>``), ``rosbag2_storage/src/rosbag2_storage/
qos.cpp`` (``convert<rclcpp::QoS>`` for version 9: enums by their rmw names) and
``bag_metadata.hpp`` (``version = 9``), identical on rosbag2's ``jazzy`` branch and in the Kilted
releases (0.32). yaml-cpp emits the keys in the order the encoders insert them, an empty
``custom_data`` map as ``~`` and the QoS profiles as a YAML sequence (version 8 and earlier wrote
them as one string). The MCAP storage plugin's ``update_metadata`` stores the same node, without
the ``rosbag2_bagfile_information`` key of the file, as the record's ``serialized_metadata``.
"""

from __future__ import annotations

import yaml
from mcap.writer import Writer
from rosbags.rosbag2 import Reader

from vjm_ros.logs import rosbag2

HASH_JS = "RIHS01_" + "a" * 64
HASH_STR = "RIHS01_" + "b" * 64

# What rosbag2 (metadata version 9: Jazzy 0.26 to Kilted 0.32) writes for a bag of one MCAP file
# with /joint_states (3 messages, keep-last 10) and /vjm_sim_node/events (1 message, keep-last
# 100, transient local), the first message at 1000 ns and the last at 5000 ns, recorded under ROS_DISTRO=kilted.
EXPECTED = f"""\
rosbag2_bagfile_information:
  version: 9
  storage_identifier: mcap
  duration:
    nanoseconds: 4000
  starting_time:
    nanoseconds_since_epoch: 1000
  message_count: 4
  topics_with_message_count:
    - topic_metadata:
        name: /joint_states
        type: sensor_msgs/msg/JointState
        serialization_format: cdr
        offered_qos_profiles:
          - history: keep_last
            depth: 10
            reliability: reliable
            durability: volatile
            deadline:
              sec: 0
              nsec: 0
            lifespan:
              sec: 0
              nsec: 0
            liveliness: automatic
            liveliness_lease_duration:
              sec: 0
              nsec: 0
            avoid_ros_namespace_conventions: false
        type_description_hash: {HASH_JS}
      message_count: 3
    - topic_metadata:
        name: /vjm_sim_node/events
        type: std_msgs/msg/String
        serialization_format: cdr
        offered_qos_profiles:
          - history: keep_last
            depth: 100
            reliability: reliable
            durability: transient_local
            deadline:
              sec: 0
              nsec: 0
            lifespan:
              sec: 0
              nsec: 0
            liveliness: automatic
            liveliness_lease_duration:
              sec: 0
              nsec: 0
            avoid_ros_namespace_conventions: false
        type_description_hash: {HASH_STR}
      message_count: 1
  compression_format: ""
  compression_mode: ""
  relative_file_paths:
    - bag_0.mcap
  files:
    - path: bag_0.mcap
      starting_time:
        nanoseconds_since_epoch: 1000
      duration:
        nanoseconds: 4000
      message_count: 4
  custom_data: ~
  ros_distro: kilted
"""


def small_bag() -> rosbag2.BagInfo:
    """Four messages on two topics, counted as the recorders count them."""
    bag = rosbag2.BagInfo()
    joints = rosbag2.TopicRecord("/joint_states", "sensor_msgs/msg/JointState",
                                 rosbag2.qos_yaml([rosbag2.DEFAULT_QOS]), HASH_JS)
    events = rosbag2.TopicRecord("/vjm_sim_node/events", "std_msgs/msg/String",
                                 rosbag2.qos_yaml([rosbag2.EVENTS_QOS]), HASH_STR)
    bag.topics += [joints, events]
    bag.note_many(joints, 2, 1000, 3000)
    bag.note(events, 3000)
    bag.note(joints, 5000)
    return bag


def assert_same_fields(got, want, where="") -> None:
    """Equal values, and mappings with the same keys in the same order, at every level."""
    if isinstance(want, dict):
        assert isinstance(got, dict), where
        assert list(got) == list(want), where
        for key in want:
            assert_same_fields(got[key], want[key], f"{where}.{key}")
    elif isinstance(want, list):
        assert isinstance(got, list) and len(got) == len(want), where
        for i, (g, w) in enumerate(zip(got, want, strict=True)):
            assert_same_fields(g, w, f"{where}[{i}]")
    else:
        assert type(got) is type(want) and got == want, (where, got, want)


def test_metadata_yaml_is_rosbag2s_layout_field_by_field():
    text = rosbag2.metadata_yaml(small_bag().metadata("bag_0.mcap"))
    assert_same_fields(yaml.safe_load(text), yaml.safe_load(EXPECTED))


def test_the_mcap_record_holds_the_metadata_node_without_the_file_key():
    got = yaml.safe_load(rosbag2.serialized_metadata(small_bag().metadata("bag_0.mcap")))
    assert_same_fields(got, yaml.safe_load(EXPECTED)["rosbag2_bagfile_information"])


def test_enum_names_are_rmws():
    """Every rmw policy value maps to the name rmw's ``*_to_str`` gives it (rclpy's ``short_key``
    wraps the same table), the way rosbag2 writes it."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, ReliabilityPolicy

    for key, policy in (("history", HistoryPolicy), ("reliability", ReliabilityPolicy),
                        ("durability", DurabilityPolicy), ("liveliness", LivelinessPolicy)):
        for member in policy:
            assert rosbag2.policy_name(key, member.value) == member.short_key, (key, member)
        assert rosbag2.policy_name(key, 99) == "unknown"
        assert rosbag2.policy_name(key, "keep_all") == "keep_all"  # names pass as they are


def test_rosbags_opens_the_bag_directory_and_reads_the_qos(tmp_path):
    """rosbags' rosbag2 reader (versions up to 9) opens a directory with this metadata.yaml; the
    profiles it parses are the ones offered (it maps names and integers to the same enums)."""
    from rosbags.interfaces import QosDurability, QosHistory, QosLiveliness, QosReliability

    bag_dir = tmp_path / "bag"
    bag_dir.mkdir()
    with (bag_dir / "bag_0.mcap").open("wb") as f:  # a valid MCAP file for the reader to open
        writer = Writer(f)
        writer.start(profile="ros2", library="test")
        writer.finish()
    rosbag2.write_bag_metadata(bag_dir, small_bag().metadata("bag_0.mcap"))
    with Reader(bag_dir) as reader:
        assert reader.ros_distro == "kilted"
        assert reader.message_count == 4
        assert reader.duration == 4000 + 1  # rosbags counts the last nanosecond in
        connections = list(reader.connections)
    assert [(c.topic, c.msgtype, c.msgcount, c.digest) for c in connections] == [
        ("/joint_states", "sensor_msgs/msg/JointState", 3, HASH_JS),
        ("/vjm_sim_node/events", "std_msgs/msg/String", 1, HASH_STR)]
    depths, durabilities = [], []
    for conn in connections:
        (qos,) = conn.ext.offered_qos_profiles
        assert qos.history == QosHistory.KEEP_LAST
        assert qos.reliability == QosReliability.RELIABLE
        assert qos.liveliness == QosLiveliness.AUTOMATIC
        depths.append(qos.depth)
        durabilities.append(qos.durability)
    assert depths == [10, 100]
    assert durabilities == [QosDurability.VOLATILE, QosDurability.TRANSIENT_LOCAL]


def test_serialized_metadata_filled_in_is_the_dumped_text():
    """The text made once and filled in as the log closes is, byte for byte, the document dumped
    then, whatever the counts and times: before any message, as messages are counted, after a
    topic is added (made again) and with a topic whose name holds a marker's digits (dumped)."""
    bag = rosbag2.BagInfo()
    joints = rosbag2.TopicRecord("/joint_states", "sensor_msgs/msg/JointState",
                                 rosbag2.qos_yaml([rosbag2.DEFAULT_QOS]), HASH_JS)
    bag.topics.append(joints)

    def same(name="bag_0.mcap"):
        assert bag.serialized_metadata(name) == rosbag2.serialized_metadata(bag.metadata(name))

    assert bag.prepare_serialized_metadata("bag_0.mcap") is not None
    same()  # no message yet: start and duration 0
    bag.note_many(joints, 10_000, 1_000_000, 9_999_000_000)
    same()
    events = rosbag2.TopicRecord("/vjm_sim_node/events", "std_msgs/msg/String",
                                 rosbag2.qos_yaml([rosbag2.EVENTS_QOS]), HASH_STR)
    bag.topics.append(events)
    bag.note(events, 12_345_678_901_234)
    same()
    same("other.mcap")
    odd = rosbag2.TopicRecord("/a987654321987654321001", "std_msgs/msg/String",
                              rosbag2.qos_yaml([rosbag2.DEFAULT_QOS]), HASH_STR)
    bag.topics.append(odd)
    bag.note(odd, 2)
    assert bag.prepare_serialized_metadata("bag_0.mcap") is None
    same()
