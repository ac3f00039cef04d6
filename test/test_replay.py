"""Replay of an MCAP log into rerun, and recovery of logs cut short (truncation, SIGKILL)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from conftest import four_bar_samples
from mcap.reader import make_reader
from rerun.chunk import RrdReader

from vjm_ros.logs.mcap_recorder import McapRecorder
from vjm_ros.logs.replay import read_info, recover, replay

REPO = Path(__file__).resolve().parents[1]
RERUN = Path(sys.executable).with_name("rerun")
TICKS = 400


@pytest.fixture(scope="module")
def run():
    return four_bar_samples(TICKS)


@pytest.fixture(scope="module")
def log(run, tmp_path_factory):
    """A finalized log with small chunks and a reset after 300 ticks."""
    scene, sim, samples = run
    path = tmp_path_factory.mktemp("replay") / "run.mcap"
    with McapRecorder(path, scene.model, sim.describe(), scene.text, chunk_seconds=0.05) as rec:
        for s in samples[:300]:
            rec.write(s)
        rec.note_reset(samples[299].t)
        for s in samples[300:]:
            rec.write(s)
    return path, rec.message_count


def series(path: Path, entity: str, component: str) -> tuple[list, list]:
    """Times (ns) and values of one temporal component, in time order."""
    times, values = [], []
    for chunk in RrdReader(path).store().stream():
        if str(chunk.entity_path) == entity and not chunk.is_static:
            batch = chunk.to_record_batch()
            if component in batch.schema.names:
                times += batch.column("sim_time").cast(pa.int64()).to_pylist()
                values += batch.column(component).to_pylist()
    order = np.argsort(times, kind="stable")
    return [times[i] for i in order], [values[i] for i in order]


def test_replay_rebuilds_the_mechanism_and_the_series(run, log, tmp_path):
    scene, _, samples = run
    path, _ = log
    out = tmp_path / "replay.rrd"
    info = replay(path, out)
    assert info["scene"] == "four_bar" and info["samples"] == TICKS and info["complete"]
    assert info["events"] == 1 and info["messages"]["/joint_states"] == TICKS
    check = subprocess.run(
        [RERUN, "rrd", "verify", out], capture_output=True, text=True, timeout=60
    )
    assert check.returncode == 0, check.stderr

    entities = set(RrdReader(out).store().schema().entity_paths())
    assert {
        "/mechanism/links",
        "/mechanism/joints",
        "/mechanism/forces",
        "/mechanism/traces",
        "/series/joints/position",
        "/series/energy",
        "/series/constraint_forces",
        "/series/closure_error",
        "/events",
    } <= entities

    times, q = series(out, "/series/joints/position", "Scalars:scalars")
    assert len(times) == TICKS
    np.testing.assert_array_equal(np.array(q), np.array([s.q for s in samples]))
    _, energy = series(out, "/series/energy", "Scalars:scalars")
    np.testing.assert_array_equal(np.array(energy), np.array([s.energy for s in samples]))
    _, error = series(out, "/series/closure_error", "Scalars:scalars")
    np.testing.assert_allclose(
        np.array(error)[:, 0], [s.closure_error[0] for s in samples], atol=1e-12
    )
    # The mechanism is redrawn from the joint states with the package's kinematics.
    link_times, strips = series(out, "/mechanism/links", "LineStrips2D:strips")
    assert len(link_times) == TICKS // 10
    for k in (0, 17, 35):
        np.testing.assert_allclose(np.array(strips[k]), samples[10 * k].segments, atol=1e-6)
    _, events = series(out, "/events", "TextLog:text")
    # the line the node publishes on ~/events (the first episode ends at 0.3 s, 1 ms ticks)
    assert events == [["reset: reset to the initial state after t = 0.3 s; simulated time goes on from t = 0.301 s"]]


def test_replay_reads_a_truncated_log(log, tmp_path):
    path, _ = log
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    info = replay(cut, tmp_path / "cut.rrd")
    assert not info["complete"]
    assert 0 < info["samples"] < TICKS
    (line,) = info["damage"]  # where reading stopped, named for the user
    assert str(cut) in line and "reading stopped at byte" in line
    assert f"of {cut.stat().st_size}" in line
    assert replay(path, tmp_path / "whole.rrd")["damage"] == []  # a finalized log is whole


def test_recover_keeps_every_complete_chunk(log, tmp_path):
    path, written = log
    data = path.read_bytes()
    with open(path, "rb") as f:
        reader = make_reader(f)
        chunks = reader.get_summary().chunk_indexes
        times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=False)]
    assert len(chunks) > 4 and len(times) == written
    damage: list[str] = []
    assert recover(path, tmp_path / "full.mcap", damage) == written  # copied whole
    assert damage == []
    ends = sorted(c.chunk_start_offset + c.chunk_length for c in chunks)
    for cut_at in (ends[2] - 1, ends[2], ends[3] + 7, len(data) - 20):
        cut = tmp_path / f"cut_{cut_at}.mcap"
        cut.write_bytes(data[:cut_at])
        fixed = tmp_path / f"fixed_{cut_at}.mcap"
        damage = []
        saved = recover(cut, fixed, damage)
        if cut_at < ends[-1]:  # a cut in the data is reported; one in the summary loses nothing
            assert len(damage) == 1 and str(cut) in damage[0], damage
        complete = [c for c in chunks if c.chunk_start_offset + c.chunk_length <= cut_at]
        last_time = max(c.message_end_time for c in complete)
        assert saved == sum(t <= last_time for t in times)  # all complete chunks, nothing else
        with open(fixed, "rb") as f:
            reader = make_reader(f)
            stats = reader.get_summary().statistics
            assert stats.message_count == saved == sum(1 for _ in reader.iter_messages())
            (att,) = list(reader.iter_attachments())
            assert att.name == "scene.yaml"
            assert {m.name for m in reader.iter_metadata()} == {
                "run_settings", "package_versions", "rosbag2"}  # one bag record, recounted
    assert saved == written  # the last cut only lost part of the summary


@pytest.mark.parametrize("command", ["replay", "recover"])
def test_cli_names_where_a_truncated_log_stops(log, tmp_path, command):
    """``vjm replay`` and ``vjm recover`` on a cut log: exit 0 with what could be read, and a
    warning on stderr naming the file and where reading stopped."""
    path, _ = log
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    out = tmp_path / ("cut.rrd" if command == "replay" else "fixed.mcap")
    res = subprocess.run([sys.executable, "-m", "vjm_ros.app.cli", command, str(cut), "-o", str(out)],
                         capture_output=True, text=True, timeout=120,
                         env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"))
    assert res.returncode == 0, res.stderr
    assert f"vjm: warning: {cut}: reading stopped at byte" in res.stderr
    assert out.is_file()


def test_recover_refuses_what_it_cannot_repair(log, tmp_path):
    path, _ = log
    with pytest.raises(ValueError, match="different file"):
        recover(path, path)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    with pytest.raises(ValueError, match="not an MCAP file"):
        recover(junk, tmp_path / "out.mcap")


def test_read_info_finds_scene_and_settings(log, tmp_path):
    path, _ = log
    info = read_info(path)
    assert info.complete
    assert info.settings["rate"] == 1000.0 and info.settings["closure"] == "exact"
    assert info.scene_text.startswith("name: four_bar")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[:-100])
    assert not read_info(cut).complete and read_info(cut).scene_text == info.scene_text


WRITER = """
import sys
from vjm_ros.logs import McapRecorder
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

scene = load_scene("four_bar")
sim = Simulator(scene.model, SimulationSettings(closure="exact"), scene.gains)
rec = McapRecorder(sys.argv[1], scene.model, sim.describe(), scene.text, chunk_seconds=0.05)
while True:
    sim.advance()
    rec.write(sim.sample())
    print(rec.message_count, rec.flushed_count, flush=True)
"""


def test_recover_after_sigkill_saves_almost_everything(tmp_path):
    """A writer killed mid-run loses at most its open chunk (0.05 s here)."""
    path = tmp_path / "killed.mcap"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=REPO,
    )
    lines = []
    try:
        deadline = time.monotonic() + 60  # a hang guard, not a speed assertion
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                raise AssertionError(f"writer ended early: {proc.stderr.read()}")
            lines.append(line)
            if int(line.split()[0]) >= 10_000:  # about 2 s of simulated time
                break
        proc.send_signal(signal.SIGKILL)
        out, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    last = [ln for ln in (lines + out.splitlines()) if len(ln.split()) == 2][-1]
    written, flushed = (int(v) for v in last.split())
    saved = recover(path, tmp_path / "saved.mcap")
    assert saved >= flushed  # every chunk handed to the OS survives
    assert saved >= 0.95 * written, (saved, written)
