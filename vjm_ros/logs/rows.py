"""The ticks of a live loop collected into blocks, which a thread of their own writes to the logs.

The node ticks one at a time. Written sample by sample in the tick thread, its logs took the
per-message paths: on a slow 2-core machine an MCAP log cost 114 µs of CPU per tick that way
(five records through the ``mcap`` writer), where the bulk encoder
(:meth:`vjm_ros.logs.McapRecorder.write_block`) costs 7 µs per tick in blocks of 100 ticks, in
one burst of about 1 ms per block. :class:`LogRows` copies each tick's sample into a block whose
efforts are kept per row and hands the block, when it is full or its first row has waited
``max_wait`` s of wall time, to a thread that writes it
(:meth:`vjm_ros.logs.storage.LogWriters.write_block`) while the tick thread goes on: the bursts
fall between ticks (the node's thread switch interval is 0.1 ms) or on the other core, not into
them. :meth:`sync` waits until every row added is written: before a reset is noted, while
paused, when the loop ends.

What the logs hold does not change: the records, their times and order are those of writing
each sample (the block encoders' guarantee), except that the wall-time conditions of the
recorders (closing an MCAP chunk, sending to rerun) are checked once per block. A process killed
with SIGKILL loses the rows not yet written, at most ``max_wait`` s more than before.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from vjm_ros.core.model import Model
from vjm_ros.logs.background import BlockFanOut, Consumer
from vjm_ros.sim.samples import BLOCK_FIELDS, Sample, SampleBlock

CAPACITY = 100
"""Rows per block: 0.1 s at 1 kHz. Per tick an MCAP log then costs about 7 µs (23 µs in blocks
of 20, 114 µs sample by sample, measured on one slow machine), in one burst per block."""
MAX_WAIT = 0.1
"""Longest wall time from a block's first row to its hand-over while ticks go on, s (what a live
rerun viewer lags behind at low tick rates); a loop that stops ticking syncs."""



class LogRows:
    """Samples of single ticks, written to the logs a block at a time by a thread of their own.

    Parameters
    ----------
    model : Model
        The simulated model (the blocks' shapes).
    write_block : callable
        ``write_block(block)``: writes the rows of a
        :class:`~vjm_ros.sim.samples.SampleBlock` whose ``effort`` has one row per tick, shape
        (capacity, n); must not keep references to the block's arrays. Called in the writing
        thread (or in :meth:`add`'s caller when ``background`` is False).
    capacity : int
        Rows per block.
    max_wait : float
        Wall time after which a block is handed over even if not full, s.
    clock : callable
        Monotonic wall time, s.
    depth : int
        Blocks the writing thread circulates (:class:`~vjm_ros.logs.background.BlockFanOut`):
        when none is free (the logs cannot keep up), :meth:`add` waits for one.
    background : bool
        Write in a thread of its own; False writes in the caller's thread.

    Notes
    -----
    An exception of ``write_block`` is raised again, once, by a later hand-over (in
    :meth:`add`) or by :meth:`sync`; the rows of the blocks after it are not written.
    """

    def __init__(self, model: Model, write_block: Callable[[SampleBlock], None],
                 capacity: int = CAPACITY, max_wait: float = MAX_WAIT,
                 clock: Callable[[], float] = time.perf_counter, depth: int = 3,
                 background: bool = True):
        if capacity < 1:
            raise ValueError(f"capacity: expected at least 1 row, found {capacity!r}")
        self._model, self._capacity = model, int(capacity)
        self._write_block = write_block
        self.max_wait = float(max_wait)
        self._clock = clock
        self._depth = int(depth)
        self._background = bool(background)
        self._writer: BlockFanOut | None = None
        self._first = 0.0
        self._fill(self._new_block())

    def _new_block(self) -> SampleBlock:
        block = SampleBlock(self._model, self._capacity)
        block.effort = np.zeros((self._capacity, self._model.n))
        return block

    def _fill(self, block: SampleBlock) -> None:
        block.rows = 0
        self.block = block
        self._targets = [(getattr(block, key), attr) for key, attr in BLOCK_FIELDS]

    def __len__(self) -> int:
        """Rows in the block being filled (not handed over yet)."""
        return self.block.rows

    def add(self, sample: Sample) -> None:
        """Copy one tick's :class:`~vjm_ros.sim.samples.Sample` (geometry included) into the
        block; hand the block over when it is full or its first row has waited ``max_wait``."""
        block = self.block
        i = block.rows
        if i == 0:
            self._first = self._clock()
        block.t[i] = sample.t
        block.effort[i] = sample.effort
        if sample.measured is not None:  # a scene with sensors
            if block.measured is None:
                block.measured = np.zeros((self._capacity,) + sample.measured.shape)
            block.measured[i] = sample.measured
        for target, attr in self._targets:
            target[i] = getattr(sample, attr)
        block.rows = i + 1
        if block.rows == self._capacity or self._clock() - self._first >= self.max_wait:
            self._hand_over()

    def _hand_over(self) -> None:
        block = self.block
        if not self._background:
            try:
                self._write_block(block)
            finally:
                block.rows = 0
            return
        if self._writer is None:
            consumer = Consumer(name="vjm log writer", write=self._write_block)
            self._writer = BlockFanOut(self._new_block, [consumer], depth=self._depth)
        try:
            self._writer.put(block)  # raises an error of an earlier block's writing
        except BaseException:
            block.rows = 0  # lost with the log's error
            raise
        self._fill(self._writer.take())

    def sync(self) -> None:
        """Hand over the rows added and wait until every one is written (the writing thread
        then ends; the next hand-over starts another)."""
        if self.block.rows:
            self._hand_over()
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.close()  # raises an error of the writing, once

    flush = close = sync
