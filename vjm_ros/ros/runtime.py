"""Process plumbing of the nodes: the executor thread, stop signals, realtime priority.

* :class:`Spinner` spins an executor in a background thread with ``spin_once(timeout_sec=0.05)``
  (the pattern that kept 1 kHz with 2000 incoming messages per second on this machine), between
  the ticks when given the tick loop's gate;
* :class:`StopOnSignals` turns SIGINT and SIGTERM into a clean stop of the tick loop;
* :func:`raise_priority` puts the tick loop's thread under SCHED_FIFO (Linux);
* :class:`PolledGroup` hands subscriptions to the tick loop, which takes their messages itself
  (:func:`take_all`) while it ticks freely;
* :func:`raw_publish` publishes serialized messages without rclpy's per-call guard.
"""

from __future__ import annotations

import os
import threading
import traceback
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

from rclpy.callback_groups import CallbackGroup
from rclpy.exceptions import InvalidHandle
from rclpy.executors import ExternalShutdownException

from vjm_ros.logs.signals import StopSignals
from vjm_ros.realtime.gate import Gate

if TYPE_CHECKING:
    from rclpy.callback_groups import Entity
    from rclpy.executors import Executor
    from rclpy.impl.rcutils_logger import RcutilsLogger
    from rclpy.node import Node
    from rclpy.publisher import Publisher
    from rclpy.subscription import Subscription

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

    def __init__(self, executor: Executor, gate: Gate | None = None) -> None:
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


class PolledGroup(CallbackGroup):
    """A callback group whose subscriptions the executor leaves alone while ``polled()`` is true.

    The tick loop then takes their messages at the start of each tick (:func:`take_all`): at
    1 kHz of commands the executor thread spent about 240 µs of CPU per message here (wait set,
    take, dispatch), the tick loop's take about a tenth of it. When ``polled()`` is false
    (paused, holding for the first command, lockstep) the executor runs the callbacks as usual.

    Parameters
    ----------
    polled : callable
        Whether the tick loop takes the messages now (read by the executor thread).
    """

    def __init__(self, polled: Callable[[], bool]) -> None:
        super().__init__()
        self.polled = polled

    def can_execute(self, entity: Entity) -> bool:
        """Whether the executor may wait for and run the entity's callbacks now."""
        return not self.polled()

    def beginning_execution(self, entity: Entity) -> bool:
        """Callbacks of this group may run side by side (each takes its own message)."""
        return True

    def ending_execution(self, entity: Entity) -> None:
        """Nothing to release."""


def raw_publish(publisher: Publisher) -> Callable[[bytes], None]:
    """The publish of serialized messages of ``publisher`` (a ``rclpy.publisher.Publisher``).

    ``Publisher.publish(data)`` enters the publisher's handle (so that it cannot be destroyed
    meanwhile) and tests the message's type before rclpy's ``publish_raw``: 4 us of each
    message's ~45 us on a slow machine, five to seven times per tick in the node. The returned
    function is ``publish_raw`` itself; the caller publishes from one thread and destroys the
    publisher only after its last call (the node: its tick loop, which rebuilds these functions
    when a reset rebuilds a publisher).

    Returns
    -------
    callable
        ``f(data: bytes)``: publish one CDR-serialized message of the publisher's type.
    """
    return publisher.handle.publish_raw


def take_all(
    subscriptions: Iterable[tuple[Subscription, Callable[..., object]]],
) -> list[tuple[Callable[..., object], object]]:
    """Take every message waiting on ``subscriptions`` (pairs of subscription and handler) and
    return ``(handler, message)`` pairs in order of reception (the messages' received
    timestamps; within one subscription, the order taken)."""
    taken = []
    for sub, handler in subscriptions:
        try:
            with sub.handle:
                while (got := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                    msg, info = got
                    taken.append((info.get("received_timestamp", 0), len(taken), handler, msg))
        except InvalidHandle:  # destroyed while shutting down
            continue
    if len(taken) > 1:
        taken.sort(key=lambda item: item[:2])
    return [(handler, msg) for _, _, handler, msg in taken]


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


def run_node_until_signal(make_node: Callable[[], Node], name: str,
                          args: list[str] | None = None) -> int:
    """Console entry point of a controller node: build it, spin until SIGINT or SIGTERM.

    The process handles the signals itself (:class:`~vjm_ros.logs.signals.StopSignals`) and
    spins with ``spin_once(timeout_sec=SPIN_TIMEOUT)``, so a signal is seen within that timeout
    whatever the executor is waiting for. Left to rclpy's own handler, a SIGINT once went unseen:
    the process stayed in the executor's wait for good (1 test run in about 20).

    Returns 0 after a signal, 2 when the node cannot be built (the reason on stderr).
    """
    import sys

    import rclpy
    import rclpy.exceptions
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from vjm_ros.core.errors import VjmError

    with StopSignals() as signals:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        try:
            node = make_node()
        except (ValueError, OSError, VjmError, rclpy.exceptions.ParameterException) as exc:
            print(f"{name}: {exc}", file=sys.stderr)
            rclpy.try_shutdown()
            return 2
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        try:
            while not signals.requested and rclpy.ok():
                executor.spin_once(timeout_sec=SPIN_TIMEOUT)
        except ExternalShutdownException:
            pass
        finally:
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown()
    return 0


def raise_priority(priority: int, logger: RcutilsLogger) -> None:
    """Put the calling thread under SCHED_FIFO at ``priority`` (0: leave it); warn if refused."""
    if priority <= 0:
        return
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError) as exc:
        logger.warning(f"realtime_priority {priority} not granted ({exc}); normal scheduling")
    else:
        logger.info(f"tick loop at SCHED_FIFO priority {priority}")
