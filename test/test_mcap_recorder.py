"""MCAP recorder: ROS 2 profile round trip, encoders, chunking, finalization on SIGTERM."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags_cdr import serialize
from test_cdr_rosbags import _encoded as encoded

from vjm_ros.logs import Timebase, cdr, finalize_on_signals, messages, msgdefs
from vjm_ros.logs.mcap_recorder import McapRecorder
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

REPO = Path(__file__).resolve().parents[1]
RERUN = Path(sys.executable).with_name("rerun")
TICKS = 300
RESET_TICKS = 40


@pytest.fixture(scope="module")
def run():
    """Four-bar samples: ``TICKS`` ticks, then (after a reset) ``RESET_TICKS`` more."""
    scene = load_scene("four_bar")
    sim = Simulator(scene.model, SimulationSettings(closure="exact"), scene.gains)
    first = []
    for _ in range(TICKS):
        sim.advance()
        first.append(sim.sample())
    sim.reset()
    second = [sim.sample()]
    for _ in range(RESET_TICKS - 1):
        sim.advance()
        second.append(sim.sample())
    return scene, sim, first, second


@pytest.fixture(scope="module")
def log(run, tmp_path_factory):
    """A finalized log of ``run``: the recorder and the file path."""
    scene, sim, first, second = run
    path = tmp_path_factory.mktemp("mcap") / "run.mcap"
    with McapRecorder(path, scene.model, sim.describe(), scene.text) as rec:
        for s in first:
            rec.write(s)
        rec.note_reset(first[-1].t)
        for s in second:
            rec.write(s)
    return rec, path


def summary_of(path):
    """Header and summary of a finalized log."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        return reader.get_header(), reader.get_summary()


def read_all(path):
    """Summary, schema name per topic, decoded messages per topic, attachments, metadata."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        by_topic: dict[str, list] = {}
        types = {}
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            types[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
            by_topic.setdefault(channel.topic, []).append((message, decoded))
        attachments = list(reader.iter_attachments())
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    return summary, types, by_topic, attachments, metadata


def test_every_topic_round_trips_through_the_ros2_decoder(run, log):
    scene, sim, first, second = run
    rec, path = log
    model = scene.model
    summary, types, by_topic, attachments, metadata = read_all(path)

    assert summary_of(path)[0].profile == "ros2"
    assert summary.statistics.message_count == rec.message_count
    assert summary.statistics.chunk_count >= 1
    wrench = "/vjm_sim_node/closures/tip_pin/wrench"
    expected = {
        "/joint_states": "sensor_msgs/msg/JointState",
        "/vjm_sim_node/constraint_forces": "std_msgs/msg/Float64MultiArray",
        wrench: "geometry_msgs/msg/WrenchStamped",
        "/vjm_sim_node/energy": "std_msgs/msg/Float64MultiArray",
        "/clock": "rosgraph_msgs/msg/Clock",
        "/vjm_sim_node/markers": "visualization_msgs/msg/MarkerArray",
        "/vjm_sim_node/events": "std_msgs/msg/String",
    }
    assert {t: v[0] for t, v in types.items()} == expected
    assert all(v[1:] == ("ros2msg", "cdr") for v in types.values())

    samples = first + second
    n = len(samples)
    tick = 1_000_000  # ns at 1 kHz
    end = round(first[-1].t * 1e9)
    times = [round(s.t * 1e9) for s in first] + [end + tick + round(s.t * 1e9) for s in second]
    assert np.all(np.diff(times) > 0)

    joints = by_topic["/joint_states"]
    assert len(joints) == n
    for (msg, js), s, ns in zip(joints, samples, times, strict=True):
        assert msg.log_time == msg.publish_time == ns
        assert js.header.stamp.sec * 10**9 + js.header.stamp.nanosec == ns
        assert js.header.frame_id == "world"
        assert js.name == model.joint_names
        assert js.position == s.q.tolist()
        assert js.velocity == s.qd.tolist()
        assert js.effort == s.effort.tolist()

    forces = by_topic["/vjm_sim_node/constraint_forces"]
    assert len(forces) == n
    for (msg, fa), s, ns in zip(forces, samples, times, strict=True):
        assert msg.log_time == ns
        assert [d.label for d in fa.layout.dim] == model.closure_names
        assert all(d.size == 3 and d.stride == 3 for d in fa.layout.dim)
        assert fa.data == s.closure_force.reshape(-1).tolist()

    for (_msg, w), s in zip(by_topic[wrench], samples, strict=True):
        assert w.header.frame_id == "world"
        f = s.closure_force[0]
        assert (w.wrench.force.x, w.wrench.force.y, w.wrench.force.z) == (f[0], f[1], 0.0)
        assert (w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z) == (0.0, 0.0, f[2])

    for (_msg, e), s in zip(by_topic["/vjm_sim_node/energy"], samples, strict=True):
        assert [d.label for d in e.layout.dim] == ["kinetic", "potential", "constraint", "total"]
        assert e.data == s.energy.tolist()

    for (msg, c), ns in zip(by_topic["/clock"], times, strict=True):
        assert c.clock.sec * 10**9 + c.clock.nanosec == msg.log_time == ns

    markers = by_topic["/vjm_sim_node/markers"]
    assert len(markers) == math.ceil(TICKS / 10) + math.ceil(RESET_TICKS / 10)
    msg, ma = markers[0]
    kinds = {m.ns: m.type for m in ma.markers}
    assert kinds == {"links": 5, "joints": 7, "constraint_forces": 0}
    links = next(m for m in ma.markers if m.ns == "links")
    assert len(links.points) == 2 * model.n
    assert links.points[1].x == pytest.approx(first[0].segments[0, 1, 0])

    ((msg, event),) = by_topic["/vjm_sim_node/events"]
    # the line the node publishes on ~/events, stating the log's own times (300 ticks of 1 ms)
    assert event.data == ("reset: reset to the initial state after t = 0.3 s; simulated time goes on from t = 0.301 s")
    assert msg.log_time == end + tick == times[TICKS]

    (att,) = attachments
    assert (att.name, att.media_type) == ("scene.yaml", "application/yaml")
    assert att.data.decode() == scene.text
    settings = metadata["run_settings"]
    assert settings["scene"] == "four_bar"
    assert settings["integrator"] == sim.describe()["integrator"]
    assert json.loads(settings["rate"]) == 1000.0
    assert "mcap" in metadata["package_versions"]


def test_rerun_reads_the_log(log, tmp_path):
    rec, path = log
    check = subprocess.run(
        [RERUN, "mcap", "check", path], capture_output=True, text=True, timeout=60
    )
    assert check.returncode == 0, check.stderr
    out = tmp_path / "converted.rrd"
    conv = subprocess.run(
        [
            RERUN,
            "mcap",
            "convert",
            path,
            "-o",
            out,
            "--timeline-type",
            "duration",
            "--application-id",
            "vjm_ros",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert conv.returncode == 0, conv.stderr
    assert "cannot be resolved" not in conv.stderr  # every schema parses with its dependencies
    verify = subprocess.run(
        [RERUN, "rrd", "verify", out], capture_output=True, text=True, timeout=60
    )
    assert verify.returncode == 0, verify.stderr
    from rerun.chunk import RrdReader

    entities = set(RrdReader(out).store().schema().entity_paths())
    assert {"/joint_states/position", "/vjm_sim_node/energy", "/clock"} <= entities


def test_fast_encoders_equal_rosbags_serializer(run):
    """The per-tick fast paths write what rosbags' serializer writes."""
    scene, _, first, _ = run
    model, s, ns = scene.model, first[-1], 1_234_567_890_123
    js = cdr.joint_state_layout(model.joint_names).encode(ns, s.q, s.qd, s.effort)
    assert js == serialize(messages.JOINT_STATE, messages.joint_state(model.joint_names, s, ns))
    layout = messages.labelled_layout(model.closure_names, 3)
    fa = cdr.multi_array_layout(layout, 3 * len(model.closures)).encode(0, s.closure_force)
    assert fa == serialize(
        messages.FLOAT64_MULTI_ARRAY, messages.constraint_forces(model.closure_names, s)
    )
    f = s.closure_force[0]
    w = cdr.wrench_stamped_layout().encode(ns, f[:2], f[2:])
    assert w == serialize(messages.WRENCH_STAMPED, messages.wrench(s, 0, ns))
    assert cdr.CLOCK_LAYOUT.encode(ns) == serialize(messages.CLOCK, messages.clock(ns))


def test_rclpy_decodes_the_encoded_messages(run):
    serialization = pytest.importorskip("rclpy.serialization")
    from geometry_msgs.msg import WrenchStamped
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray, String
    from visualization_msgs.msg import MarkerArray

    scene, _, first, _ = run
    model, s, ns = scene.model, first[7], 3_000_000_001
    decode = serialization.deserialize_message  # the package's encoders, read by rclpy
    js = decode(
        encoded(messages.JOINT_STATE, messages.joint_state(model.joint_names, s, ns)), JointState
    )
    assert list(js.name) == model.joint_names and list(js.position) == s.q.tolist()
    assert (js.header.stamp.sec, js.header.stamp.nanosec) == (3, 1)
    fa = decode(
        encoded(
            messages.FLOAT64_MULTI_ARRAY, messages.constraint_forces(model.closure_names, s)
        ),
        Float64MultiArray,
    )
    assert (
        fa.layout.dim[0].label == "tip_pin"
        and list(fa.data) == s.closure_force.reshape(-1).tolist()
    )
    w = decode(encoded(messages.WRENCH_STAMPED, messages.wrench(s, 0, ns)), WrenchStamped)
    assert w.wrench.force.y == s.closure_force[0, 1]
    assert decode(cdr.CLOCK_LAYOUT.encode(ns), Clock).clock.nanosec == 1
    assert decode(encoded(messages.STRING, messages.event("reset")), String).data == "reset"
    ma = decode(encoded(messages.MARKER_ARRAY, messages.markers(s, ns)), MarkerArray)
    assert [m.type for m in ma.markers] == [5, 7, 0]
    assert ma.markers[1].points[-1].x == s.points[-1, 0]


def test_definitions_carry_their_dependencies():
    text = msgdefs.definition("geometry_msgs/msg/WrenchStamped")
    assert text.startswith("std_msgs/Header header\ngeometry_msgs/Wrench wrench\n")
    for dep in (
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Wrench",
        "geometry_msgs/Vector3",
    ):
        assert f"{'=' * 80}\nMSG: {dep}\n" in text
    assert set(msgdefs.LOGGED_TYPES) <= set(msgdefs.known_types())


def test_chunks_close_every_chunk_seconds(run, tmp_path):
    scene, sim, first, _ = run
    path = tmp_path / "chunks.mcap"
    with McapRecorder(path, scene.model, sim.describe(), scene.text, chunk_seconds=0.05) as rec:
        for s in first:
            rec.write(s)
            assert rec.message_count - rec.flushed_count <= 6 * 51
    summary = summary_of(path)[1]
    spans = [c.message_end_time - c.message_start_time for c in summary.chunk_indexes]
    assert len(spans) >= TICKS * 1e-3 / 0.05
    assert max(spans) <= 0.05e9


def test_vjm_run_closes_a_chunk_every_simulated_second(tmp_path):
    """``vjm run`` writes its MCAP log in chunks of one simulated second (MCAP_CHUNK_SECONDS),
    every message in one of them, in time order, as the reader and rosbags read it."""
    from rosbags.highlevel import AnyReader

    from vjm_ros.app import cli
    from vjm_ros.app.run_outputs import MCAP_CHUNK_SECONDS

    path = tmp_path / "run.mcap"
    assert cli.main(["run", "four_bar", "--duration", "2.5", "--mcap", str(path)]) == 0
    summary = summary_of(path)[1]
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    spans = [(c.message_start_time, c.message_end_time) for c in chunks]
    # 2.5 s: two whole seconds and the half after them (a chunk closes at the first tick a
    # second after its first, so it spans one second exactly; the clock is in whole ns)
    assert len(chunks) == 3
    assert [b - a for a, b in spans[:2]] == [int(MCAP_CHUNK_SECONDS * 1e9)] * 2
    assert all(b[0] > a[1] for a, b in zip(spans[:-1], spans[1:], strict=True))
    with AnyReader([path]) as reader:
        assert sum(1 for _ in reader.messages()) == summary.statistics.message_count


def test_close_is_idempotent_and_write_after_close_fails(run, tmp_path):
    scene, sim, first, _ = run
    rec = McapRecorder(tmp_path / "x.mcap", scene.model, sim.describe(), scene.text)
    rec.write(first[0])
    rec.close()
    rec.close()
    assert rec.closed
    with pytest.raises(ValueError, match="closed"):
        rec.write(first[1])
    assert summary_of(tmp_path / "x.mcap")[1].statistics.message_count == 6


def test_timebase_keeps_time_monotonic_across_resets():
    tb = Timebase(tick=0.001)
    assert tb.reset() == 0  # nothing written yet: no shift
    assert tb.to_ns(0.5) == 500_000_000
    start = tb.reset(0.5)
    assert start == 501_000_000
    assert tb.to_ns(0.0) == start
    assert tb.reset(0.2) == start + 200_000_000 + 1_000_000


def test_finalize_on_signals_turns_sigterm_into_system_exit():
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(SystemExit) as exc:
        with finalize_on_signals():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1.0)  # the handler raises before this ends (a signal, not a speed)
    assert exc.value.code == 128 + signal.SIGTERM
    assert signal.getsignal(signal.SIGTERM) is before


def test_a_signal_during_a_write_takes_effect_when_the_write_returns(run, tmp_path):
    scene, sim, first, _ = run
    path = tmp_path / "atomic.mcap"
    rec = McapRecorder(path, scene.model, sim.describe(), scene.text)
    original = rec._add_run
    sent = []

    def add_with_a_signal(*args):
        if not sent:  # SIGTERM after the tick is encoded, before its messages are added
            sent.append(True)
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.05)  # the handler runs here: it must not raise inside the write
        return original(*args)

    rec._add_run = add_with_a_signal
    with pytest.raises(SystemExit) as exc, finalize_on_signals(), rec:
        rec.write(first[0])
        raise AssertionError("the signal should end the block after the write")
    assert exc.value.code == 128 + signal.SIGTERM
    with open(path, "rb") as f:  # the whole tick is in the finalized log, and nothing else
        reader = make_reader(f)
        stats = reader.get_summary().statistics
        # joints, forces, energy, clock, markers, and one wrench per closure
        tick = 5 + len(scene.model.closures)
        assert stats.message_count == sum(1 for _ in reader.iter_messages()) == tick


WRITER = """
import sys
from vjm_ros.logs import McapRecorder, finalize_on_signals
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

scene = load_scene("four_bar")
sim = Simulator(scene.model, SimulationSettings(closure="exact"), scene.gains)
rec = McapRecorder(sys.argv[1], scene.model, sim.describe(), scene.text, chunk_seconds=0.05)
with finalize_on_signals(), rec:
    while True:
        sim.advance()
        rec.write(sim.sample())
        print(rec.message_count, rec.flushed_count, flush=True)
"""


def start_writer(path: Path) -> subprocess.Popen:
    """A subprocess that records the four-bar to ``path`` until stopped, printing its counts."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=REPO,
    )


def wait_for_messages(proc: subprocess.Popen, count: int, timeout: float = 30.0) -> str:
    """Read the writer's counts until it has written ``count`` messages; the last line read."""
    deadline = time.monotonic() + timeout  # a hang guard, not a speed assertion
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            raise AssertionError(f"writer ended early: {proc.stderr.read()}")
        if int(line.split()[0]) >= count:
            return line
    raise AssertionError("writer too slow")


def last_counts(seen: str, rest: str) -> tuple[int, int]:
    """Messages written and flushed, from the writer's last complete line."""
    lines = [ln for ln in (seen + rest).splitlines() if len(ln.split()) == 2]
    written, flushed = lines[-1].split()
    return int(written), int(flushed)


def test_sigterm_leaves_a_finalized_log(tmp_path):
    path = tmp_path / "term.mcap"
    proc = start_writer(path)
    try:
        seen = wait_for_messages(proc, 1000)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 128 + signal.SIGTERM, err
    written, _ = last_counts(seen, out)
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        stats = reader.get_summary().statistics
        decoded = sum(1 for _ in reader.iter_decoded_messages())
    assert stats.message_count >= written
    assert decoded == stats.message_count
