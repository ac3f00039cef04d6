"""The pacing floor (benchmarks.pacing_floor) counts a stall of the process as the node would.

On a fake clock the answer is known by hand: a tick released ``L`` ms after its deadline is
followed by empty ticks that start at once, each one period (1 ms) less late, and a tick counts as
missed when it starts a whole period or more late. The figures of a real run are benchmarks, not
asserted here.
"""

from __future__ import annotations

import pytest

from benchmarks import pacing_floor


class FakeTime:
    """A clock that moves 1 µs per reading and by each sleep plus its overshoot: 50 µs, and
    ``stall`` s once, on sleep number ``stall_at``."""

    def __init__(self, stall: float, stall_at: int):
        self.now = 0.0
        self.sleeps = 0
        self.stall = stall
        self.stall_at = stall_at

    def clock(self) -> float:
        self.now += 1e-6
        return self.now

    def sleep(self, seconds: float) -> None:
        self.sleeps += 1
        self.now += seconds + (self.stall if self.sleeps == self.stall_at else 50e-6)


def test_a_stall_is_missed_once_per_period_it_lasts():
    # The stall wakes the loop 5.7 ms after it asked to; the pacer asked to wake its margin
    # (at most half a period, 0.5 ms) before the deadline, so the tick starts 5.2-5.7 ms late
    # and the next ones 4.2-4.7, 3.2-3.7, 2.2-2.7, 1.2-1.7 and 0.2-0.7 ms late: 5 missed.
    fake = FakeTime(stall=5.7e-3, stall_at=100)
    row = pacing_floor.measure(1.0, 1000.0, clock=fake.clock, sleep=fake.sleep)
    assert row["ticks"] == 1000
    assert row["missed_ticks"] == 5
    assert row["missed_share"] == pytest.approx(5 / 1000)
    assert 5.2 <= row["max_lateness_ms"] <= 5.7
    # late (more than 10 % of the period): the five missed and the 0.2-0.7 ms one after them
    assert row["late_ticks"] == 6


def test_without_a_stall_nothing_is_missed():
    fake = FakeTime(stall=0.0, stall_at=-1)
    row = pacing_floor.measure(0.5, 1000.0, clock=fake.clock, sleep=fake.sleep)
    assert (row["ticks"], row["missed_ticks"]) == (500, 0)
    assert row["max_lateness_ms"] < 0.1


def test_the_real_clock_runs_the_ticks_asked_for():
    row = pacing_floor.measure(0.05, 1000.0)
    assert row["ticks"] == 50
    assert 0 <= row["missed_ticks"] <= row["late_ticks"] <= row["ticks"]
    assert "missed" in pacing_floor.describe(row)


@pytest.mark.parametrize("seconds, rate", [(0.0, 1000.0), (1.0, 0.0), (-1.0, 1000.0)])
def test_a_run_of_nothing_is_refused_naming_both(seconds, rate):
    with pytest.raises(ValueError, match="seconds and rate"):
        pacing_floor.measure(seconds, rate)
