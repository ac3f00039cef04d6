"""The gate between the tick loop and the executor thread, without ROS."""

from __future__ import annotations

import threading


class Gate:
    """When the executor thread may run ROS callbacks.

    The tick loop closes the gate from just before a realtime tick's deadline until the tick's
    outputs are out. Callbacks then run between ticks only; a message that arrives during a
    tick waits in its subscription's keep-last queue (and under a flood, older ones drop out of
    it). Without the gate a flood of incoming messages (a callback costs ~150 us of CPU here)
    holds the interpreter lock when a tick is due.
    """

    def __init__(self) -> None:
        self._cv = threading.Condition()
        self._open = True

    @property
    def is_open(self) -> bool:
        """Whether a callback may run now."""
        return self._open

    def open(self) -> None:
        """Let callbacks run."""
        with self._cv:
            self._open = True
            self._cv.notify_all()

    def close(self) -> None:
        """No callbacks until the next :meth:`open`."""
        with self._cv:
            self._open = False

    def enter(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s until callbacks may run; False if they still may not."""
        with self._cv:
            return self._cv.wait_for(lambda: self._open, timeout)
