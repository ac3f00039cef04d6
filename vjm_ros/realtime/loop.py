"""The tick loop of the simulator node, without ROS.

One tick (:meth:`TickLoop.run`):

1. wait: realtime mode waits for the tick's wall-clock deadline (:class:`~.pacing.Pacer`), fast
   mode does not wait, lockstep mode waits for a command received since the previous tick (or
   ``lockstep_timeout``, counted);
2. take the commands that arrived since the previous tick (:attr:`TickLoop.poll_inputs`, while
   ticking freely) and latch the efforts (:meth:`~.commands.CommandBuffer.latch`): a command
   received while the previous tick ran applies from this tick on, and it is held over the
   whole tick;
3. advance the simulator by one tick;
4. outputs: ``/clock`` every tick; joint states every ``publish_every`` ticks (from the state
   itself, cheap); constraint forces, wrenches and energy every ``forces_every`` ticks (these need
   a full :meth:`~vjm_ros.sim.simulator.Simulator.sample`); recorders every tick, in blocks of
   ticks (:class:`~vjm_ros.logs.rows.LogRows`; a log that cannot be written is given up,
   :class:`~vjm_ros.logs.storage.LogWriters`); markers and
   diagnostics at their wall-clock periods.

In realtime mode ROS callbacks run between ticks: the loop's :class:`~.gate.Gate` lets them start
in the first :data:`GATE_OPEN_SHARE` of the time to the next deadline and closes at the deadline's
approach, so that a flood of incoming messages cannot hold the interpreter when a tick is due.

The state at ``t = 0`` is published before the first tick (a lockstep controller answers it with
the first command); in lockstep mode, resuming from a pause publishes the joint state again. With
``wait_for_command`` the loop holds the initial state until the first command arrives, so that a
controller whose discovery takes a while finds the mechanism where the scene put it.

Pause, step, reset and stop are requests from other threads (the service callbacks), served
between ticks, so the simulator is only ever touched by the loop's thread.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence

from vjm_ros.logs import Timebase, events
from vjm_ros.logs.rows import LogRows
from vjm_ros.logs.storage import LogWriters
from vjm_ros.realtime.commands import CommandBuffer
from vjm_ros.realtime.gate import Gate
from vjm_ros.realtime.loop_io import LoopOptions, Outputs, Recorder
from vjm_ros.realtime.monitor import Monitor
from vjm_ros.realtime.pacing import Pacer
from vjm_ros.realtime.row_sample import RowSample
from vjm_ros.realtime.wrenches import WrenchBuffer
from vjm_ros.sim.samples import Sample, SampleBlock
from vjm_ros.sim.simulator import Simulator

WAIT_SLICE = 0.05
"""Longest uninterrupted wait of the loop, s (how soon it sees a request or a stop)."""
GATE_OPEN_SHARE = 0.6
"""Share of the time between two realtime ticks in which ROS callbacks may start; the rest
lets a callback that started late finish before the tick is due."""
GATE_MIN_OPEN = 1e-4
"""Shortest time the executor's gate stays open between two ticks, s: when the loop runs behind
and catches up, ROS callbacks (the commands) still get a turn at every tick (once per
:data:`SERVICE_TURN` when the loop takes the commands itself)."""
SERVICE_TURN = 0.01
"""While the loop takes the commands itself (:attr:`TickLoop.poll_inputs`), the longest the
executor goes without its minimal turn when the loop runs behind, wall s: services and parameter
changes still get through within it, and catch-up ticks do not each wait ``GATE_MIN_OPEN``."""
SIGMA_PERIOD = 0.05
"""Simulated seconds between two evaluations of the closure Jacobian's smallest singular value
(for ``/diagnostics``, which reports the smallest of each second): one costs 0.1 ms here (a kernel
call and an SVD), a tick's CPU; every 10 ms it was 8 % of the node's CPU in fast mode, for a
figure reported once a second of a pose that changes over many ticks."""
HOLD_REPUBLISH = 0.1
"""Period of the joint state republished while waiting for the first command, wall s."""
PAUSE_WAIT = 5.0
"""Longest a pause request waits for the tick under way to finish, wall s (a hang guard: a tick
takes well under a millisecond)."""

DURATION = "duration"
STOPPED = "stopped"


class TickLoop:
    """Runs a :class:`~vjm_ros.sim.simulator.Simulator` tick by tick.

    Parameters
    ----------
    simulator : Simulator
    commands : CommandBuffer
        Efforts in the simulator's actuator order.
    outputs : Outputs
    options : LoopOptions
    recorders : sequence of Recorder
        Written with every tick's sample (a block of ticks at a time, :attr:`log_rows`); told
        about resets.
    paused : bool
        Start paused.
    clock : callable
        Monotonic wall time, s.
    sleep : callable
        ``sleep(seconds)``.
    wrenches : WrenchBuffer, optional
        External wrenches, latched at the start of each tick (:mod:`vjm_ros.realtime.wrenches`).
    """

    def __init__(
        self,
        simulator: Simulator,
        commands: CommandBuffer,
        outputs: Outputs,
        options: LoopOptions | None = None,
        recorders: Sequence[Recorder] = (),
        *,
        paused: bool = False,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
        wrenches: WrenchBuffer | None = None,
    ):
        self.sim = simulator
        self.commands = commands
        self.wrenches = wrenches
        self.outputs = outputs
        self.options = options or LoopOptions()
        self.logs = LogWriters(recorders, self._log_failed)
        self._clock = clock
        self.log_rows = LogRows(simulator.model, self.logs.write_block, clock=clock)
        """Each tick's sample on its way to the logs, written a block at a time by a thread of
        its own."""
        self._sleep = sleep
        self.pacer = Pacer(simulator.dt, self.options.realtime, clock=clock, sleep=sleep)
        self.monitor = Monitor(clock)
        self.lockstep_timeouts = 0
        self.ticks = 0
        """Ticks run since the start, across resets (the simulator's own count restarts)."""
        self._cv = threading.Condition()
        self._stop = False
        self._paused = paused
        self._in_tick = False
        self._steps_asked = self._steps_done = 0
        self._resets_asked = self._resets_done = 0
        self._replacement: tuple[Simulator, CommandBuffer] | None = None
        self._next_markers = 0.0
        self._next_diagnostics = 0.0
        self._next_sigma = 0.0
        self._realtime = self.options.realtime
        self._holding = False
        self.gate = Gate(clock)
        self.timebase = Timebase(simulator.dt)
        """When ROS callbacks may run: closed from just before a realtime tick's deadline until
        its outputs are out (:class:`~.gate.Gate`)."""
        self._gate_opened = -math.inf
        self._last_turn = -math.inf
        self._block: SampleBlock | None = None
        self._block_for: Simulator | None = None
        self._row: RowSample | None = None
        self.poll_inputs: Callable[[], None] | None = None
        """Called at the start of every tick while :attr:`polls_inputs` (the node takes the
        commands that arrived since the previous tick)."""
        self.ticking_since: tuple[float, float] | None = None
        """Wall time (of ``clock``) and process CPU time (s) when the ticks began: at the start of
        :meth:`run`, or when the first command ended a ``wait_for_command`` hold."""

    @property
    def polls_inputs(self) -> bool:
        """Whether the loop takes its inputs itself (:attr:`poll_inputs`) at each tick: while it
        ticks freely; not while paused, holding for the first command or in lockstep (then it
        waits for commands, which the executor's callbacks deliver)."""
        return not (self._paused or self._holding or self.options.lockstep)

    @property
    def recorders(self) -> list:
        """The logs still being written."""
        return self.logs.active

    def _log_failed(self, where: str, error: str) -> None:
        self.outputs.notice(
            "log_failed", f"log {where} could not be written ({error}); recording to it stopped "
            f"at t = {self.sim.t:.6g} s, the simulation goes on")

    # ------------------------------------------------------------------ requests (any thread)
    def stop(self) -> None:
        """Ask the loop to return after the current tick (safe from signal handlers)."""
        self._stop = True

    @property
    def paused(self) -> bool:
        """Whether ticks are suspended."""
        return self._paused

    def pause(self, paused: bool) -> None:
        """Suspend (True) or resume (False) the ticks.

        A pause takes effect at a tick boundary: a tick already under way (a callback may run
        beside one) is finished before this returns, so ``sim.t`` is then the time of the last
        state published, and no tick follows until resumed.
        """
        with self._cv:
            changed = paused != self._paused
            self._paused = paused
            self._cv.notify_all()
            if paused:
                self._cv.wait_for(lambda: not self._in_tick, PAUSE_WAIT)
        if changed:
            self.outputs.notice("paused" if paused else "resumed",
                                f"{'paused' if paused else 'resumed'} at t = {self.time:.6g} s")

    def step(self, timeout: float = 2.0) -> float | None:
        """Run one tick while paused and wait for it.

        Returns
        -------
        float or None
            Simulated time after the tick, s; None if not paused or not done within ``timeout``.
        """
        with self._cv:
            if not self._paused:
                return None
            self._steps_asked += 1
            ticket = self._steps_asked
            self._cv.notify_all()
            done = self._cv.wait_for(lambda: self._steps_done >= ticket, timeout)
            return self.time if done else None

    def reset(self, timeout: float = 2.0) -> bool:
        """Return to the initial state (with new settings if some are waiting) and wait for it.

        Returns
        -------
        bool
            Done within ``timeout``.
        """
        with self._cv:
            self._resets_asked += 1
            ticket = self._resets_asked
            self._cv.notify_all()
            return self._cv.wait_for(lambda: self._resets_done >= ticket, timeout)

    @property
    def time(self) -> float:
        """Simulated time as published, s: it only ever increases, also across resets.

        The simulator's own clock restarts at 0 on a reset; what the loop publishes (``/clock``,
        stamps, logs) goes on from one tick after the last time published
        (:class:`~vjm_ros.logs.Timebase`, the recorders' rule).
        """
        return self._published(self.sim.t)

    def _published(self, t: float) -> float:
        return self.timebase.to_ns(t) * 1e-9

    def replace_on_reset(self, simulator: Simulator, commands: CommandBuffer) -> None:
        """Use ``simulator`` and ``commands`` from the next reset on."""
        with self._cv:
            self._replacement = (simulator, commands)

    # ------------------------------------------------------------------ the loop
    def run(self) -> str:
        """Tick until stopped or until ``duration``.

        Returns
        -------
        str
            :data:`DURATION` or :data:`STOPPED`.

        Raises
        ------
        DivergenceError
            From the simulator; the loop stops.
        """
        try:
            self._load_kernels()
            self._emit(self.sim.sample(singular_values=True))
            self._holding = self.options.wait_for_command
            if not self._holding:
                self._mark_start()
            self._next_diagnostics = self._clock() + self.options.diagnostics_period
            while not self._stop:
                self._serve_requests()
                if self._paused:
                    self._idle()
                    continue
                if self._holding:
                    self._hold()
                    continue
                if self._duration_reached():
                    return DURATION
                if not self._await_tick():
                    continue
                with self._cv:
                    if self._interrupted():  # a pause, reset or stop came while waiting
                        continue
                    self._in_tick = True
                try:
                    self._tick()
                finally:
                    with self._cv:
                        self._in_tick = False
                        self._cv.notify_all()
                self._periodic()
                self._open_gate()
            return STOPPED
        finally:
            try:
                self.log_rows.close()  # every tick written, also those before a divergence
            finally:
                self.gate.open()
            with self._cv:
                self._cv.notify_all()

    def _load_kernels(self) -> None:
        """Load the compiled tick and the kernel before the first deadline (the kernel serves
        the first sample of an episode, the singular values and a tick that is not a block)."""
        self.sim.blocks_compiled()
        self.sim.mechanism.warm_up()

    def _hold(self) -> None:
        """Keep the initial state until a command arrives, republishing it for late joiners."""
        self.log_rows.sync()  # the logs hold the start state meanwhile
        self.gate.open()
        if self.commands.wait_fresh(HOLD_REPUBLISH):
            self._holding = False
            self.pacer.restart()
            self._mark_start()
            self.outputs.notice("started", f"first command: running from t = {self.time:.6g} s")
            return
        self._joints(self.time)
        self._periodic()

    def _mark_start(self) -> None:
        if self.ticking_since is None:
            self.ticking_since = (self._clock(), time.process_time())

    def _duration_reached(self) -> bool:
        """Whether the published time (:attr:`time`, which a reset does not turn back) has
        reached ``duration``: the simulated time since the start, not the episode's. 1 ns of
        slack absorbs the rounding of the tick times to whole nanoseconds."""
        d = self.options.duration
        return d > 0 and self.timebase.to_ns(self.sim.t) >= round(d * 1e9) - 1

    def _await_tick(self) -> bool:
        """Wait until the next tick may run; False when a request or a stop came first."""
        opts = self.options
        if opts.lockstep:
            self.gate.open()
            deadline = self._clock() + opts.lockstep_timeout
            while not self._interrupted():
                remaining = deadline - self._clock()
                if remaining <= 0:
                    self.lockstep_timeouts += 1
                    self.outputs.notice(
                        "lockstep_timeout",
                        f"no command within lockstep_timeout = {opts.lockstep_timeout:g} s at "
                        f"t = {self.sim.t:.6g} s; stepping with the efforts in force",
                    )
                    return True
                if self.commands.wait_fresh(min(remaining, WAIT_SLICE)):
                    return True
            return False
        if opts.realtime != self._realtime:
            self._realtime = self.pacer.realtime = opts.realtime
            self.pacer.restart()
        return not math.isnan(self.pacer.wait(self._interrupted, self._close_gate))

    def _open_gate(self) -> None:
        now = self._gate_opened = self._clock()
        due = self.pacer.next_due
        if due is None or self.options.lockstep:
            self.gate.open()
        else:
            self.gate.open(max(now + GATE_OPEN_SHARE * (due - now), now + GATE_MIN_OPEN))

    def _close_gate(self) -> None:
        """Stop ROS callbacks for the tick, after their minimal turn since the previous one;
        while the loop takes the commands itself, after one turn per :data:`SERVICE_TURN`."""
        now = self._clock()
        left = GATE_MIN_OPEN - (now - self._gate_opened)
        if left > 0:
            if self._polling() and now - self._last_turn < SERVICE_TURN:
                self.gate.close()  # behind schedule: catch up; the services had a turn lately
                return
            self._sleep(left)
            now = self._clock()
        self._last_turn = now
        self.gate.close()

    def _polling(self) -> bool:
        return self.poll_inputs is not None and self.polls_inputs

    def _interrupted(self) -> bool:
        return self._stop or self._paused or self._resets_asked > self._resets_done

    def _tick(self) -> None:
        self.ticks += 1
        if self._polling():
            self.poll_inputs()
        latched = self.commands.latch()
        if latched.timed_out:
            self.outputs.notice(
                "command_timeout",
                f"no valid command for {self.commands.timeout:g} s: efforts set to zero at "
                f"t = {self.sim.t:.6g} s",
            )
        sim, opts, outputs = self.sim, self.options, self.outputs
        if latched.fresh or latched.timed_out:
            sim.set_efforts(latched.efforts)
        if self.wrenches is not None:
            loads = self.wrenches.latch()
            if loads is not None:  # a wrench arrived or timed out: from this tick on
                sim.set_external_loads(loads)
        forces = (sim.ticks + 1) % opts.forces_every == 0
        now = self._clock()
        draw = opts.marker_period > 0 and now >= self._next_markers
        sample = self._advance(forces or draw or bool(self.recorders), forces, draw)
        t = self.time
        if opts.publish_clock:
            outputs.clock(t)
        if sim.ticks % opts.publish_every == 0:
            self._joints(t)
        if sample is not None:
            if forces:
                outputs.dynamics(sample, t)
                self.monitor.observe(sample)
            if self.recorders:
                self.log_rows.add(sample)
            if draw:
                outputs.markers(sample, t)
                self._next_markers = now + opts.marker_period

    def _advance(self, observed: bool, forces: bool, draw: bool) -> Sample | None:
        """One tick; its sample when ``observed``. With a compiled fixed-step integrator the
        step, the guard and the sample are one compiled call (a block of one tick: 15 µs where
        ``advance`` then ``sample`` take 43 µs on four_bar); the smallest singular value of the
        closure Jacobian joins the forces every ``SIGMA_PERIOD``.

        The sample's arrays are views of the block, refilled by the next tick (the outputs, the
        monitor and :attr:`log_rows` copy what they keep).
        """
        sim = self.sim
        if observed and (self._block_for is sim or sim.blocks_compiled()):
            if self._block_for is not sim:
                self._block, self._block_for = SampleBlock(sim.model, 1), sim
                self._row = RowSample(self._block)
            sim.advance_block(self._block, 1)
            sample = self._row.refresh()
            if self._sigma_due(forces):
                sample.sigma_min = sim.smallest_singular_value()
            return sample
        sim.advance()
        if not observed:
            return None
        return sim.sample(singular_values=self._sigma_due(forces),
                          geometry=draw or bool(self.recorders))

    def _sigma_due(self, forces: bool) -> bool:
        if forces and self.sim.t >= self._next_sigma:
            self._next_sigma = self.sim.t + SIGMA_PERIOD - 1e-12
            return True
        return False

    def _joints(self, t: float) -> None:
        """The simulator's joint state stamped ``t`` (s): measured, and exact beside it, when
        the scene has sensors."""
        sim = self.sim
        if sim.measured is None:
            self.outputs.joints(t, sim.q, sim.qd, sim.tau)
        else:
            self.outputs.joints(t, *sim.measured)  # rows: position, velocity, effort
            self.outputs.ground_truth(t, sim.q, sim.qd, sim.tau)

    def _emit(self, sample: Sample) -> None:
        """Outputs of a state that starts an episode (t = 0)."""
        t = self._published(sample.t)
        if self.options.publish_clock:
            self.outputs.clock(t)
        self._joints(t)
        self.outputs.dynamics(sample, t)
        self.monitor.observe(sample)
        if self.recorders:
            self.log_rows.add(sample)
        if self.options.marker_period > 0:
            self.outputs.markers(sample, t)

    def _periodic(self) -> None:
        now = self._clock()
        if now >= self._next_diagnostics:
            self._next_diagnostics = now + self.options.diagnostics_period
            self.outputs.diagnostics(self.report(), self._paused)

    def report(self) -> dict:
        """Current health figures (starts a new report window)."""
        counters = {
            "commands_accepted": self.commands.accepted,
            "commands_rejected": self.commands.rejected,
            "refused_oversize_commands": self.commands.oversize,
            "efforts_clamped": self.commands.clamped,
            "command_timeouts": self.commands.timeouts,
            "lockstep_timeouts": self.lockstep_timeouts,
        }
        if self.wrenches is not None:
            counters["wrenches_accepted"] = self.wrenches.accepted
            counters["wrenches_refused"] = self.wrenches.refused
        return self.monitor.report(self.time, self.pacer.stats, counters)

    def _idle(self) -> None:
        """Paused: serve steps, keep diagnostics going, otherwise wait."""
        self.log_rows.sync()  # the logs show the state the loop rests in
        self.gate.open()
        with self._cv:
            if self._steps_asked == self._steps_done and not self._interrupted_while_paused():
                self._cv.wait(WAIT_SLICE)
            step = self._paused and self._steps_asked > self._steps_done
        if step:
            self._tick()
            with self._cv:
                self._steps_done += 1
                self._cv.notify_all()
            self.outputs.notice("stepped", f"stepped to t = {self.time:.6g} s")
        self._periodic()
        if not self._paused:
            self.pacer.restart()
            if self.options.lockstep:  # give the controller a state to answer
                self._joints(self.time)

    def _interrupted_while_paused(self) -> bool:
        return self._stop or not self._paused or self._resets_asked > self._resets_done

    def _serve_requests(self) -> None:
        if self._resets_asked == self._resets_done:
            return
        t_before = self.sim.t
        ended = self.time
        with self._cv:
            replacement, self._replacement = self._replacement, None
        if replacement is not None:
            self.sim, self.commands = replacement
            if self.wrenches is not None:  # the new scene's points
                self.wrenches = WrenchBuffer(self.sim.model.points, self.wrenches.timeout)
            self._load_kernels()
            self.pacer.period = self.sim.dt
            self.outputs.rebuilt(self.sim)
        else:
            self.sim.reset()
        self.commands.clear()
        if self.wrenches is not None:
            self.wrenches.clear()
        self.log_rows.sync()  # the ending episode's ticks are written before the reset is noted
        if replacement is not None:  # its model may differ in shape
            self.log_rows.close()
            self.log_rows = LogRows(self.sim.model, self.logs.write_block, clock=self._clock)
        self.logs.note_reset(t_before, self.sim.dt)  # the new period, if rate_hz changed
        self.timebase.tick_ns = int(round(self.sim.dt * 1e9))
        start = self.timebase.reset(t_before) * 1e-9
        self.monitor.reset()
        self._next_sigma = 0.0
        self.pacer.restart()
        self.outputs.notice(events.RESET, events.reset_text(ended, start))  # as the logs record it
        self._emit(self.sim.sample(singular_values=True))
        self._holding = self.options.wait_for_command
        with self._cv:
            self._resets_done = self._resets_asked
            self._cv.notify_all()
