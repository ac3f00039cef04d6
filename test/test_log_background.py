"""Blocks handed to consumer threads (:mod:`vjm_ros.logs.background`), and ``vjm run`` writing its
outputs that way.

The oracles: the sequence of blocks handed over (each consumer must see it whole and in order);
for ``vjm run``, the same ticks simulated one by one and written by a row-by-row :mod:`csv`
writer (``trajectory.csv`` byte for byte), and the readers of each log after a SIGINT.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from vjm_ros.logs.background import BlockFanOut, Consumer

ROOT = Path(__file__).resolve().parents[1]


class Box:
    """A block: the value it was filled with."""

    def __init__(self):
        self.value = None


def hand_over(fan: BlockFanOut, count: int) -> None:
    """Fill ``count`` blocks with the values 0, 1, ... and hand each over, in order."""
    for i in range(count):
        block = fan.take()
        block.value = i
        fan.put(block)


def test_every_consumer_sees_every_block_in_order_and_blocks_are_reused():
    seen = {"a": [], "b": []}
    finished = []
    made = []

    def make():
        made.append(Box())
        return made[-1]

    def slow(block):  # lags behind: the filler must wait for blocks given back
        time.sleep(0.001)
        seen["b"].append(block.value)

    consumers = [Consumer("a", lambda b: seen["a"].append(b.value), lambda: finished.append("a")),
                 Consumer("b", slow, lambda: finished.append("b"))]
    with BlockFanOut(make, consumers, depth=3) as fan:
        hand_over(fan, 50)
    assert seen == {"a": list(range(50)), "b": list(range(50))}
    assert sorted(finished) == ["a", "b"]
    assert len(made) == 3


def test_a_failing_consumer_is_raised_by_close_after_the_others_finish():
    seen, finished = [], []

    def broken(block):
        if block.value == 5:
            raise RuntimeError("consumer broke")

    consumers = [Consumer("ok", lambda b: seen.append(b.value), lambda: finished.append("ok")),
                 Consumer("broken", broken, lambda: finished.append("broken"))]
    interval = sys.getswitchinterval()
    fan = BlockFanOut(Box, consumers, depth=2)
    with pytest.raises(RuntimeError, match="consumer broke"):
        try:
            hand_over(fan, 20)  # blocks of a failed consumer are still given back
        finally:
            fan.close()
    assert seen == list(range(len(seen))) and len(seen) >= 6
    assert sorted(finished) == ["broken", "ok"]  # files are closed also after a failure
    assert sys.getswitchinterval() == interval
    fan.close()  # idempotent, raises once


def test_a_consumer_that_cannot_start_writes_nothing_and_its_error_is_raised():
    written, finished = {"opens": [], "fails": []}, []

    def cannot_open():
        raise OSError("cannot open")

    consumers = [Consumer("opens", lambda b: written["opens"].append(b.value),
                          lambda: finished.append("opens"), lambda: None),
                 Consumer("fails", lambda b: written["fails"].append(b.value),
                          lambda: finished.append("fails"), cannot_open)]
    fan = BlockFanOut(Box, consumers)
    assert fan.wait_started() is False and fan.start_failed
    with pytest.raises(OSError, match="cannot open"):
        try:
            hand_over(fan, 5)
        finally:
            fan.close()
    assert written["fails"] == [] and finished == ["opens"]  # what opened is closed
    assert written["opens"] == list(range(len(written["opens"])))


def test_all_started_once_every_start_returned():
    release = threading.Event()
    fan = BlockFanOut(Box, [Consumer("slow", lambda b: None, None, release.wait),
                            Consumer("quick", lambda b: None, None, lambda: None)])
    assert not fan.all_started
    release.set()
    assert fan.wait_started() and fan.all_started
    fan.close()


def test_when_a_thread_cannot_be_started_the_others_finish_and_nothing_is_left(monkeypatch):
    finished, interval = [], sys.getswitchinterval()
    real_start, calls = threading.Thread.start, []

    def start(thread):
        calls.append(thread.name)
        if len(calls) == 2:
            raise RuntimeError("can't start new thread")
        real_start(thread)

    monkeypatch.setattr(threading.Thread, "start", start)
    consumers = [Consumer("first", lambda b: None, lambda: finished.append("first"), lambda: None),
                 Consumer("second", lambda b: None, lambda: finished.append("second"))]
    with pytest.raises(RuntimeError, match="can't start"):
        BlockFanOut(Box, consumers)
    monkeypatch.undo()
    for thread in threading.enumerate():
        if thread.name == "first":
            thread.join(timeout=60)  # a hang guard: the thread ends at once
    assert finished == ["first"] and sys.getswitchinterval() == interval


def test_in_the_calling_thread_consumers_see_the_same_blocks(monkeypatch):
    from vjm_ros.logs import background

    monkeypatch.setattr(background, "IN_CALLING_THREAD", True)
    seen, events = [], []
    consumers = [Consumer("a", lambda b: seen.append((threading.current_thread().name, b.value)),
                          lambda: events.append("finish"), lambda: events.append("start"))]
    with BlockFanOut(Box, consumers, depth=2) as fan:
        assert fan.all_started
        hand_over(fan, 5)
    assert seen == [(threading.current_thread().name, i) for i in range(5)]
    assert events == ["start", "finish"]


def test_consumers_run_in_threads_of_their_own():
    names = set()
    with BlockFanOut(Box, [Consumer("vjm-x", lambda b: names.add(
            threading.current_thread().name))]) as fan:
        fan.put(fan.take())
    assert names == {"vjm-x"}


def test_consumers_that_share_a_thread_see_every_block_in_turn():
    """A sequence of consumers shares one thread: each sees every block, in order; they start
    in their order before either writes, and finish after the last block."""
    events: list = []

    def consumer(name):
        return Consumer(name,
                        lambda b: events.append((name, b.value, threading.current_thread().name)),
                        lambda: events.append((name, "finish")),
                        lambda: events.append((name, "start")))

    with BlockFanOut(Box, [[consumer("a"), consumer("b")], consumer("c")], depth=2) as fan:
        hand_over(fan, 20)
    shared = [e for e in events if e[0] in "ab"]
    assert shared[:2] == [("a", "start"), ("b", "start")]
    assert shared[2:-2] == [(n, i, "a + b") for i in range(20) for n in "ab"]
    assert shared[-2:] == [("a", "finish"), ("b", "finish")]
    assert [e[1] for e in events if e[0] == "c" and len(e) == 3] == list(range(20))
    assert {e[2] for e in events if e[0] == "c" and len(e) == 3} == {"c"}


@pytest.mark.parametrize("fails_at", ["start", "write"])
def test_a_consumer_that_fails_stops_alone_in_the_thread_it_shares(fails_at):
    """The consumer beside one that fails at a block writes every block handed over, and the
    failed one is handed no more; beside one that cannot start, the other starts and is
    finished (the next ``put`` raises, as for a consumer in a thread of its own); each failure
    is raised in the calling thread."""
    seen, finished, tried = [], [], []
    handed = threading.Event()  # the write case: every block is queued before the failure

    def cannot_open():
        raise OSError("cannot open")

    def broken(block):
        tried.append(block.value)
        if block.value >= 3:
            raise RuntimeError("consumer broke")

    bad = Consumer("bad", broken, lambda: finished.append("bad"),
                   cannot_open if fails_at == "start" else handed.wait)
    good = Consumer("good", lambda b: seen.append(b.value), lambda: finished.append("good"))
    fan = BlockFanOut(Box, [[bad, good]], depth=10)
    if fails_at == "start":
        assert fan.wait_started() is False
    with pytest.raises(OSError if fails_at == "start" else RuntimeError):
        try:
            hand_over(fan, 10)
        finally:
            handed.set()
            fan.close()
    if fails_at == "start":
        assert seen == tried == [] and finished == ["good"]
    else:
        assert seen == list(range(10)) and tried == [0, 1, 2, 3]
        assert finished == ["bad", "good"]


def _priority() -> int:
    return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread nice is Linux's")
def test_consumers_and_the_threads_they_start_run_at_a_lower_priority():
    from vjm_ros.logs import background

    caller = _priority()
    seen = {}

    def start():
        seen["start"] = _priority()
        child = threading.Thread(target=lambda: seen.setdefault("child", _priority()))
        child.start()
        child.join()

    with BlockFanOut(Box, [Consumer("vjm-x", lambda b: seen.setdefault("write", _priority()),
                                    start=start)]) as fan:
        fan.put(fan.take())
    lowered = min(caller + background.NICENESS, 19)
    assert lowered > caller or caller == 19
    assert seen == {"start": lowered, "child": lowered, "write": lowered}
    assert _priority() == caller  # the physics' thread keeps its priority


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread policies are Linux's")
def test_consumers_of_a_realtime_thread_return_to_normal_scheduling():
    """The node's tick loop may run under SCHED_FIFO (``realtime_priority``) and starts the log
    thread: that thread must not inherit the real-time policy, where its nice is ignored."""
    seen = {}

    def run():
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        except OSError:
            seen["refused"] = True
            return
        with BlockFanOut(Box, [Consumer("vjm-x", lambda b: seen.setdefault(
                "consumer", os.sched_getscheduler(0)))]) as fan:
            fan.put(fan.take())
        seen["caller"] = os.sched_getscheduler(0)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    if seen.get("refused"):
        pytest.skip("SCHED_FIFO not permitted here")
    assert seen == {"consumer": os.SCHED_OTHER, "caller": os.SCHED_FIFO}


# ---------------------------------------------------------------- vjm run
def row_by_row_csv(scene_name: str, ticks: int) -> bytes:
    """The oracle: the run simulated tick by tick, one ``csv.writer`` row per sample."""
    import csv
    import io

    from vjm_ros.app import cli
    from vjm_ros.scene.loader import load_scene
    from vjm_ros.sim.simulator import Simulator
    from vjm_ros.sim.trajectory import Trajectory

    args = cli._parser().parse_args(["run", scene_name, "--integrator", "rk4", "--closure",
                                     "exact"])
    scene = load_scene(scene_name)
    sim = Simulator(scene.model, cli._settings(args, scene), scene.gains)
    sim.set_efforts(np.array([a.effort for a in scene.model.actuators]))
    traj = Trajectory(scene.model)
    traj.append(sim.sample())
    for _ in range(ticks):
        sim.advance()
        traj.append(sim.sample())
    fh = io.StringIO(newline="")
    w = csv.writer(fh)
    w.writerow(traj.columns())
    for row in traj.table():
        w.writerow([repr(float(x)) for x in row])
    return fh.getvalue().encode()


def test_vjm_run_writes_the_csv_of_the_ticks_one_by_one_with_every_log(tmp_path):
    from vjm_ros.app import cli

    out = tmp_path / "out"
    code = cli.main(["run", "four_bar", "--integrator", "rk4", "--closure", "exact",
                     "--duration", "0.437", "--out", str(out), "--mcap",
                     str(tmp_path / "run.mcap"), "--rrd", str(tmp_path / "run.rrd"), "--json"])
    assert code == 0
    assert (out / "trajectory.csv").read_bytes() == row_by_row_csv("four_bar", 437)


@pytest.mark.parametrize("mcap_option", ["--mcap", "--bag"])
def test_vjm_run_writes_the_mcap_log_in_a_thread_of_its_own(tmp_path, monkeypatch, mcap_option):
    """The MCAP log (a file or a rosbag2 directory) has a writing thread of its own; the rerun
    log shares the trajectory's (app/run_outputs.py, OWN_THREAD)."""
    from vjm_ros.app import cli
    from vjm_ros.logs.mcap_recorder import McapRecorder
    from vjm_ros.logs.rerun_recorder import RerunRecorder
    from vjm_ros.sim.trajectory import Trajectory

    threads: dict[str, set] = {"mcap": set(), "rrd": set(), "csv": set()}
    for key, cls in (("mcap", McapRecorder), ("rrd", RerunRecorder), ("csv", Trajectory)):
        method = "extend" if cls is Trajectory else "write_block"
        real = getattr(cls, method)

        def spy(self, block, _real=real, _key=key):
            threads[_key].add(threading.current_thread().name)
            return _real(self, block)

        monkeypatch.setattr(cls, method, spy)
    target = tmp_path / ("run.mcap" if mcap_option == "--mcap" else "bag")
    code = cli.main(["run", "four_bar", "--integrator", "rk4", "--closure", "exact",
                     "--duration", "0.3", "--out", str(tmp_path / "out"), mcap_option,
                     str(target), "--rrd", str(tmp_path / "run.rrd"), "--json"])
    assert code == 0
    assert len(threads["mcap"]) == 1 and threads["rrd"] == threads["csv"], threads
    assert len(threads["rrd"]) == 1 and threads["rrd"] != threads["mcap"], threads
    assert threading.current_thread().name not in threads["mcap"] | threads["rrd"]


def test_the_wait_for_the_outputs_after_the_last_tick_is_reported(tmp_path, monkeypatch, capsys):
    """``outputs_wait_time`` is the part of ``wall_time`` after the last tick: a log whose
    finalization takes 0.3 s (a slow disk) shows in it whole, and the ticks before do not."""
    from vjm_ros.app import cli
    from vjm_ros.logs.mcap_recorder import McapRecorder

    real = McapRecorder._finalize

    def slow_finalize(self):
        time.sleep(0.3)
        real(self)

    monkeypatch.setattr(McapRecorder, "_finalize", slow_finalize)
    code = cli.main(["run", "four_bar", "--duration", "0.2", "--mcap", str(tmp_path / "run.mcap"),
                     "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    # the sleep lies between the last tick and the end of wall_time (sleep overshoots, never
    # undershoots); the 200 ticks before it are not in the wait
    assert 0.3 <= summary["outputs_wait_time"] <= summary["wall_time"]
    assert summary["wall_time"] - summary["outputs_wait_time"] > 0.0
    assert summary["ticks"] == 200


def test_a_signal_while_the_run_starts_up_stops_it_before_its_first_tick(tmp_path, monkeypatch,
                                                                        capsys):
    """SIGINT while the scene loads (before the run's own handling, where Python's default
    handler raised a KeyboardInterrupt that numba's cache loading could swallow): the run
    stops before its first tick with 130, its MCAP log finalized (read back by the ``mcap``
    reader) with the first sample only."""
    from mcap.reader import make_reader

    from vjm_ros.app import cli
    from vjm_ros.scene import loader

    load = loader.load_scene

    def load_and_interrupt(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        return load(*args, **kwargs)

    monkeypatch.setattr(loader, "load_scene", load_and_interrupt)
    mcap = tmp_path / "run.mcap"
    code = cli.main(["run", "four_bar", "--duration", "600", "--mcap", str(mcap), "--json"])
    assert code == 130
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["steps"] == 0 and summary["error"] == "interrupted by signal 2"
    with open(mcap, "rb") as f:
        clock = [m for _, ch, m in make_reader(f).iter_messages() if ch.topic == "/clock"]
    assert len(clock) == 1 and clock[0].log_time == 0


def test_a_log_that_cannot_be_opened_stops_the_run_before_any_output(tmp_path, monkeypatch):
    from mcap.reader import make_reader

    from vjm_ros.app import cli
    from vjm_ros.logs import rerun_recorder

    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(rerun_recorder.RerunRecorder, "__init__", refuse)
    out, mcap = tmp_path / "out", tmp_path / "run.mcap"
    code = cli.main(["run", "four_bar", "--duration", "0.5", "--out", str(out), "--mcap",
                     str(mcap), "--rrd", str(tmp_path / "run.rrd")])
    assert code == cli.EXIT_BAD_INPUT
    assert not (out / "trajectory.csv").exists() and not (out / "summary.json").exists()
    with mcap.open("rb") as f:  # the log that did open is finalized, with the first sample only
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.message_count > 0


@pytest.mark.parametrize("sig", [signal.SIGINT,
                                 pytest.param(signal.SIGTERM, marks=pytest.mark.slow)])
def test_a_signal_mid_run_leaves_every_output_complete(tmp_path, sig):
    from mcap.reader import make_reader

    out, mcap, rrd = tmp_path / "out", tmp_path / "run.mcap", tmp_path / "run.rrd"
    proc = subprocess.Popen(
        [sys.executable, "-m", "vjm_ros.app.cli", "run", "six_bar", "--duration", "600",
         "--out", str(out), "--mcap", str(mcap), "--rrd", str(rrd), "--json"],
        cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)), stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120  # a hang guard, not a speed assertion
        csv_path = out / "trajectory.csv"
        while not (csv_path.is_file() and csv_path.stat().st_size > 100_000):
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
            time.sleep(0.05)
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 128 + sig, stderr
    summary = json.loads(stdout.strip().splitlines()[-1])
    rows = csv_path.read_bytes().split(b"\r\n")
    assert rows[-1] == b"" and len(rows) - 2 == summary["ticks"] + 1  # header, every tick
    assert float(rows[-2].split(b",")[0]) == pytest.approx(summary["sim_time"])
    with mcap.open("rb") as f:
        reader = make_reader(f)
        stats = reader.get_summary().statistics
        count = sum(1 for _ in reader.iter_messages())
    assert count == stats.message_count
    ticks = count_ticks(mcap)
    assert ticks == summary["ticks"] + 1  # the first sample and every tick of the run
    verify = subprocess.run([str(Path(sys.executable).with_name("rerun")), "rrd", "verify",
                             str(rrd)], capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stdout + verify.stderr


def count_ticks(path: Path) -> int:
    """Messages on ``/clock`` in an MCAP file: one per tick."""
    from mcap.reader import make_reader

    with path.open("rb") as f:
        return sum(1 for _ in make_reader(f).iter_messages(topics=["/clock"]))
