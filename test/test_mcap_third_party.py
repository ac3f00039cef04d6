"""Our logs read by code that is not ours: rosbags (AnyReader, the rosbag2 Reader) and ``mcap``.

One ``vjm run five_bar --bag`` (1 s at 1 kHz) is the subject. Counts per topic must equal what a
run of that length writes; values decoded by rosbags with its own typestore must equal the
``trajectory.csv`` of the same run (written by a different code path: the CSV table, not the
CDR encoders); the ``mcap`` reader must find valid CRCs, chunk and message indexes, and every
message in time order; rosbag2's per-channel metadata must parse. A truncated copy, repaired by
``vjm recover``, must again be readable by rosbags.
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.metadata import parse_qos

SCENE, SECONDS, RATE = "five_bar", 1.5, 1000  # two chunks (vjm run: a simulated second each)
TICKS = int(SECONDS * RATE) + 1  # the state at t = 0, then one per tick
NODE = "/vjm_sim_node"
PER_TICK = ["/joint_states", "/clock", f"{NODE}/constraint_forces", f"{NODE}/energy",
            f"{NODE}/closures/pin/wrench"]


def vjm(*args, cwd=None):
    out = subprocess.run([sys.executable, "-m", "vjm_ros.app.cli", *args], capture_output=True,
                         text=True, timeout=300, cwd=cwd,
                         env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"))
    assert out.returncode == 0, out.stderr
    return out


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A bag directory and the CSV of the same run."""
    tmp = tmp_path_factory.mktemp("bag")
    bag, out = tmp / "five_bar_bag", tmp / "out"
    vjm("run", SCENE, "--duration", str(SECONDS), "--bag", str(bag), "--out", str(out))
    with (out / "trajectory.csv").open() as f:
        rows = list(csv.DictReader(f))
    return bag, rows


def test_bag_directory_is_what_rosbag2_writes(run):
    bag, _ = run
    assert sorted(p.name for p in bag.iterdir()) == ["five_bar_bag_0.mcap", "metadata.yaml"]
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["five_bar_bag_0.mcap"]
    assert info["duration"]["nanoseconds"] == int(SECONDS * 1e9)


def test_rosbags_reads_every_message_of_the_bag_and_the_file(run):
    bag, _ = run
    for source in (bag, bag / "five_bar_bag_0.mcap"):
        with AnyReader([source]) as reader:
            counts = Counter(c.topic for c, _, _ in reader.messages())
        for topic in PER_TICK:
            assert counts[topic] == TICKS, (source, topic)
        assert counts[f"{NODE}/markers"] == (TICKS + 9) // 10  # every tenth sample, the first too
    with Reader(bag) as reader:  # the rosbag2 reader on the directory: metadata.yaml agrees
        by_topic = {c.topic: c.msgcount for c in reader.connections}
        assert reader.message_count == sum(counts.values())
    assert {t: by_topic[t] for t in PER_TICK} == {t: TICKS for t in PER_TICK}


def test_values_decoded_by_rosbags_equal_the_csv(run):
    bag, rows = run
    joints = ["left_base", "left_elbow", "right_base", "right_elbow"]
    q = np.array([[float(r[f"q.{j}"]) for j in joints] for r in rows])
    t = np.array([float(r["t"]) for r in rows])
    force = np.array([[float(r["f.pin.x"]), float(r["f.pin.y"])] for r in rows])
    got: dict[str, list] = {"/joint_states": [], "/clock": [], f"{NODE}/constraint_forces": []}
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in got]
        for conn, stamp, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/joint_states":
                assert list(msg.name) == joints
                got[conn.topic].append((stamp, msg.header.stamp.sec * 10**9
                                        + msg.header.stamp.nanosec, msg.position))
            elif conn.topic == "/clock":
                got[conn.topic].append(msg.clock.sec * 10**9 + msg.clock.nanosec)
            else:
                assert [(d.label, d.size) for d in msg.layout.dim] == [("pin", 3)]
                got[conn.topic].append(msg.data)
    log_times = np.array([g[0] for g in got["/joint_states"]])
    stamps = np.array([g[1] for g in got["/joint_states"]])
    positions = np.array([g[2] for g in got["/joint_states"]])
    np.testing.assert_array_equal(log_times, stamps)  # log time = header stamp = sim time
    np.testing.assert_allclose(stamps * 1e-9, t, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(np.array(got["/clock"]), stamps)
    # The CSV prints 17 significant digits: equal to the double the log holds.
    np.testing.assert_allclose(positions, q, rtol=1e-15, atol=0)
    forces = np.array(got[f"{NODE}/constraint_forces"])[:, :2]
    np.testing.assert_allclose(forces, force, rtol=1e-15, atol=1e-300)


def test_mcap_reader_validates_crcs_indexes_and_time_order(run):
    bag, _ = run
    with open(bag / "five_bar_bag_0.mcap", "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary.statistics.message_count == sum(summary.statistics.channel_message_counts.values())
        assert summary.chunk_indexes and all(c.message_index_length > 0 for c in summary.chunk_indexes)
        times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
        assert len(times) == summary.statistics.message_count
        assert all(b >= a for a, b in zip(times, times[1:], strict=False))
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert {"run_settings", "package_versions", "rosbag2"} <= set(meta)
    bag_info = yaml.safe_load(meta["rosbag2"]["serialized_metadata"])
    assert bag_info["message_count"] == summary.statistics.message_count
    # rosbag2's MCAP plugin stores the metadata node itself, without the file's top-level key
    # (its reader decodes the record's YAML as the metadata): the same node as metadata.yaml's.
    in_file = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert bag_info == in_file and bag_info["version"] == 9


def test_channel_metadata_parses_as_rosbag2_qos_and_type_hashes(run):
    """Nine keys, integer enums; the type hashes equal the ones ROS 2 Kilted installs."""
    bag, _ = run
    share = Path(sys.prefix) / "share"
    with open(bag / "five_bar_bag_0.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    for channel in summary.channels.values():
        profiles = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert len(profiles) == 1 and len(profiles[0]) == 9
        assert all(isinstance(profiles[0][k], int) for k in ("history", "reliability", "durability"))
        (qos,) = parse_qos(channel.metadata["offered_qos_profiles"])
        assert qos.reliability.name == "RELIABLE" and qos.depth in (10, 100)
        type_name = summary.schemas[channel.schema_id].name
        package, _, name = type_name.split("/")
        installed = share / package / "msg" / f"{name}.json"
        if installed.is_file():  # the interface packages of the ROS 2 wheels
            hashes = json.loads(installed.read_text())["type_hashes"]
            assert channel.metadata["topic_type_hash"] == hashes[0]["hash_string"], type_name


def test_a_truncated_log_recovered_reads_in_rosbags(run, tmp_path):
    bag, _ = run
    path = bag / "five_bar_bag_0.mcap"
    data = path.read_bytes()
    with open(path, "rb") as f:
        chunks = sorted(make_reader(f).get_summary().chunk_indexes,
                        key=lambda c: c.chunk_start_offset)
    assert len(chunks) >= 2
    last = chunks[-1]  # cut inside the last chunk: every chunk before it is complete
    cut, fixed = tmp_path / "cut.mcap", tmp_path / "fixed.mcap"
    cut.write_bytes(data[: last.chunk_start_offset + last.chunk_length // 2])
    from rosbags.highlevel import AnyReaderError

    with pytest.raises(AnyReaderError, match="magic"):  # no summary: rosbags refuses it
        AnyReader([cut]).open()
    out = vjm("recover", str(cut), "-o", str(fixed))
    saved = int(out.stdout.split()[1])  # "recovered N messages into ..."
    with AnyReader([fixed]) as reader:
        counts = Counter(c.topic for c, _, _ in reader.messages())
    assert 0 < counts["/joint_states"] < TICKS
    # the ticks of the complete chunks, every one: those logged before the last chunk's first
    before = round((last.message_start_time - chunks[0].message_start_time) * 1e-9 * RATE)
    assert counts["/joint_states"] == before
    assert sum(counts.values()) == saved
    with open(fixed, "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    info = yaml.safe_load(meta["rosbag2"]["serialized_metadata"])
    assert info["message_count"] == sum(counts.values())
