"""Tick pacing against the wall clock, without ROS.

Realtime mode is a deadline loop: tick ``k`` is due at ``start + k * period`` (``next += period``),
so a tick that starts late is followed by ticks that catch up instead of skipping simulated time.
To be on time without burning a core, :meth:`Pacer.wait` sleeps until ``margin`` before the
deadline and spins for the rest, yielding the GIL at every turn so that subscription callbacks
are not held up. ``time.sleep`` wakes late by an amount that depends on the machine (a median of
0.08 ms on a quiet 2-core VM, 0.11 ms with a p90 of 0.16 ms on a busier one): by default the
margin follows it, an estimate of the 75th percentile of the overshoots seen (plus
:data:`MARGIN_GUARD`), so that the loop wakes just before three deadlines in four, spins for
tens of microseconds, and starts the fourth tick late by a fraction of the overshoots' spread
(well within :attr:`Pacer.late_tolerance` on these machines). A fixed margin of 0.2 ms spun for
0.1 ms a tick on the quiet machine, a tenth of a core at 1 kHz taken from the other processes on
it (a controller in the loop). Measured on the busier machine, the node alone at 1 kHz (five_bar),
the waiting took 95-116 us of CPU per tick at the 90th percentile, 84-92 at the 75th and
73-75 at the median: the sleep itself costs about 50 us of CPU there.

Counts (:class:`PacingStats`):

* **late**: a tick that started more than ``late_tolerance`` after its deadline;
* **missed**: a tick that started a whole period or more after its deadline, i.e. when the next
  tick was already due (a subset of the late ticks). After a stall, every catch-up tick that is
  still a period behind counts;
* **resyncs**: the loop fell more than ``max_lag`` behind and gave up catching up; the schedule
  restarts from the current time (simulated time then trails wall time for good).

Fast mode (``realtime = False``) never waits: ticks run back to back and nothing is counted as late.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass

SLEEP_SLICE = 0.05
"""Longest single sleep, s, so that a stop request is seen within this time."""
MARGIN_START = 2e-4
"""Margin before the first sleeps are seen, s."""
MARGIN_RANGE = (2e-5, 2e-3)
"""Least and largest margin the estimate may take, s."""
MARGIN_PERIOD_SHARE = 0.5
"""Largest margin the estimate may take, as a share of the period: the loop must still sleep
before each deadline to learn the overshoot. Above the time left after a tick's work it would
spin through every tick and never sleep, so never learn that the overshoots had come down
(without this bound, a spell of 1.5 ms oversleeps on a fake clock left a 1 kHz pacer spinning
0.7 ms of every tick for good: test/test_ros_commands.py)."""
MARGIN_GUARD = 1e-5
"""Added to the overshoot estimate, s."""
OVERSHOOT_QUANTILE = 0.75
"""Share of sleeps whose overshoot the margin covers."""
OVERSHOOT_STEP = 2e-6
"""Learning step of the overshoot quantile, s per sleep (the estimate moves up by
``OVERSHOOT_QUANTILE`` of it after a larger overshoot, down by the rest after a smaller one:
hundreds of ticks to settle, a few outliers move it by microseconds)."""


@dataclass
class PacingStats:
    """Counters of a pacer since it was created.

    Attributes
    ----------
    ticks : int
        Ticks released by :meth:`Pacer.wait`.
    late, missed, resyncs : int
        See the module documentation.
    max_lateness : float
        Largest start delay seen, s.
    """

    ticks: int = 0
    late: int = 0
    missed: int = 0
    resyncs: int = 0
    max_lateness: float = 0.0


class Pacer:
    """Releases ticks at a fixed wall-clock period (realtime) or at once (fast mode).

    Parameters
    ----------
    period : float
        Tick period, s.
    realtime : bool
        Pace to the wall clock; False runs flat out.
    margin : float, optional
        Time before a deadline at which sleeping stops and spinning starts, s; by default it
        follows the sleeps' overshoot (see the module notes).
    max_lag : float
        Largest backlog caught up, s; beyond it the schedule restarts (a resync).
    clock : callable
        Monotonic time, s.
    sleep : callable
        ``sleep(seconds)``.
    """

    def __init__(
        self,
        period: float,
        realtime: bool = True,
        *,
        margin: float | None = None,
        max_lag: float = 0.1,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
    ):
        if not period > 0:
            raise ValueError(f"period: expected a positive number of seconds, found {period!r}")
        self.period = float(period)
        self.realtime = bool(realtime)
        self.adaptive = margin is None
        self.margin = MARGIN_START if margin is None else float(margin)
        self._overshoot = self.margin - MARGIN_GUARD
        self.max_lag = float(max_lag)
        self._clock = clock
        self._sleep = sleep
        self._yield = os.sched_yield  # called while spinning to the deadline: releases the GIL
        self._next: float | None = None
        self.stats = PacingStats()

    def _learn(self, overshoot: float) -> None:
        """Move the overshoot quantile estimate by one observation (a sleep ``overshoot`` s
        longer than asked) and set the margin from it."""
        q = OVERSHOOT_QUANTILE
        self._overshoot += OVERSHOOT_STEP * (q if overshoot > self._overshoot else q - 1.0)
        lo, hi = MARGIN_RANGE
        hi = max(min(hi, MARGIN_PERIOD_SHARE * self.period), lo)
        self._overshoot = min(max(self._overshoot, lo - MARGIN_GUARD), hi)
        self.margin = min(max(self._overshoot + MARGIN_GUARD, lo), hi)

    @property
    def late_tolerance(self) -> float:
        """Start delay beyond which a tick counts as late: 10 % of the period, s."""
        return 0.1 * self.period

    @property
    def next_due(self) -> float | None:
        """Wall-clock time the next tick is due, s (None in fast mode or right after a restart)."""
        return self._next if self.realtime else None

    def restart(self) -> None:
        """Make the next tick due now (after a pause, a reset or a change of mode or period)."""
        self._next = None

    def wait(self, cancelled: Callable[[], bool] | None = None,
             approach: Callable[[], object] | None = None) -> float:
        """Block until the next tick is due and account for it.

        Parameters
        ----------
        cancelled : callable, optional
            Checked between sleep slices; when it returns True the wait ends early and the tick
            is not released (returns ``nan``).
        approach : callable, optional
            Called once when sleeping ends, ``margin`` before the deadline (realtime mode only):
            the tick loop closes the executor's gate there (:class:`~.runtime.Spinner`).

        Returns
        -------
        float
            How late the tick starts, s (0 in fast mode, ``nan`` when cancelled).
        """
        if not self.realtime:
            self.stats.ticks += 1
            return 0.0
        now = self._clock()
        if self._next is None:
            self._next = now
        target = self._next
        while target - now > self.margin:
            if cancelled is not None and cancelled():
                return float("nan")
            asked = min(target - now - self.margin, SLEEP_SLICE)
            self._sleep(asked)
            woke = self._clock()
            if self.adaptive:
                self._learn(woke - now - asked)
            now = woke
        if approach is not None:
            approach()
        while now < target:
            self._yield()  # lets the executor thread take the GIL while this one spins
            now = self._clock()
        lateness = now - target
        s = self.stats
        s.ticks += 1
        if lateness > self.late_tolerance:
            s.late += 1
        if lateness >= self.period:
            s.missed += 1
        s.max_lateness = max(s.max_lateness, lateness)
        if lateness > self.max_lag:
            s.resyncs += 1
            self._next = now + self.period
        else:
            self._next = target + self.period
        return lateness
