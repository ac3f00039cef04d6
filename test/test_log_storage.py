"""Log paths and full disks: refused at start with the path named; a log that fails mid-run is given
up while the run goes on (``vjm run`` exits 4, the node reports ``log_failed`` and keeps running).

``/dev/full`` stands for a disk that fills up: it opens, and every write fails with ENOSPC.
"""

import errno
import json
import os
import subprocess
import sys
from collections import namedtuple
from pathlib import Path

import pytest

from vjm_ros.core.errors import ConfigurationError
from vjm_ros.logs import storage
from vjm_ros.logs.storage import LogWriters, check_log_path, is_file_target
from vjm_ros.realtime.commands import CommandBuffer
from vjm_ros.realtime.loop import DURATION, LoopOptions, TickLoop
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

ROOT = Path(__file__).resolve().parents[1]
Usage = namedtuple("Usage", "total used free")


def test_a_log_path_that_cannot_be_written_is_refused_naming_it(tmp_path):
    with pytest.raises(ConfigurationError, match=r"--mcap .*no/such/dir/x.mcap: cannot write the log"):
        check_log_path(tmp_path / "no" / "such" / "dir" / "x.mcap", "--mcap")
    with pytest.raises(ConfigurationError, match="expected a file path, found a directory"):
        check_log_path(tmp_path, "mcap")
    assert check_log_path(tmp_path / "ok.mcap", "--mcap") == tmp_path / "ok.mcap"


def test_a_nearly_full_disk_is_refused_with_the_space_needed(tmp_path, monkeypatch):
    monkeypatch.setattr(storage.shutil, "disk_usage", lambda p: Usage(1 << 30, 0, 10 * 2**20))
    with pytest.raises(ConfigurationError, match=r"only 10 MB free .* at least 64 MB"):
        check_log_path(tmp_path / "x.mcap", "--mcap")
    # A long run needs more: 20 MB per simulated minute at 1 kHz (600 s: 200 MB).
    monkeypatch.setattr(storage.shutil, "disk_usage", lambda p: Usage(1 << 30, 0, 100 * 2**20))
    check_log_path(tmp_path / "x.mcap", "--mcap", sim_seconds=60.0)
    with pytest.raises(ConfigurationError, match="at least 200 MB"):
        check_log_path(tmp_path / "x.mcap", "--mcap", sim_seconds=600.0)


def test_viewer_targets_are_not_files():
    assert is_file_target("run.rrd") and is_file_target("/tmp/run.mcap")
    assert not any(map(is_file_target, ["spawn", "connect", "rerun+http://127.0.0.1:9876/proxy"]))


class Recorder:
    def __init__(self, path, fail_at=None):
        self.path, self.fail_at, self.samples, self.closed = path, fail_at, 0, False

    def write(self, sample):
        if self.fail_at is not None and self.samples >= self.fail_at:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.samples += 1

    def note_reset(self, t, tick=None):
        pass

    def close(self):
        self.closed = True


class Notices:
    def __init__(self):
        self.seen = []

    def notice(self, kind, text):
        self.seen.append((kind, text))

    def __getattr__(self, name):  # every other output: ignored
        return lambda *args: None


def test_the_tick_loop_gives_up_a_failing_log_and_goes_on():
    scene = load_scene("four_bar")
    sim = Simulator(scene.model, SimulationSettings(), scene.gains)
    commands = CommandBuffer(sim.model.actuator_names, sim.model.joint_names, sim.limits, 0.0)
    bad, good = Recorder("/full/disk.mcap", fail_at=5), Recorder("/good.mcap")
    out = Notices()
    loop = TickLoop(sim, commands, out, LoopOptions(realtime=False, marker_period=0.0,
                                                    duration=0.05), [bad, good])
    assert loop.run() == DURATION and sim.ticks == 50
    assert good.samples == 51 and bad.samples == 5 and bad.closed
    failed = [text for kind, text in out.seen if kind == "log_failed"]
    assert len(failed) == 1 and "/full/disk.mcap" in failed[0] and "No space left" in failed[0]
    assert loop.recorders == [good]


def test_log_writers_report_a_log_that_cannot_be_finalized():
    class Unclosable(Recorder):
        def close(self):
            raise OSError(errno.EIO, os.strerror(errno.EIO))

    seen = []
    logs = LogWriters([Unclosable("/x.mcap")], lambda where, why: seen.append((where, why)))
    logs.close()
    assert seen == [("/x.mcap", os.strerror(errno.EIO))] and logs.failed == seen


def test_vjm_run_with_a_disk_that_fills_up_keeps_its_other_outputs_and_exits_4(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, "-m", "vjm_ros.app.cli", "run", "four_bar", "--duration", "0.5",
         "--mcap", "/dev/full", "--out", str(out), "--json"],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
        env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 4, proc.stderr
    assert "log /dev/full could not be written (No space left on device)" in proc.stderr
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert summary["steps"] == 500 and "/dev/full" in summary["error"]
    rows = (out / "trajectory.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 501  # header and every tick: the run went on
