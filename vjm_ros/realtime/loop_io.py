"""What the tick loop is given: its options, where its outputs go, the logs it writes.

:class:`~vjm_ros.realtime.loop.TickLoop` takes a :class:`LoopOptions`, sends what it produces to
an :class:`Outputs` (the node publishes it; tests collect it) and writes :class:`Recorder` logs.
No ROS here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from vjm_ros.sim.samples import Sample
from vjm_ros.sim.simulator import Simulator


class Outputs(Protocol):
    """Where the loop sends what it produces (the node publishes; tests collect)."""

    def clock(self, t: float) -> None:
        """Simulated time ``t`` (s), every tick."""

    def joints(self, t: float, q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> None:
        """Joint positions, rates and applied efforts at simulated time ``t`` (s), shape (n,):
        as the scene's sensors measure them, or exact without sensors."""

    def ground_truth(self, t: float, q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> None:
        """The exact joint state beside :meth:`joints`, only when the scene has sensors."""

    def dynamics(self, sample: Sample, t: float) -> None:
        """Constraint forces and energy of a sample, stamped ``t`` (s)."""

    def markers(self, sample: Sample, t: float) -> None:
        """A drawing of the mechanism (decimated), stamped ``t`` (s)."""

    def diagnostics(self, report: dict, paused: bool) -> None:
        """Periodic health figures (:meth:`~.monitor.Monitor.report`)."""

    def notice(self, kind: str, text: str) -> None:
        """An event: ``command_timeout``, ``lockstep_timeout``, ``paused``, ``resumed``,
        ``stepped``, ``reset``, ``started``, ``log_failed``."""

    def rebuilt(self, simulator: Simulator) -> None:
        """The simulator was replaced (new settings applied at a reset)."""


class Recorder(Protocol):
    """A log (:mod:`vjm_ros.logs`)."""

    def write(self, sample: Sample) -> None: ...

    def note_reset(self, t: float, tick: float | None = None) -> None: ...


@dataclass
class LoopOptions:
    """Settings of the loop that may change while it runs.

    Attributes
    ----------
    realtime : bool
        Pace to the wall clock.
    duration : float
        Stop once the published simulated time (:attr:`~vjm_ros.realtime.loop.TickLoop.time`, counted from the start
        and never turned back by a reset) reaches this, s; 0: never.
    publish_every : int
        Ticks between two joint-state outputs.
    forces_every : int
        Ticks between two outputs of constraint forces and energy.
    publish_clock : bool
        Send the simulated time every tick.
    lockstep : bool
        Wait for a fresh command before each tick.
    lockstep_timeout : float
        Longest lockstep wait, wall s.
    marker_period : float
        Wall seconds between marker outputs; 0: none.
    diagnostics_period : float
        Wall seconds between diagnostics.
    wait_for_command : bool
        Hold the initial state (after start and after each reset) until a command arrives,
        republishing the joint state every :data:`~vjm_ros.realtime.loop.HOLD_REPUBLISH` seconds meanwhile.
    """

    realtime: bool = True
    duration: float = 0.0
    publish_every: int = 1
    forces_every: int = 1
    publish_clock: bool = True
    lockstep: bool = False
    lockstep_timeout: float = 1.0
    marker_period: float = 1.0 / 30.0
    diagnostics_period: float = 1.0
    wait_for_command: bool = False
