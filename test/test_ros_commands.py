"""The node's logic without ROS: commands, pacing, settings, health figures and the tick loop.

Nothing here imports rclpy; the tick loop runs the real simulator with a recording stand-in for
the ROS outputs, and fake clocks where time matters.
"""

import math
import threading
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vjm_ros.core.errors import ConfigurationError, DivergenceError, SceneError, StiffnessError
from vjm_ros.realtime import commands as cmd
from vjm_ros.realtime.commands import CommandBuffer, Throttle
from vjm_ros.realtime.gate import Gate
from vjm_ros.realtime.loop import (
    DURATION,
    GATE_MIN_OPEN,
    GATE_OPEN_SHARE,
    SERVICE_TURN,
    STOPPED,
    LoopOptions,
    TickLoop,
)
from vjm_ros.realtime.monitor import EnergyLedger, Monitor, assess
from vjm_ros.realtime.pacing import Pacer, PacingStats
from vjm_ros.realtime.parameters import (
    PARAMETERS,
    NodeConfig,
    build_simulator,
    simulation_settings,
    ticks_between,
)
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator


class FakeClock:
    """A clock that only moves when told (``sleep`` advances it).

    The pacing tests below count late and missed ticks and resynchronisations on this clock, so
    those counts are exact and independent of the machine; real-clock figures are measured by
    ``python -m benchmarks.latency``.
    """

    def __init__(self, t=0.0):
        self.t = t
        self.sleeps = []

    def __call__(self):
        return self.t

    def sleep(self, dt):
        self.sleeps.append(dt)
        self.t += dt


def buffer(timeout=0.5, clock=None):
    """The five-bar's actuators: left_base, right_base (limit 50 N m); four joints."""
    return CommandBuffer(
        ["left_base", "right_base"],
        ["left_base", "left_elbow", "right_base", "right_elbow"],
        [50.0, 50.0],
        timeout,
        clock or FakeClock(),
    )


# ---------------------------------------------------------------- commands
def test_valid_array_command_is_held_and_fresh_once():
    b = buffer()
    v = b.submit_array([1.0, -2.0])
    assert v.accepted and v.clamped == ()
    first, second = b.latch(), b.latch()
    assert first.fresh and not second.fresh
    np.testing.assert_array_equal(first.efforts, [1.0, -2.0])
    np.testing.assert_array_equal(second.efforts, [1.0, -2.0])


@pytest.mark.parametrize(
    "values, kind, words",
    [
        ([1.0], cmd.WRONG_LENGTH, ["expected 2 values", "'left_base', 'right_base'", "found 1"]),
        ([1.0, 2.0, 3.0], cmd.WRONG_LENGTH, ["found 3"]),
        ([math.nan, 0.0], cmd.NON_FINITE, ["non-finite", "left_base = nan"]),
        ([0.0, math.inf], cmd.NON_FINITE, ["right_base = inf"]),
        ([0.0, -math.inf], cmd.NON_FINITE, ["right_base = -inf"]),
    ],
)
def test_bad_array_command_is_refused_with_reason(values, kind, words):
    b = buffer()
    b.submit_array([3.0, 4.0])
    v = b.submit_array(values)
    assert not v.accepted and v.kind == kind
    for w in words:
        assert w in v.reason
    np.testing.assert_array_equal(b.latch().efforts, [3.0, 4.0])  # unchanged
    assert b.rejected == 1 and b.accepted == 1


@pytest.mark.parametrize(
    "names, efforts, kind, words",
    [
        (["left_base", "nose"], [1.0, 2.0], cmd.UNKNOWN_JOINT, ["unknown joint 'nose'", "left_elbow"]),
        (["left_elbow"], [1.0], cmd.NOT_ACTUATED, ["'left_elbow' has no actuator", "'right_base'"]),
        (["left_base", "left_base"], [1.0, 2.0], cmd.DUPLICATE_JOINT, ["more than once: 'left_base'"]),
        (["left_base", "right_base"], [1.0], cmd.WRONG_LENGTH, ["'name' has 2", "'effort' has 1"]),
        (["left_base"], [], cmd.NO_EFFORTS, ["0 effort"]),
        ([], [], cmd.NO_EFFORTS, ["0 name"]),
        (["right_base"], [math.nan], cmd.NON_FINITE, ["right_base = nan"]),
    ],
)
def test_bad_named_command_is_refused_with_reason(names, efforts, kind, words):
    b = buffer()
    b.submit_array([3.0, 4.0])
    v = b.submit_named(names, efforts)
    assert not v.accepted and v.kind == kind
    for w in words:
        assert w in v.reason, v.reason
    np.testing.assert_array_equal(b.latch().efforts, [3.0, 4.0])


def test_a_flood_of_junk_names_is_refused_in_linear_time_with_a_short_reason():
    b = buffer()
    names = [f"junk_{i}" for i in range(50_000)] * 2  # every name twice: duplicates
    v = b.submit_named(names, np.zeros(len(names)))
    assert v.kind == cmd.DUPLICATE_JOINT and "and 49992 more" in v.reason
    v = b.submit_named(names[:50_000], np.zeros(50_000))
    assert v.kind == cmd.UNKNOWN_JOINT and len(v.reason) < 1000
    v = b.submit_named(["x" * 1_000_000], [1.0])
    assert v.kind == cmd.UNKNOWN_JOINT and len(v.reason) < 1000


JOINTS = ["left_base", "left_elbow", "right_base", "right_elbow"]
efforts_st = st.floats(allow_nan=True, allow_infinity=True, width=64)
commands_st = st.one_of(
    st.tuples(st.just("array"), st.lists(efforts_st, max_size=5), st.just(())),
    st.lists(st.tuples(st.sampled_from([*JOINTS, "nose", ""]), efforts_st), max_size=5).map(
        lambda pairs: ("named", [e for _, e in pairs], tuple(n for n, _ in pairs))),
    st.tuples(st.just("named"), st.lists(efforts_st, max_size=3),
              st.lists(st.sampled_from(JOINTS), max_size=3).map(tuple)),
)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.lists(commands_st, min_size=1, max_size=12))
def test_fuzzed_commands_apply_exactly_the_valid_ones_clamped(sequence):
    # Oracle: the rules of the module docstring, written out independently of the buffer.
    b = buffer()
    expected = np.zeros(2)
    for kind, values, names in sequence:
        if kind == "array":
            valid = len(values) == 2 and all(math.isfinite(x) for x in values)
            update = dict(zip(["left_base", "right_base"], values, strict=False))
            verdict = b.submit_array(values)
        else:
            valid = (len(names) > 0 and len(names) == len(values) and len(set(names)) == len(names)
                     and set(names) <= {"left_base", "right_base"}
                     and all(math.isfinite(x) for x in values))
            update = dict(zip(names, values, strict=False))
            verdict = b.submit_named(list(names), values)
        assert verdict.accepted == valid, (kind, values, names, verdict)
        if valid:
            for i, name in enumerate(["left_base", "right_base"]):
                if name in update:
                    expected[i] = min(max(update[name], -50.0), 50.0)
        else:
            assert verdict.reason and len(verdict.reason) < 1000
        latched = b.latch().efforts
        np.testing.assert_array_equal(latched, expected)  # exact: copies and clamps only


def test_named_command_updates_only_the_named_actuators():
    b = buffer()
    b.submit_array([3.0, 4.0])
    assert b.submit_named(["right_base"], [-1.5]).accepted
    np.testing.assert_array_equal(b.latch().efforts, [3.0, -1.5])


def test_limits_clamp_and_are_reported():
    b = buffer()
    v = b.submit_named(["left_base", "right_base"], [80.0, -60.0])
    assert v.accepted and len(v.clamped) == 2
    assert "left_base: 80 clamped to 50 (limit 50)" in v.clamped[0]
    np.testing.assert_array_equal(b.latch().efforts, [50.0, -50.0])
    assert b.clamped == 2


def test_command_times_out_to_zero_once_then_rearms():
    clock = FakeClock()
    b = buffer(timeout=0.5, clock=clock)
    b.submit_array([1.0, 2.0])
    clock.t = 0.5  # exactly at the timeout: still held
    assert not b.latch().timed_out
    clock.t = 0.51
    first = b.latch()
    assert first.timed_out and not first.fresh
    np.testing.assert_array_equal(first.efforts, [0.0, 0.0])
    clock.t = 5.0
    assert not b.latch().timed_out  # reported once
    assert b.timeouts == 1


def test_timeout_after_new_command_counts_again():
    clock = FakeClock()
    b = buffer(timeout=0.5, clock=clock)
    b.submit_array([1.0, 2.0])
    clock.t = 1.0
    assert b.latch().timed_out
    b.submit_array([1.0, 1.0])
    got = b.latch()
    assert got.fresh and not got.timed_out
    np.testing.assert_array_equal(got.efforts, [1.0, 1.0])
    clock.t = 2.0
    assert b.latch().timed_out and b.timeouts == 2


def test_zero_timeout_holds_forever():
    clock = FakeClock()
    b = buffer(timeout=0.0, clock=clock)
    b.submit_array([1.0, 2.0])
    clock.t = 1e6
    got = b.latch()
    assert not got.timed_out
    np.testing.assert_array_equal(got.efforts, [1.0, 2.0])


def test_wait_fresh_wakes_on_a_command_from_another_thread():
    b = buffer()
    assert not b.wait_fresh(0.01)
    timer = threading.Timer(0.05, lambda: b.submit_array([1.0, 1.0]))
    timer.start()
    assert b.wait_fresh(5.0)
    timer.join()
    b.latch()
    assert not b.wait_fresh(0.0)


def test_clear_drops_the_command_in_force():
    b = buffer()
    b.submit_array([1.0, 2.0])
    b.clear()
    got = b.latch()
    assert not got.fresh
    np.testing.assert_array_equal(got.efforts, [0.0, 0.0])


def test_throttle_reports_each_key_at_most_once_per_period():
    clock = FakeClock()
    th = Throttle(1.0, clock)
    assert th("nan") == 0
    assert th("nan") is None and th("nan") is None
    assert th("length") == 0  # another key is independent
    clock.t = 1.0
    assert th("nan") == 2  # two held back since the last report


# ---------------------------------------------------------------- pacing
def test_realtime_pacer_keeps_a_drift_free_schedule():
    clock = FakeClock(100.0)
    p = Pacer(0.001, clock=clock, sleep=clock.sleep, margin=0.0)
    starts = []
    for _ in range(5):
        p.wait()
        starts.append(clock.t)
        clock.t += 0.0004  # work of the tick
    np.testing.assert_allclose(np.diff(starts), 0.001, rtol=0, atol=1e-12)
    assert p.stats == PacingStats(ticks=5)


def test_late_and_missed_ticks_are_counted_and_caught_up():
    clock = FakeClock()
    p = Pacer(0.001, clock=clock, sleep=clock.sleep, margin=0.0)
    p.wait()  # tick 0 due at 0
    clock.t += 0.0035  # a stall: ticks 1, 2, 3 are due at 1, 2, 3 ms
    lateness = [p.wait(), p.wait(), p.wait()]
    np.testing.assert_allclose(lateness, [0.0025, 0.0015, 0.0005], atol=1e-12)
    p.wait()  # tick 4 is due at 4 ms: waited for
    assert clock.t == pytest.approx(0.004)
    s = p.stats
    assert (s.ticks, s.late, s.missed, s.resyncs) == (5, 3, 2, 0)
    assert s.max_lateness == pytest.approx(0.0025)


def test_backlog_beyond_max_lag_resynchronizes():
    clock = FakeClock()
    p = Pacer(0.001, clock=clock, sleep=clock.sleep, margin=0.0, max_lag=0.01)
    p.wait()
    clock.t += 0.5
    p.wait()
    assert p.stats.resyncs == 1
    t = clock.t
    p.wait()  # the schedule restarted from the late tick
    assert clock.t == pytest.approx(t + 0.001)


def test_fast_mode_never_waits():
    clock = FakeClock()
    p = Pacer(0.001, realtime=False, clock=clock, sleep=clock.sleep)
    for _ in range(10):
        assert p.wait() == 0.0
    assert clock.t == 0.0 and p.stats.ticks == 10 and p.stats.late == 0


def test_pacer_wait_can_be_cancelled():
    clock = FakeClock()
    p = Pacer(1.0, clock=clock, sleep=clock.sleep, margin=0.0)
    p.wait()
    assert math.isnan(p.wait(cancelled=lambda: True))
    assert p.stats.ticks == 1


class TickingClock(FakeClock):
    """A fake clock that also advances by ``step`` at every reading (as a spinning loop sees)."""

    def __init__(self, step):
        super().__init__()
        self.step = step
        self.reads = 0

    def __call__(self):
        self.reads += 1
        self.t += self.step
        return self.t


def test_pacer_sleeps_then_spins_to_the_deadline():
    clock = TickingClock(1e-5)
    p = Pacer(0.01, clock=clock, sleep=clock.sleep, margin=0.002)
    p.wait()
    start = clock.t
    reads = clock.reads
    p.wait()
    assert clock.sleeps == [pytest.approx(0.008, abs=1e-4)]  # slept until 2 ms before
    assert clock.reads - reads == pytest.approx(200, abs=5)  # then spun to the deadline
    assert clock.t - start == pytest.approx(0.01, abs=1e-4)


class OvershootingClock(TickingClock):
    """A fake clock whose sleeps last longer than asked, by ``overshoots`` in turn (s); each
    reading advances it by 1 us (a spinning loop reads it until the deadline)."""

    def __init__(self, overshoots):
        super().__init__(1e-6)
        self.overshoots = overshoots
        self.count = 0

    def sleep(self, dt):
        extra = self.overshoots[self.count % len(self.overshoots)]
        self.count += 1
        super().sleep(dt + extra)


def test_the_margin_follows_the_sleeps_overshoot():
    """By default the margin settles on the 75th percentile of the overshoots plus a guard of
    10 us. Overshoots spread evenly over 50-250 us: the margin settles near 200 + 10 us, the ticks
    after one sleep in five (those beyond 210 us) start late by at most 40 us, none early (the
    loop spins to the deadline); a machine that sleeps precisely ends with the least margin."""
    overshoots = list(np.linspace(50e-6, 250e-6, 201))
    np.random.default_rng(3).shuffle(overshoots)
    clock = OvershootingClock(overshoots)
    p = Pacer(0.001, clock=clock, sleep=clock.sleep)
    assert p.adaptive and p.margin == pytest.approx(2e-4)
    lateness = []
    for _ in range(6000):
        lateness.append(p.wait())
        clock.t += 3e-4  # work of the tick
    assert p.margin == pytest.approx(210e-6, abs=10e-6)
    late = np.array(lateness[3000:])  # settled
    assert late.min() >= 0.0
    # a reading advances the clock by 1 us: "on time" is within a few readings
    assert np.mean(late > 5e-6) == pytest.approx(0.2, abs=0.04)
    assert late.max() < 45e-6
    assert p.stats.late == 0 and p.stats.missed == 0

    precise = OvershootingClock([0.0])
    q = Pacer(0.001, clock=precise, sleep=precise.sleep)
    for _ in range(4000):
        q.wait()
        precise.t += 3e-4
    assert q.margin == pytest.approx(2e-5)  # the least margin


def test_the_margin_recovers_after_a_spell_of_long_oversleeps():
    """Sleeps that overshoot by 1.5 ms for a while (a loaded machine) raise the margin, but never
    beyond half the period: the loop still sleeps before each deadline, keeps learning, and the
    margin comes back down once the sleeps are short again (above half the period the loop would
    spin through every tick and, sleeping no more, never learn that it may)."""
    long_spell, short = [1.5e-3] * 2000, [50e-6] * 30000
    clock = OvershootingClock(long_spell + short)
    p = Pacer(0.001, clock=clock, sleep=clock.sleep)
    highest = 0.0
    for _ in range(12000):
        p.wait()
        highest = max(highest, p.margin)
        clock.t += 3e-4  # work of the tick
    assert highest == pytest.approx(5e-4)  # half the period, not MARGIN_RANGE's 2 ms
    assert clock.count > len(long_spell)  # it slept on after the spell...
    assert p.margin == pytest.approx(60e-6, abs=5e-6)  # ...and follows the short sleeps again


def test_a_fixed_margin_stays_as_given():
    clock = OvershootingClock([1e-4])
    p = Pacer(0.001, clock=clock, sleep=clock.sleep, margin=3e-4)
    for _ in range(100):
        p.wait()
    assert not p.adaptive and p.margin == 3e-4


# ---------------------------------------------------------------- settings
def test_every_parameter_has_a_description_and_a_config_default():
    assert {p.name for p in PARAMETERS} >= {
        "scene", "rate_hz", "substeps", "integrator", "closure", "kp", "kv", "realtime",
        "duration", "mcap", "rrd", "publish_clock", "command_timeout", "publish_rate_hz",
        "lockstep", "lockstep_timeout",
    }
    defaults = NodeConfig()
    for p in PARAMETERS:
        assert p.description.endswith(".")
        assert getattr(defaults, p.name) == p.default
        if isinstance(p.default, (int, float)) and not isinstance(p.default, bool):
            assert p.low <= p.default <= p.high


@pytest.mark.parametrize(
    "values, words",
    [
        ({"rate_hz": -1.0}, ["rate_hz", "from 0 to 100000", "-1.0"]),
        ({"integrator": "rk5"}, ["integrator", "'rk4'", "'rk5'"]),
        ({"closure": "glue"}, ["closure", "'penalty'"]),
        ({"substeps": 1.5}, ["substeps", "whole number"]),
        ({"realtime": "yes"}, ["realtime", "true or false"]),
        ({"duration": math.nan}, ["duration"]),
        ({"kv": 10.0}, ["kv", "set kp too"]),
        ({"volume": 11}, ["unknown parameter", "volume"]),
    ],
)
def test_bad_values_are_refused_naming_the_parameter(values, words):
    with pytest.raises(ConfigurationError) as err:
        NodeConfig.from_values(values)
    for w in words:
        assert w in str(err.value)


def test_node_settings_resolve_like_the_command_line():
    scene = load_scene("four_bar")
    s = simulation_settings(NodeConfig(), scene)
    assert (s.integrator, s.closure, s.rate, s.substeps) == ("rk4", "penalty", 1000.0, 1)
    assert s.kp is None and s.kv is None  # the scene's gains
    s = simulation_settings(NodeConfig(kp=2e4, rate_hz=500.0, integrator="implicit_euler"), scene)
    assert (s.kp, s.kv, s.rate, s.integrator) == (2e4, 0.0, 500.0, "implicit_euler")


def test_build_refuses_what_cannot_run():
    with pytest.raises(StiffnessError, match="omega_n"):
        build_simulator(NodeConfig(kp=1e9, kv=0.0))
    with pytest.raises(ConfigurationError, match="publish_rate_hz: expected at most the tick rate 200"):
        build_simulator(NodeConfig(rate_hz=200.0, publish_rate_hz=500.0))
    with pytest.raises(SceneError, match="no such scene"):
        build_simulator(NodeConfig(scene="/nonexistent/scene.yaml"))
    _, sim = build_simulator(NodeConfig(scene="five_bar", rate_hz=500.0))
    assert sim.dt == 0.002 and sim.model.name == "five_bar"


def test_ticks_between_outputs():
    assert ticks_between(0.0, 1000.0) == 1
    assert ticks_between(100.0, 1000.0) == 10
    assert ticks_between(300.0, 1000.0) == 3
    assert ticks_between(1000.0, 1000.0) == 1


# ---------------------------------------------------------------- health figures
class _S:
    """A sample with just the fields the ledger reads."""

    def __init__(self, t, qd, effort, energy, dissipation=0.0, joint_loss=0.0):
        self.t, self.qd, self.effort = t, np.asarray(qd, float), np.asarray(effort, float)
        self.energy = np.array([0.0, 0.0, 0.0, energy])
        self.power_in = float(self.effort @ self.qd)
        self.dissipation = dissipation
        self.joint_loss = joint_loss
        self.closure_error = np.zeros(1)
        self.sigma_min = math.nan

    max_closure_error = 0.0


def test_energy_ledger_is_exact_for_a_linear_energy_input():
    # qd grows linearly under a constant effort 2: P = 2 qd; E = integral P = t^2 (qd = t).
    ledger = EnergyLedger()
    for k in range(11):
        t = 0.1 * k
        ledger.update(_S(t, [t], [2.0], 3.0 + t * t))
    assert ledger.residual == pytest.approx(0.0, abs=1e-12)


def test_energy_ledger_uses_the_effort_of_each_interval():
    # qd = 1 constant; effort 0 until t = 1, then 5: the work is 5 (t - 1).
    ledger = EnergyLedger()
    ledger.update(_S(0.0, [1.0], [0.0], 0.0))
    ledger.update(_S(1.0, [1.0], [0.0], 0.0))
    ledger.update(_S(2.0, [1.0], [5.0], 5.0))
    assert ledger.residual == pytest.approx(0.0, abs=1e-12)


def test_energy_ledger_counts_what_the_joints_took_at_its_tick():
    # at rest; an impact takes 0.5 J during the second tick: the ledger balances at once
    ledger = EnergyLedger()
    ledger.update(_S(0.0, [0.0], [0.0], 2.0))
    ledger.update(_S(0.1, [0.0], [0.0], 2.0))
    ledger.update(_S(0.2, [0.0], [0.0], 1.5, joint_loss=0.5))
    assert ledger.residual == pytest.approx(0.0, abs=1e-12)
    assert ledger.max_residual == pytest.approx(0.0, abs=1e-12)


def test_energy_balance_of_a_real_run_is_small():
    scene = load_scene("four_bar")
    sim = Simulator(scene.model, SimulationSettings(rate=1000.0), scene.gains)
    ledger = EnergyLedger()
    ledger.update(sim.sample())
    for k in range(300):
        sim.advance([3.0 if k < 150 else -2.0])
        ledger.update(sim.sample())
    total = abs(sim.sample().energy[3])
    assert ledger.max_residual < 1e-3 * max(total, 1.0)


def test_monitor_reports_windows_and_totals():
    clock = FakeClock()
    mon = Monitor(clock)
    clock.t = 2.0
    mon.observe(_S(0.5, [0.0], [0.0], 1.0))
    rep = mon.report(1.0, PacingStats(ticks=10, late=2, missed=1), {"lockstep_timeouts": 3})
    assert rep["realtime_factor"] == pytest.approx(0.5)
    assert (rep["ticks"], rep["late_ticks"], rep["missed_ticks_window"]) == (10, 2, 1)
    assert rep["lockstep_timeouts_window"] == 3
    assert assess(rep)[0] == 1 and "1 missed ticks" in assess(rep)[1]
    clock.t = 3.0
    rep = mon.report(2.0, PacingStats(ticks=20, late=2, missed=1), {"lockstep_timeouts": 3})
    assert rep["missed_ticks_window"] == 0 and rep["lockstep_timeouts_window"] == 0
    assert assess(rep)[0] == 0 and math.isnan(rep["sigma_min"])


def test_monitor_window_spans_a_reset_in_published_time():
    """The published time goes on across a reset (one tick later), so a report window that
    holds a reset counts the simulated time of both episodes: 2 s of it in 4 wall s here."""
    clock = FakeClock()
    mon = Monitor(clock)
    clock.t = 1.0
    mon.report(1.0, PacingStats())  # the window now starts at published time 1.0 s
    clock.t = 3.0
    mon.reset()  # the episode ended at 2.0 s; the next one starts at 2.001 s
    clock.t = 5.0
    assert mon.report(3.0, PacingStats())["realtime_factor"] == pytest.approx(0.5)


# ---------------------------------------------------------------- the tick loop
class Collect:
    """Outputs that record what the loop produces (and may act on it)."""

    def __init__(self, on_joints=None):
        self.times, self.q, self.effort, self.forces, self.notices = [], [], [], [], []
        self.clocks, self.markers_seen, self.reports = [], 0, []
        self.on_joints = on_joints

    def clock(self, t):
        self.clocks.append(t)

    def joints(self, t, q, qd, effort):
        self.times.append(t)
        self.q.append(np.array(q))
        self.effort.append(np.array(effort))
        if self.on_joints:
            self.on_joints(t)

    def dynamics(self, sample, t):
        self.forces.append(t)

    def markers(self, sample, t):
        self.markers_seen += 1

    def diagnostics(self, report, paused):
        self.reports.append(report)

    def notice(self, kind, text):
        self.notices.append((kind, text))

    def rebuilt(self, simulator):
        pass


def four_bar(rate=1000.0):
    scene = load_scene("four_bar")
    return Simulator(scene.model, SimulationSettings(rate=rate), scene.gains)


def make_loop(outputs, rate=1000.0, **options):
    sim = four_bar(rate)
    commands = CommandBuffer(sim.model.actuator_names, sim.model.joint_names, sim.limits, 0.0)
    opts = LoopOptions(realtime=False, marker_period=0.0, **options)
    return TickLoop(sim, commands, outputs, opts)


def test_duration_stops_after_exactly_that_many_ticks():
    out = Collect()
    loop = make_loop(out, rate=500.0, duration=0.1, forces_every=5)
    assert loop.run() == DURATION
    assert loop.sim.ticks == 50
    np.testing.assert_allclose(out.times, np.arange(51) * 0.002, atol=1e-12)
    assert out.clocks == out.times
    np.testing.assert_allclose(out.forces, np.arange(0, 51, 5) * 0.002, atol=1e-12)


def test_duration_counts_published_time_since_start_across_resets():
    """``duration`` is simulated time since the start, the time ``/clock`` publishes, which a
    reset does not turn back: 30 ticks, a reset (its state published one tick later, 31 ms),
    then ticks up to 100 ms, and no further."""
    out = Collect()
    loop = make_loop(out, duration=0.1)
    loop.pause(True)
    result = []
    thread = threading.Thread(target=lambda: result.append(loop.run()))
    thread.start()
    try:
        for _ in range(30):
            assert loop.step(timeout=10.0) is not None  # 10 s: a hang guard
        assert loop.reset(timeout=10.0)
        loop.pause(False)
        thread.join(30.0)
    finally:
        loop.stop()
        thread.join(10.0)
    assert result == [DURATION]
    assert out.clocks[-1] == pytest.approx(0.1, abs=1e-12)
    assert all(b > a for a, b in zip(out.clocks, out.clocks[1:], strict=False))
    assert out.clocks[31] == pytest.approx(0.031, abs=1e-12)  # the reset state
    assert loop.ticks == 99 and loop.time == pytest.approx(0.1, abs=1e-12)


def test_command_received_during_tick_k_applies_from_tick_k_plus_1():
    k = 20
    loop = None

    def command_while_publishing(t):
        # The state after tick k is published inside tick k: a command sent now is seen by
        # tick k + 1 at the earliest.
        if round(t / loop.sim.dt) == k:
            loop.commands.submit_array([7.0])

    out = Collect(command_while_publishing)
    loop = make_loop(out, duration=0.05)
    loop.run()
    ref = four_bar()
    expected = [ref.q.copy()]
    for tick in range(1, 51):
        ref.advance([7.0] if tick > k else [0.0])
        expected.append(ref.q.copy())
    np.testing.assert_array_equal(np.array(out.q), np.array(expected))
    assert out.effort[k][0] == 0.0 and out.effort[k + 1][0] == 7.0


def test_lockstep_without_commands_times_out_and_counts():
    out = Collect()
    loop = make_loop(out, duration=0.003, lockstep=True, lockstep_timeout=0.01)
    assert loop.run() == DURATION
    assert loop.lockstep_timeouts == 3
    assert [k for k, _ in out.notices] == ["lockstep_timeout"] * 3


def test_lockstep_steps_once_per_command():
    loop = None

    def answer(t):
        loop.commands.submit_array([1.0])

    out = Collect(answer)
    loop = make_loop(out, duration=0.02, lockstep=True, lockstep_timeout=5.0)
    loop.run()
    assert loop.lockstep_timeouts == 0 and loop.commands.accepted == 21


class FakeRecorder:
    def __init__(self):
        self.times, self.resets = [], []

    def write(self, sample):
        self.times.append(sample.t)

    def note_reset(self, t, tick=None):
        self.resets.append(t)


def test_wait_for_command_holds_the_initial_state_until_a_command_arrives():
    out = Collect()
    loop = make_loop(out, duration=0.01, wait_for_command=True)
    result = []
    thread = threading.Thread(target=lambda: result.append(loop.run()))
    thread.start()
    try:
        # Republished every 0.1 s while holding: wait (up to a hang guard) for three of them,
        # rather than sleeping a fixed time that a loaded machine may stretch.
        deadline = time.monotonic() + 30.0
        while len(out.times) < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert loop.sim.ticks == 0 and len(out.times) >= 3
        assert set(out.times) == {0.0}
        loop.commands.submit_array([2.0])
        thread.join(10.0)
    finally:
        loop.stop()
        thread.join(10.0)
    assert result == [DURATION] and loop.sim.ticks == 10
    assert out.effort[-1][0] == 2.0 and ("started" in [k for k, _ in out.notices])


def test_pause_step_reset_and_stop_from_another_thread():
    out = Collect()
    loop = make_loop(out)
    recorder = FakeRecorder()
    loop.recorders.append(recorder)
    loop.pause(True)
    result = []
    thread = threading.Thread(target=lambda: result.append(loop.run()))
    thread.start()
    try:
        assert loop.step(timeout=10.0) == pytest.approx(0.001)
        assert loop.step(timeout=10.0) == pytest.approx(0.002)
        assert loop.sim.ticks == 2 and out.times == pytest.approx([0.0, 0.001, 0.002])
        assert loop.reset(timeout=10.0)
        # the simulator restarts at 0; what the loop publishes goes on one tick after 0.002 s
        assert loop.sim.t == 0.0 and out.times[-1] == pytest.approx(0.003)
        np.testing.assert_array_equal(out.q[-1], out.q[0])
        loop.pause(False)
        assert loop.step(timeout=0.1) is None  # not paused: no step
    finally:
        loop.stop()
        thread.join(10.0)
    assert result == [STOPPED]
    assert recorder.times[:4] == pytest.approx([0.0, 0.001, 0.002, 0.0])  # every tick, then reset
    assert recorder.resets == [pytest.approx(0.002)]  # told when the episode ended
    kinds = [k for k, _ in out.notices]
    assert kinds[:4] == ["paused", "stepped", "stepped", "reset"] and "resumed" in kinds


def test_divergence_stops_the_loop():
    scene = load_scene("four_bar")
    sim = Simulator(scene.model, SimulationSettings(kp=10.0, kv=0.0), scene.gains)
    commands = CommandBuffer(sim.model.actuator_names, sim.model.joint_names, sim.limits, 0.0)
    loop = TickLoop(sim, commands, Collect(), LoopOptions(realtime=False, marker_period=0.0))
    with pytest.raises(DivergenceError, match="closure residual"):
        loop.run()


class CoarseClock(FakeClock):
    """A fake clock whose sleeps last at least a microsecond (as real ones do)."""

    def sleep(self, dt):
        super().sleep(max(dt, 1e-6))


def test_ros_callbacks_are_gated_out_of_realtime_ticks_but_get_a_turn_when_behind():
    clock = CoarseClock()
    out = Collect()
    gate_during_tick = []
    sim = four_bar(1000.0)
    commands = CommandBuffer(sim.model.actuator_names, sim.model.joint_names, sim.limits, 0.0)
    loop = None

    def slow_tick(t):
        gate_during_tick.append(loop.gate.is_open)
        clock.t += 0.0015 if 0.01 < t < 0.02 else 0.0002  # ten ticks longer than a period

    out.on_joints = slow_tick
    loop = TickLoop(sim, commands, out, LoopOptions(realtime=True, marker_period=0.0,
                                                    duration=0.05),
                    clock=clock, sleep=clock.sleep)
    loop.pacer._yield = lambda: setattr(clock, "t", clock.t + 1e-5)  # spinning takes time
    assert loop.run() == DURATION and loop.gate.is_open
    assert gate_during_tick[0] and not any(gate_during_tick[1:])  # t = 0 is published ungated
    # Behind schedule the loop still sleeps GATE_MIN_OPEN before closing the gate (the executor's
    # turn); on schedule it sleeps towards the deadline instead.
    turns = [dt for dt in clock.sleeps if dt == pytest.approx(GATE_MIN_OPEN, abs=1e-6)]
    assert len(turns) >= 10
    assert loop.pacer.stats.missed > 0


def test_a_loop_that_takes_its_commands_catches_up_without_a_turn_per_tick():
    """Taking the commands itself, the loop behind schedule gives the executor (services) its
    GATE_MIN_OPEN turn once per SERVICE_TURN instead of before every catch-up tick, and takes
    the inputs at every tick."""
    clock = CoarseClock()
    out = Collect()
    sim = four_bar(1000.0)
    commands = CommandBuffer(sim.model.actuator_names, sim.model.joint_names, sim.limits, 0.0)
    polls = []

    def slow_tick(t):
        clock.t += 0.0015 if 0.01 < t < 0.04 else 0.0002  # thirty ticks longer than a period

    out.on_joints = slow_tick
    loop = TickLoop(sim, commands, out, LoopOptions(realtime=True, marker_period=0.0,
                                                    duration=0.06),
                    clock=clock, sleep=clock.sleep)
    loop.poll_inputs = lambda: polls.append(clock.t)
    loop.pacer._yield = lambda: setattr(clock, "t", clock.t + 1e-5)  # spinning takes time
    assert loop.run() == DURATION
    assert len(polls) == sim.ticks == 60
    turns = [dt for dt in clock.sleeps if dt == pytest.approx(GATE_MIN_OPEN, abs=1e-6)]
    # behind for about 45 ms of wall time (30 ticks of 1.5 ms): one turn per SERVICE_TURN, not
    # one per tick (the loop without polled inputs sleeps before each, test above)
    assert loop.pacer.stats.missed >= 10
    assert 1 <= len(turns) <= math.ceil(0.045 / SERVICE_TURN) + 1, len(turns)


def test_gate_lets_callbacks_start_only_until_its_closing_time():
    clock = FakeClock()
    gate = Gate(clock)
    assert gate.is_open and gate.enter(0.0)  # open without limit at first
    gate.open(until=0.0006)
    clock.t = 0.0005
    assert gate.enter(0.0)
    clock.t = 0.0006
    assert not gate.is_open and not gate.enter(0.0)  # a callback may not start any more
    gate.open()
    assert gate.enter(0.0)
    gate.close()
    assert not gate.enter(0.0)
    # Another thread waiting to enter is woken by open().
    threading.Timer(0.05, gate.open).start()
    assert gate.enter(5.0)


def test_realtime_tick_opens_the_gate_for_a_share_of_the_time_to_the_next_deadline():
    clock = CoarseClock()
    sim = four_bar(1000.0)
    commands = CommandBuffer(sim.model.actuator_names, sim.model.joint_names, sim.limits, 0.0)
    closing = []
    out = Collect(lambda t: None)
    loop = TickLoop(sim, commands, out, LoopOptions(realtime=True, marker_period=0.0,
                                                    duration=0.01),
                    clock=clock, sleep=clock.sleep)
    loop.pacer._yield = lambda: setattr(clock, "t", clock.t + 1e-5)  # spinning takes time
    original = loop.gate.open
    loop.gate.open = lambda until=math.inf: (closing.append((clock.t, until)), original(until))
    loop.run()
    timed = [(now, until) for now, until in closing if until != math.inf]
    assert len(timed) >= 9
    for now, until in timed:  # 60 % of the way to the deadline that follows
        due = loop.pacer.period * (math.floor(now / loop.pacer.period + 1e-9) + 1)
        assert until == pytest.approx(now + GATE_OPEN_SHARE * (due - now), abs=1e-9)
