"""Blocks of ticks written by threads of their own while the physics computes the next blocks.

``vjm run`` computes a block of ticks in one compiled call that releases the GIL
(:meth:`vjm_ros.sim.simulator.Simulator.advance_block`); what is done with a block (the
trajectory and its CSV, the MCAP and rerun logs) is independent of the next block's physics.
:class:`BlockFanOut` hands each filled block to every *consumer*, each consumer in a thread of its
own (or a few consumers sharing one thread, one after the other) that takes the blocks in the
order they were filled, and gives the block back for refilling once every consumer is done with
it. So on two cores the logs are written while the physics runs, and the consumers run beside
each other where they release the GIL (compiled CSV formatting, chunk compression, file writes).
Consumers that share a thread cost fewer thread switches and GIL hand-overs, which on two cores
take time from the physics and from each other.

Guarantees:

* each consumer's ``start`` (opening its file) runs first, in its thread, beside the physics
  (consumers sharing a thread start one after the other, in order, before any of them writes),
  and the consumer writes blocks as soon as it has started; a consumer whose ``start`` fails
  writes nothing and is not finished, and the error is raised in the calling thread (by the
  next :meth:`put` or by :meth:`close`); :attr:`BlockFanOut.all_started` tells a consumer
  whether every other one has started (to create a file only then);
* every consumer sees every block handed over, in order, exactly once, before :meth:`close`
  returns (also when the run ends by a signal or an exception: ``close`` is called in a
  ``finally``), then runs its ``finish`` (closing its files) in its thread;
* an exception raised by a consumer (other than what the consumer handles itself, such as a
  log given up on a full disk) stops that consumer (not those sharing its thread) and is raised
  again in the calling thread by the next :meth:`put` or by :meth:`close`;
* at most ``depth`` blocks exist: the physics waits for a free block when the consumers lag.

The consumers' threads run at a lower scheduling priority than the physics (:data:`NICENESS`,
Linux, where a thread has a priority of its own; threads a consumer starts, such as the rerun
SDK's encoder and file writer, inherit it): on two cores the logs then take what the physics
leaves, instead of preempting it at every block.

While blocks are in flight the interpreter's switch interval is shortened
(:data:`SWITCH_INTERVAL`): the physics thread needs the GIL for a few microseconds between two
compiled calls, and with the default 5 ms it would wait for a consumer's time slice to end at
every block.
"""

from __future__ import annotations

import os
import queue
import sys
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

SWITCH_INTERVAL = 1e-4
"""Interpreter switch interval while consumers run, s (:func:`sys.setswitchinterval`)."""

NICENESS = 10
"""How much lower than the calling thread's the consumers' threads' scheduling priority is (the
``nice`` increment, 0-19). Measured on a 2-core machine, ``vjm run four_bar --out --mcap --rrd``
(10 s at 1 kHz), best of 16 interleaved fresh processes: 53.8 ms at 10 and 52.6 ms at 19,
against 59.4 ms at 0 (32.6 ms without outputs)."""


def lower_priority(niceness: int) -> None:
    """Lower the calling thread's scheduling priority by ``niceness`` (Linux, where each thread
    has its own ``nice`` value; elsewhere, where it would apply to the whole process, and where
    the system refuses, nothing happens). A thread started by a real-time one (the node's tick
    loop at ``realtime_priority``) inherits its SCHED_FIFO, where ``nice`` means nothing: it goes
    back to normal scheduling first."""
    if niceness <= 0 or not sys.platform.startswith("linux"):
        return
    tid = threading.get_native_id()
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:  # 0: the calling thread
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        os.setpriority(os.PRIO_PROCESS, tid, min(os.getpriority(os.PRIO_PROCESS, tid)
                                                 + niceness, 19))
    except OSError:
        pass


@dataclass
class Consumer:
    """What to do with each block, in a thread of its own.

    Attributes
    ----------
    name : str
        Thread name (shown in tracebacks).
    write : callable
        ``write(block)``: use the block's rows; must not keep references to its arrays.
    finish : callable, optional
        Called once in the consumer's thread after the last block (close files); not called
        when ``start`` failed.
    start : callable, optional
        Called once in the consumer's thread before any block (open files).
    """

    name: str
    write: Callable[[object], None]
    finish: Callable[[], None] | None = None
    start: Callable[[], None] | None = None


_STOP = object()

IN_CALLING_THREAD = False
"""Run the consumers in the calling thread, one after the other, at :meth:`BlockFanOut.put`
(for profiling their cost without threads waiting for each other; see
:func:`benchmarks.log_cost.breakdown`)."""


class BlockFanOut:
    """Hands filled blocks to consumers, each in a thread of its own (see the module notes).

    Parameters
    ----------
    make_block : callable
        ``make_block()`` returns a new empty block (called at most ``depth`` times).
    consumers : sequence of Consumer or of sequences of Consumer
        A sequence of consumers shares one thread: each block goes to them in their order.
    depth : int
        Blocks in circulation: one being filled, the others queued or being written.

    Notes
    -----
    Use as a context manager, or call :meth:`close` in a ``finally``.
    """

    def __init__(self, make_block: Callable[[], object],
                 consumers: Sequence[Consumer | Sequence[Consumer]], depth: int = 16):
        groups = [(c,) if isinstance(c, Consumer) else tuple(c) for c in consumers]
        groups = [g for g in groups if g]
        self._make_block = make_block
        self._free: queue.SimpleQueue = queue.SimpleQueue()
        self._made = 0
        self._depth = max(int(depth), 2)
        self._pending: dict[int, int] = {}
        self._lock = threading.Lock()
        self._errors: list[BaseException] = []
        self._raised = False
        self._closed = False
        self._interval = sys.getswitchinterval()
        sys.setswitchinterval(min(self._interval, SWITCH_INTERVAL))
        self._starts_left = sum(len(g) for g in groups)
        self._starts_done = threading.Event()
        if not groups:
            self._starts_done.set()
        self._start_failed = False
        if IN_CALLING_THREAD:
            self._queues = [_InCallingThread(self, c) for g in groups for c in g]
            self._threads = []
            return
        self._queues = [queue.SimpleQueue() for _ in groups]
        self._threads = [
            threading.Thread(target=self._serve, args=(g, q), daemon=True,
                             name=" + ".join(c.name for c in g))
            for g, q in zip(groups, self._queues, strict=True)
        ]
        running = 0
        try:
            for thread in self._threads:
                thread.start()
                running += 1
        except BaseException:  # no thread to be had: the others stop, nothing is written
            self._start_failed = True
            for _ in range(sum(len(g) for g in groups[running:])):
                self._count_start()
            for q in self._queues[:running]:
                q.put(_STOP)
            sys.setswitchinterval(self._interval)
            raise

    @property
    def start_failed(self) -> bool:
        """Whether a consumer's ``start`` failed."""
        return self._start_failed

    @property
    def all_started(self) -> bool:
        """Whether every consumer's ``start`` has returned, none failing (does not wait)."""
        return self._starts_done.is_set() and not self._start_failed

    def wait_started(self) -> bool:
        """Wait until every consumer's ``start`` has returned or failed; :attr:`all_started`."""
        self._starts_done.wait()
        return self.all_started

    def take(self) -> object:
        """A block to fill: a new one while fewer than ``depth`` exist, else the next one the
        consumers give back (waits for it)."""
        try:
            return self._free.get_nowait()
        except queue.Empty:
            pass
        if self._made < self._depth:
            self._made += 1
            return self._make_block()
        return self._free.get()

    def put(self, block: object) -> None:
        """Hand a filled block to every consumer; raises a consumer's exception if one failed."""
        self._raise_error()
        if not self._queues:
            self._free.put(block)
            return
        with self._lock:
            self._pending[id(block)] = len(self._queues)
        for q in self._queues:
            q.put(block)

    def close(self) -> None:
        """Wait until every consumer has written every block and finished; restore the switch
        interval; raise the first exception of a consumer, if any. Later calls do nothing."""
        if self._closed:
            return
        self._closed = True
        try:
            for q in self._queues:
                q.put(_STOP)
            for thread in self._threads:
                thread.join()
        finally:
            sys.setswitchinterval(self._interval)
        self._raise_error()

    def __enter__(self) -> BlockFanOut:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ consumer threads
    def _serve(self, group: tuple[Consumer, ...], blocks: queue.SimpleQueue) -> None:
        """One thread's work: start its consumers, hand them every block in turn (each until
        it fails), then finish those that started."""
        lower_priority(NICENESS)
        started = [self._start(consumer) for consumer in group]
        writing = [c for c, ok in zip(group, started, strict=True) if ok]
        while True:
            block = blocks.get()
            if block is _STOP:
                break
            writing = [c for c in writing if self._write(c, block)]
            self._release(block)
        for consumer, ok in zip(group, started, strict=True):
            if ok:
                self._finish(consumer)

    def _call(self, step, *args) -> bool:
        """Run one of a consumer's ``start``, ``write`` or ``finish`` (None: nothing to run);
        whether it returned without raising (what it raised is kept for the caller)."""
        try:
            if step is not None:
                step(*args)
        except BaseException as exc:  # noqa: BLE001 - raised again in the caller
            self._errors.append(exc)
            return False
        return True

    def _write(self, consumer: Consumer, block) -> bool:
        """Hand ``block`` to the consumer; whether it took it without raising."""
        return self._call(consumer.write, block)

    def _finish(self, consumer: Consumer) -> None:
        self._call(consumer.finish)

    def _start(self, consumer: Consumer) -> bool:
        """Run the consumer's ``start``; whether it started."""
        started = self._call(consumer.start)
        if not started:
            self._start_failed = True
        self._count_start()
        return started

    def _count_start(self) -> None:
        """One consumer's ``start`` has returned (or will never run)."""
        with self._lock:
            self._starts_left -= 1
            if self._starts_left == 0:
                self._starts_done.set()

    def _release(self, block) -> None:
        with self._lock:
            left = self._pending[id(block)] - 1
            if left:
                self._pending[id(block)] = left
                return
            del self._pending[id(block)]
        self._free.put(block)

    def _raise_error(self) -> None:
        if self._errors and not self._raised:
            self._raised = True
            raise self._errors[0]


class _InCallingThread:
    """A consumer's thread and queue in one, when :data:`IN_CALLING_THREAD`: the consumer
    starts at once and takes each block when it is put."""

    def __init__(self, fan: BlockFanOut, consumer: Consumer):
        self.fan = fan
        self.consumer = consumer
        self.started = fan._start(consumer)
        self.failed = not self.started

    def put(self, block) -> None:
        if block is _STOP:
            if self.started:
                self.fan._finish(self.consumer)
            return
        self.failed = self.failed or not self.fan._write(self.consumer, block)
        self.fan._release(block)
