"""The live loop's logs in blocks (:class:`vjm_ros.logs.rows.LogRows`).

Oracle: the same run's log written sample by sample. A recorder that has no ``write_block`` is
written row by row (:class:`vjm_ros.logs.storage.LogWriters`), which is how every tick reached the
logs before; its MCAP must hold the very messages (topics, times, sequence numbers, bytes) of
the MCAP written in blocks, across efforts that change every tick, a pause with steps and a
reset.
"""

import threading
import time

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from vjm_ros.logs.mcap_recorder import McapRecorder
from vjm_ros.logs.rows import LogRows
from vjm_ros.realtime.commands import CommandBuffer
from vjm_ros.realtime.loop import STOPPED, LoopOptions, TickLoop
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.simulator import SimulationSettings, Simulator


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def samples(n):
    """``n`` samples of a five_bar run whose efforts change every tick."""
    scene = load_scene("five_bar")
    sim = Simulator(scene.model, SimulationSettings(), scene.gains)
    out = []
    for k in range(n):
        sim.advance([0.1 * k * (-1) ** j for j in range(len(sim.model.actuators))])
        out.append(sim.sample())
    return out


def test_rows_are_written_when_the_block_is_full_when_they_waited_and_when_asked():
    model = load_scene("five_bar").model
    written, clock = [], Clock()

    def keep(block):
        written.append([block.sample(i) for i in range(len(block))])

    rows = LogRows(model, keep, capacity=4, max_wait=0.1, clock=clock, background=False)
    run = samples(10)
    for s in run[:4]:
        rows.add(s)
    assert [len(b) for b in written] == [4] and len(rows) == 0  # full
    rows.add(run[4])
    clock.now = 0.05
    rows.add(run[5])
    assert len(written) == 1 and len(rows) == 2
    clock.now = 0.1  # the first waiting row is 0.1 s old
    rows.add(run[6])
    assert [len(b) for b in written] == [4, 3]
    rows.add(run[7])
    rows.flush()
    rows.flush()  # nothing waits: no empty block
    assert [len(b) for b in written] == [4, 3, 1]
    got = [s for block in written for s in block]
    assert len(got) == 8
    for a, b in zip(got, run[:8], strict=True):  # every field, per-tick efforts included
        assert a.t == b.t
        np.testing.assert_array_equal(a.effort, b.effort)
        for name in ("q", "qd", "qdd", "closure_force", "energy", "segments", "points"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert got[7].effort[0] == pytest.approx(0.7)


def test_the_writing_thread_writes_every_row_in_order_and_sync_waits_for_it():
    model = load_scene("five_bar").model
    written, gate = [], threading.Event()

    def slow(block):
        gate.wait(30.0)  # a hang guard; the test opens the gate
        written.extend(block.sample(i).t for i in range(len(block)))

    rows = LogRows(model, slow, capacity=3, depth=2)
    run = samples(8)
    for s in run[:3]:
        rows.add(s)  # the block goes to the thread, which waits at the gate
    assert written == [] and len(rows) == 0
    for s in run[3:5]:
        rows.add(s)
    assert written == [] and len(rows) == 2
    threading.Timer(0.1, gate.set).start()
    for s in run[5:8]:  # the second block is handed over; add waits for the first to be free
        rows.add(s)
    rows.sync()
    assert written == [s.t for s in run]
    rows.close()
    rows.close()


def test_an_error_of_the_writing_thread_is_raised_in_the_ticking_one():
    model = load_scene("four_bar").model
    calls = []

    def fail(block):
        calls.append(len(block))
        raise OSError("disk full")

    rows = LogRows(model, fail, capacity=2)
    scene = load_scene("four_bar")
    sim = Simulator(scene.model, SimulationSettings(), scene.gains)
    rows.add(sim.sample())
    with pytest.raises(OSError, match="disk full"):
        rows.sync()  # the partial block is written (and fails) before sync returns
    assert calls == [1] and len(rows) == 0
    rows.sync()  # raised once
    rows.close()


def test_a_block_with_efforts_per_row_gives_each_row_its_own():
    model = load_scene("four_bar").model
    block = SampleBlock(model, 3)
    block.effort = np.arange(3.0)[:, None] * np.ones(model.n)
    block.rows = 3
    assert [block.sample(i).effort[0] for i in range(3)] == [0.0, 1.0, 2.0]


class RowByRow:
    """A recorder that only takes samples one at a time (the oracle's path)."""

    def __init__(self, inner):
        self.inner = inner
        self.path = inner.path

    def write(self, sample):
        self.inner.write(sample)

    def note_reset(self, t, tick=None):
        self.inner.note_reset(t, tick)

    def close(self):
        self.inner.close()


class Ignored:
    def __getattr__(self, name):  # every output: ignored
        return lambda *args: None


def messages(path):
    with open(path, "rb") as f:
        return [(c.topic, m.log_time, m.publish_time, m.sequence, bytes(m.data))
                for _, c, m in make_reader(f).iter_messages(log_time_order=False)]


def wait_until(condition, what, timeout=30.0):
    deadline = time.monotonic() + timeout  # a hang guard, not a speed target
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.005)


def test_the_loop_logs_in_blocks_what_it_logged_sample_by_sample(tmp_path):
    """Lockstep, so that this test decides every tick: 137 ticks (a block of 100 written, 38
    rows waiting when the reset comes), a reset, 55 more; a new effort every tick."""
    scene = load_scene("four_bar")
    sim = Simulator(scene.model, SimulationSettings(), scene.gains)
    commands = CommandBuffer(sim.model.actuator_names, sim.model.joint_names, sim.limits, 0.0)
    settings = sim.describe()
    blocks = McapRecorder(tmp_path / "blocks.mcap", sim.model, settings, scene.text)
    rows = McapRecorder(tmp_path / "rows.mcap", sim.model, settings, scene.text)
    options = LoopOptions(realtime=False, lockstep=True, lockstep_timeout=60.0, marker_period=0.0)
    loop = TickLoop(sim, commands, Ignored(), options, [blocks, RowByRow(rows)])
    loop.log_rows.max_wait = float("inf")  # blocks close when full, or when the loop asks

    def tick(k):
        done = loop.sim.ticks + 1
        loop.commands.submit_array([np.sin(0.05 * k)])
        wait_until(lambda: loop.sim.ticks >= done, f"tick {k}")

    result = []
    thread = threading.Thread(target=lambda: result.append(loop.run()))
    thread.start()
    try:
        for k in range(137):
            tick(k)
        assert len(loop.log_rows) == 38  # the start state and 137 ticks: 100 written
        assert loop.reset(timeout=10.0)
        for k in range(55):
            tick(k)
    finally:
        loop.stop()
        thread.join(10.0)
    assert result == [STOPPED]
    blocks.close()
    rows.close()
    got, expected = messages(tmp_path / "blocks.mcap"), messages(tmp_path / "rows.mcap")
    assert got == expected
    joint_states = [m for m in got if m[0] == "/joint_states"]
    assert len(joint_states) == 137 + 55 + 2  # the ticks and the two episodes' start states
    times = [m[1] for m in joint_states]  # one tick apart, across the reset too
    assert np.all(np.diff(times) == 1_000_000)
    events = [m for m in got if m[0] == "/vjm_sim_node/events"]
    assert len(events) == 1 and times[137] < events[0][1] == times[138]  # the reset, in order

    # rosbags, with its own typestore, reads the block-written log: every tick's joint state
    # carries the effort this test commanded for that tick (per-row efforts), and q the state
    commanded = [0.0] + [np.sin(0.05 * k) for k in range(137)]  # start state, then tick k
    commanded += [0.0] + [np.sin(0.05 * k) for k in range(55)]  # efforts cleared by the reset
    with AnyReader([tmp_path / "blocks.mcap"]) as reader:
        conns = [c for c in reader.connections if c.topic == "/joint_states"]
        decoded = [reader.deserialize(raw, c.msgtype)
                   for c, _, raw in reader.messages(connections=conns)]
    assert [m.effort[0] for m in decoded] == commanded
    assert [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in decoded] == times


class Collecting:
    path = "collecting"

    def __init__(self):
        self.times = []

    def write(self, sample):
        self.times.append(sample.t)

    def note_reset(self, t, tick=None):
        pass

    def close(self):
        pass


def test_a_loop_holding_for_its_first_command_has_logged_its_start_state():
    scene = load_scene("four_bar")
    sim = Simulator(scene.model, SimulationSettings(), scene.gains)
    commands = CommandBuffer(sim.model.actuator_names, sim.model.joint_names, sim.limits, 0.0)
    rec = Collecting()
    options = LoopOptions(realtime=False, marker_period=0.0, wait_for_command=True)
    loop = TickLoop(sim, commands, Ignored(), options, [rec])
    result = []
    thread = threading.Thread(target=lambda: result.append(loop.run()))
    thread.start()
    try:
        wait_until(lambda: rec.times == [0.0], "the start state in the log")
        assert loop.sim.ticks == 0
        loop.commands.submit_array([1.0])
        wait_until(lambda: loop.sim.ticks >= 5, "5 ticks")
    finally:
        loop.stop()
        thread.join(10.0)
    assert result == [STOPPED] and rec.times[:6] == pytest.approx([0.0, 0.001, 0.002, 0.003,
                                                                   0.004, 0.005])
