"""The ``vjm`` command line contract of docs/design.md section 5, through the installed entry point."""

import csv
import json
import os
import resource
import subprocess
import sys

import pytest

from vjm_ros.scene.loader import builtin_scenes, load_scene

SUMMARY_KEYS = {
    "scene",
    "integrator",
    "closure",
    "rate",
    "substeps",
    "sim_time",
    "wall_time",
    "cpu_time",
    "outputs_wait_time",
    "steps",
    "realtime_factor",
    "max_closure_error",
    "rms_closure_error",
    "energy_drift",
    "energy_balance_residual",
    "finite",
}


def vjm(*args, cwd=None):
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return subprocess.run(
        [sys.executable, "-m", "vjm_ros.app.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=cwd,
        env=env,
    )


def expected_columns(model):
    cols = ["t"]
    for j in model.joint_names:
        cols += [f"q.{j}", f"qd.{j}", f"qdd.{j}", f"effort.{j}"]
    cols += [f"theta.{lk}" for lk in model.link_names]
    for p in model.points:
        cols += [f"x.{p.name}", f"y.{p.name}"]
    for c in model.closures:
        cols += [f"f.{c.name}.z"] if c.kind == "angle" else [f"f.{c.name}.x", f"f.{c.name}.y"]
    return cols + [
        "energy.kinetic",
        "energy.potential",
        "energy.constraint",
        "energy.total",
        "closure_error",
    ]


def test_scenes_lists_builtins():
    out = vjm("scenes")
    assert out.returncode == 0, out.stderr
    listed = {line.split()[0] for line in out.stdout.splitlines() if line.strip()}
    assert listed == set(builtin_scenes())


def test_closed_output_pipe_ends_quietly():
    """``vjm scenes | head -1``: the reader goes away before the listing is written; the command
    stops with the shell's SIGPIPE code and no traceback (the read end is closed before the
    process can write, so the write always fails)."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.Popen([sys.executable, "-m", "vjm_ros.app.cli", "scenes"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    proc.stdout.close()
    try:
        stderr = proc.communicate(timeout=120)[1].decode()
    finally:
        proc.kill()
    assert proc.returncode == 141, stderr
    assert stderr == ""


@pytest.mark.parametrize("scene", ["six_bar", "rrr_platform"])
def test_run_writes_contract(tmp_path, scene):
    """trajectory.csv columns, summary.json keys and the --json last line."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = vjm("run", scene, "--duration", "0.05", "--out", str(tmp_path), "--json")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert out.returncode == 0, out.stderr
    last = json.loads(out.stdout.strip().splitlines()[-1])
    assert SUMMARY_KEYS <= set(last)
    # cpu_time spans the run, not the process: 50 ticks take ms, the interpreter's start-up and
    # imports some 0.5-1 s of CPU; and no more CPU time than the machine's cores give in the
    # run's wall time (5 ms for the two clocks being read one after the other)
    process_cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    assert 0.0 <= last["cpu_time"] < 0.1 * process_cpu
    assert last["cpu_time"] <= last["wall_time"] * os.cpu_count() + 5e-3
    assert 0.0 <= last["outputs_wait_time"] <= last["wall_time"]
    assert last["scene"] == scene and last["finite"] is True
    assert last["steps"] == 50 and abs(last["sim_time"] - 0.05) < 1e-12
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(summary)
    with (tmp_path / "trajectory.csv").open() as fh:
        rows = list(csv.reader(fh))
    model = load_scene(scene).model
    assert rows[0] == expected_columns(model)
    assert len(rows) == 1 + 51  # t = 0 and 50 ticks
    assert float(rows[-1][0]) == pytest.approx(0.05, abs=1e-12)


def test_effort_and_flags(tmp_path):
    """--effort, --closure exact and --integrator reach the run; the effort column shows it."""
    out = vjm(
        "run",
        "pendulum",
        "--duration",
        "0.01",
        "--effort",
        "1.5",
        "--closure",
        "exact",
        "--integrator",
        "semi_implicit_euler",
        "--out",
        str(tmp_path),
        "--json",
    )
    assert out.returncode == 0, out.stderr
    s = json.loads(out.stdout.strip().splitlines()[-1])
    assert s["closure"] == "exact" and s["integrator"] == "semi_implicit_euler"
    with (tmp_path / "trajectory.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert float(rows[-1]["effort.pivot"]) == 1.5


def test_run_prints_its_summary_one_key_per_line(tmp_path):
    """Without --json, the summary's contract keys and the run's costs, one per line, in order."""
    out = vjm("run", "four_bar", "--duration", "0.05", "--mcap", str(tmp_path / "run.mcap"))
    assert out.returncode == 0, out.stderr
    lines = dict(line.split(None, 1) for line in out.stdout.strip().splitlines())
    assert list(lines) == ["scene", "integrator", "closure", "rate", "substeps", "sim_time",
                           "wall_time", "cpu_time", "outputs_wait_time", "steps",
                           "realtime_factor", "max_closure_error", "rms_closure_error",
                           "energy_drift", "energy_balance_residual", "finite"]
    assert SUMMARY_KEYS <= set(lines)
    assert lines["scene"] == "four_bar" and lines["steps"] == "50" and lines["finite"] == "True"
    assert 0.0 <= float(lines["outputs_wait_time"]) <= float(lines["wall_time"])


def test_bad_inputs_exit_2():
    """Unknown scene, wrong effort count and stiff gains are refused before running."""
    out = vjm("run", "no_such_scene")
    assert out.returncode == 2 and "no_such_scene" in out.stderr
    out = vjm("run", "five_bar", "--effort", "1.0", "--duration", "0.01")
    assert out.returncode == 2 and "efforts" in out.stderr
    out = vjm("run", "four_bar", "--kp", "1e9", "--kv", "0", "--duration", "0.01")
    assert out.returncode == 2 and "stability bound" in out.stderr and "tip_pin" in out.stderr
    out = vjm("run", "four_bar", "--integrator", "nope")
    assert out.returncode == 2 and "rk4" in out.stderr
    out = vjm("run", "four_bar", "--kernel", "numpy", "--duration", "0.01")
    assert out.returncode == 2 and "no longer a choice" in out.stderr and "'auto'" in out.stderr


def test_growing_blocks_write_what_whole_blocks_write(tmp_path, monkeypatch):
    """``vjm run`` computes its first blocks short and growing (``FIRST_BLOCK_TICKS``, half as
    many ticks more each, up to ``RUN_BLOCK_TICKS``); the CSV is byte for byte, and the MCAP
    messages (read by the ``mcap`` reader) are, those of the same run in 1000-tick blocks from
    the first tick. The blocks' sizes are recorded to show that the two runs did block the
    ticks differently."""
    from mcap.reader import make_reader

    from vjm_ros.app import cli
    from vjm_ros.sim import samples
    from vjm_ros.sim.simulator import Simulator

    sizes: list[int] = []
    advance = Simulator.advance_block

    def recorded(self, block, ticks):
        sizes.append(ticks)
        return advance(self, block, ticks)

    monkeypatch.setattr(Simulator, "advance_block", recorded)
    runs = {}
    default, whole_blocks = samples.FIRST_BLOCK_TICKS, samples.RUN_BLOCK_TICKS
    for first in (default, whole_blocks):
        monkeypatch.setattr(samples, "FIRST_BLOCK_TICKS", first)
        sizes.clear()
        out = tmp_path / str(first)
        assert cli.main(["run", "four_bar", "--integrator", "rk4", "--closure", "exact",
                         "--duration", "2.5", "--out", str(out), "--mcap",
                         str(out / "run.mcap")]) == 0
        with (out / "run.mcap").open("rb") as fh:
            messages = [(channel.topic, message.log_time, message.sequence, message.data)
                        for _, channel, message in make_reader(fh).iter_messages()]
        runs[first] = (list(sizes), (out / "trajectory.csv").read_bytes(), messages)
    growing, whole = runs[default], runs[whole_blocks]
    assert growing[0] == [100, 150, 225, 337, 505, 757, 426]
    assert whole[0] == [1000, 1000, 500]
    assert growing[1] == whole[1]
    assert len(growing[2]) > 5 * 2500 and growing[2] == whole[2]
