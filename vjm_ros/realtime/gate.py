"""The gate between the tick loop and the executor thread, without ROS."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable


class Gate:
    """When the executor thread may run ROS callbacks.

    After a realtime tick the loop opens the gate until a time well before the next deadline;
    a callback starts only while it is open, and the loop closes it at the deadline's approach.
    Callbacks thus run between ticks and are done before the next one is due; a message that
    arrives meanwhile waits in its subscription's keep-last queue (and under a flood, older ones
    drop out of it). Without the gate a flood of incoming messages (a callback costs ~150 us of
    CPU here) holds the interpreter lock when a tick is due.

    Parameters
    ----------
    clock : callable
        Monotonic time, s (the tick loop's clock).
    """

    def __init__(self, clock: Callable[[], float] = time.perf_counter) -> None:
        self._cv = threading.Condition()
        self._clock = clock
        self._open = True
        self._until = math.inf

    @property
    def is_open(self) -> bool:
        """Whether a callback may run now."""
        return self._open and (self._until == math.inf or self._clock() < self._until)

    def open(self, until: float = math.inf) -> None:
        """Let callbacks start until the time ``until`` (of ``clock``, s)."""
        if self._open and self._until == until:
            return  # nothing changes (fast mode opens it after every tick); only this thread sets it
        with self._cv:
            self._open = True
            self._until = until
            self._cv.notify_all()

    def close(self) -> None:
        """No callbacks until the next :meth:`open`."""
        with self._cv:
            self._open = False

    def enter(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s until callbacks may run; False if they still may not."""
        with self._cv:
            return self._cv.wait_for(lambda: self.is_open, timeout)
