"""Process plumbing of the nodes: the executor thread, stop signals, realtime priority.

* :class:`Spinner` spins an executor in a background thread with ``spin_once(timeout_sec=0.05)``
  (the pattern that kept 1 kHz with 2000 incoming messages per second on this machine), between
  the ticks when given the tick loop's gate;
* :class:`StopOnSignals` turns SIGINT and SIGTERM into a clean stop of the tick loop;
* :func:`raise_priority` puts the tick loop's thread under SCHED_FIFO (Linux).
"""

from __future__ import annotations

import os
import threading
import traceback
from typing import TYPE_CHECKING

from rclpy.executors import ExternalShutdownException

from vjm_ros.logs.signals import StopSignals
from vjm_ros.realtime.gate import Gate

if TYPE_CHECKING:
    from vjm_ros.realtime.loop import TickLoop

SPIN_TIMEOUT = 0.05
"""``spin_once`` timeout of the executor thread, s."""


class Spinner:
    """Spins an executor in a background thread with ``spin_once(timeout_sec=SPIN_TIMEOUT)``.

    Parameters
    ----------
    executor : rclpy.executors.Executor
    gate : Gate, optional
        The tick loop's gate: callbacks run only while it is open (between realtime ticks).
    """

    def __init__(self, executor, gate: Gate | None = None):
        self.executor = executor
        self.gate = gate
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="vjm_executor", daemon=True)

    def start(self) -> Spinner:
        """Start spinning."""
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop spinning and join the thread."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()

    def _run(self) -> None:
        gate = self.gate
        while not self._stop.is_set():
            if gate is not None and not gate.enter(SPIN_TIMEOUT):
                continue
            try:
                self.executor.spin_once(timeout_sec=SPIN_TIMEOUT)
            except ExternalShutdownException:
                return
            except Exception:
                if not self.executor.context.ok():
                    return
                traceback.print_exc()


class StopOnSignals(StopSignals):
    """Context manager: SIGINT and SIGTERM ask the tick loop to stop (the node then exits 0).

    A signal that arrives before the loop exists (while the scene loads) stops the loop as soon
    as it is attached. The handling itself is :class:`~vjm_ros.logs.signals.StopSignals`'s.
    """

    def __init__(self) -> None:
        super().__init__(on_stop=self._stop_loop)
        self.loop: TickLoop | None = None

    def _stop_loop(self, signum: int) -> None:
        if self.loop is not None:
            self.loop.stop()

    def attach(self, loop: TickLoop) -> None:
        """Stop ``loop`` on the next signal (at once if one came already)."""
        self.loop = loop
        if self.requested:
            loop.stop()


def run_node_until_signal(make_node, name: str, args: list[str] | None = None) -> int:
    """Console entry point of a controller node: build it, spin until SIGINT or SIGTERM.

    Returns 0 after a signal, 2 when the node cannot be built (the reason on stderr).
    """
    import sys

    import rclpy
    import rclpy.exceptions

    from vjm_ros.core.errors import VjmError

    rclpy.init(args=args)
    try:
        node = make_node()
    except (ValueError, OSError, VjmError, rclpy.exceptions.ParameterException) as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def raise_priority(priority: int, logger) -> None:
    """Put the calling thread under SCHED_FIFO at ``priority`` (0: leave it); warn if refused."""
    if priority <= 0:
        return
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError) as exc:
        logger.warning(f"realtime_priority {priority} not granted ({exc}); normal scheduling")
    else:
        logger.info(f"tick loop at SCHED_FIFO priority {priority}")
