"""Health figures of a running simulation (what the node publishes on ``/diagnostics``), no ROS.

* realtime factor: simulated seconds per wall second over the last report window;
* late / missed ticks and resyncs: from :class:`~vjm_ros.realtime.pacing.PacingStats`;
* closure error: the largest ``|C|`` (m, rad for angle closures) in the window and since start;
* smallest singular value of the closure Jacobian in the window (distance to a singular pose);
* energy-balance residual (docs/design.md section 2): ``E(t) - E(0) - integral(tau . qd - sum Kv Cdot^2)``
  with the trapezoid rule over the observed samples, J. With a sample every tick it measures the
  integration error; with decimated samples it also carries the quadrature error.
"""

from __future__ import annotations

import math
import operator
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from vjm_ros.realtime.pacing import PacingStats
from vjm_ros.sim.samples import Sample

OK, WARN, ERROR = 0, 1, 2
"""Diagnostic levels (the values of ``diagnostic_msgs/DiagnosticStatus``)."""


class EnergyLedger:
    """Running energy balance ``E(t) - E(0) - W(t)`` over consecutive samples.

    ``W`` integrates ``tau . qd - dissipation`` by the trapezoid rule, less each tick's
    ``joint_loss`` (the energy sticking friction and stops took); over the interval that ends at a
    sample the efforts are the ones applied during it (``sample.effort``), also at the interval's
    start.
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Start a new balance at the next sample."""
        self._started = False
        self._t = 0.0
        self._qd: list[float] = []
        self._dissipation = 0.0
        self._e0 = 0.0
        self.work = 0.0
        self.residual = 0.0
        self.max_residual = 0.0

    def update(self, sample: Sample) -> float:
        """Add one sample (the ledger keeps copies of what it needs: the sample's arrays may be
        refilled afterwards).

        Returns
        -------
        float
            The current residual, J.
        """
        # Python floats: numpy's per-call overhead on arrays of a few entries is several times
        # the arithmetic (the node calls this every tick)
        total = float(sample.energy[3])
        if not self._started:
            self._started = True
            self._e0 = total
        else:
            rate_start = sum(map(operator.mul, sample.effort.tolist(), self._qd))
            rate_start -= self._dissipation
            rate_end = sample.power_in - sample.dissipation
            self.work += 0.5 * (rate_start + rate_end) * (sample.t - self._t) - sample.joint_loss
            self.residual = total - self._e0 - self.work
            self.max_residual = max(self.max_residual, abs(self.residual))
        self._t = sample.t
        self._qd = sample.qd.tolist()
        self._dissipation = sample.dissipation
        return self.residual


@dataclass
class Window:
    """Figures gathered since the last report."""

    wall_start: float
    sim_start: float
    counters: dict = field(default_factory=dict)
    max_closure_error: float = 0.0
    sigma_min: float = math.inf


class Monitor:
    """Collects samples and counters into periodic reports.

    Parameters
    ----------
    clock : callable
        Monotonic wall time, s.
    """

    def __init__(self, clock: Callable[[], float] = time.perf_counter):
        self._clock = clock
        self.ledger = EnergyLedger()
        self.max_closure_error = 0.0
        self._window = Window(clock(), 0.0)

    def reset(self) -> None:
        """Forget the episode's figures (after a simulator reset). The report window keeps its
        start: the published time goes on across a reset, so its realtime factor counts the
        simulated time of both episodes."""
        self.ledger.reset()
        self.max_closure_error = 0.0
        self._window.max_closure_error = 0.0
        self._window.sigma_min = math.inf

    def observe(self, sample: Sample) -> None:
        """Account for one sample."""
        self.ledger.update(sample)
        err = max(sample.closure_error.tolist(), default=0.0)  # a list: see EnergyLedger.update
        w = self._window
        w.max_closure_error = max(w.max_closure_error, err)
        self.max_closure_error = max(self.max_closure_error, err)
        if math.isfinite(sample.sigma_min):
            w.sigma_min = min(w.sigma_min, float(sample.sigma_min))

    def report(self, sim_time: float, pacing: PacingStats, counters: dict | None = None) -> dict:
        """Figures of the window that ends now, then start a new window.

        Parameters
        ----------
        sim_time : float
            Simulated time now, s.
        pacing : PacingStats
            The pacer's counters (cumulative).
        counters : dict, optional
            Further cumulative integer counters (commands, lockstep timeouts, ...).

        Returns
        -------
        dict
            ``realtime_factor`` (window), ``sim_time`` (s), the cumulative counters ``ticks``,
            ``late_ticks``, ``missed_ticks``, ``resyncs`` and those given, each also as
            ``<name>_window`` (the increase in the window); ``max_lateness`` (s),
            ``max_closure_error`` (window, m), ``max_closure_error_run`` (m), ``sigma_min``
            (window minimum; nan if not computed), ``energy_balance_residual`` (J, current) and
            ``energy_balance_residual_max`` (J, largest since start).
        """
        now = self._clock()
        w = self._window
        wall = now - w.wall_start
        totals = {
            "ticks": pacing.ticks,
            "late_ticks": pacing.late,
            "missed_ticks": pacing.missed,
            "resyncs": pacing.resyncs,
            **(counters or {}),
        }
        out = {
            "realtime_factor": (sim_time - w.sim_start) / wall if wall > 0 else math.nan,
            "sim_time": sim_time,
        }
        for key, value in totals.items():
            out[key] = value
            out[f"{key}_window"] = value - w.counters.get(key, 0)
        out.update(
            {
                "max_lateness": pacing.max_lateness,
                "max_closure_error": w.max_closure_error,
                "max_closure_error_run": self.max_closure_error,
                "sigma_min": w.sigma_min if math.isfinite(w.sigma_min) else math.nan,
                "energy_balance_residual": self.ledger.residual,
                "energy_balance_residual_max": self.ledger.max_residual,
            }
        )
        self._window = Window(now, sim_time, totals)
        return out


def assess(report: dict, paused: bool = False) -> tuple[int, str]:
    """Diagnostic level and one-line message for a report.

    WARN when ticks were missed or lockstep ticks timed out in the window.

    Returns
    -------
    level : int
        :data:`OK` or :data:`WARN`.
    message : str
    """
    if paused:
        return OK, f"paused at t = {report['sim_time']:.6g} s"
    problems = []
    if report.get("missed_ticks_window", 0):
        problems.append(f"{report['missed_ticks_window']} missed ticks")
    if report.get("lockstep_timeouts_window", 0):
        problems.append(f"{report['lockstep_timeouts_window']} lockstep timeouts")
    rtf = report["realtime_factor"]
    text = f"running, realtime factor {rtf:.3g}" if math.isfinite(rtf) else "running"
    if problems:
        return WARN, f"{text}; {', '.join(problems)} in the last period"
    return OK, text
