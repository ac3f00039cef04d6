"""Termination signals, handled one way everywhere: recorded by the handler, acted on between writes.

:class:`StopSignals` is the one mechanism. Its handler does no work of its own: it records the
first signal (``code = 128 + signum``), calls an optional ``on_stop`` and ignores later signals,
so a second Ctrl-C cannot cut the finalization of a log short. What the program does with the
request is its own choice:

* ``vjm run`` checks :attr:`StopSignals.code` between two ticks and ends the run (exit 130/143);
* the node stops its tick loop (``on_stop``) and exits 0;
* library users wrap their own loops in :func:`finalize_on_signals`, which turns the signal into
  :class:`SystemExit` at once, or, if a recorder is writing in the main thread, when that write
  returns (:func:`atomic`), so that the ``close()`` of every recorder runs and no log holds half a
  message.

Outside the main thread, where Python cannot install handlers, nothing is installed.
"""

from __future__ import annotations

import functools
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

INTERACTIVE_SIGNALS: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)
"""Signals a program run by hand or by a launch system stops on."""
DEFAULT_SIGNALS: tuple[int, ...] = tuple(
    s for s in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None)) if s is not None
)
"""Signals :func:`finalize_on_signals` converts (SIGINT already raises KeyboardInterrupt)."""


class StopSignals:
    """Context manager: a termination signal during the block is a request to stop.

    Parameters
    ----------
    signals : tuple of int
        Signals to handle (SIGINT and SIGTERM by default).
    on_stop : callable, optional
        Called with the signal number at the first signal, from the handler (keep it short:
        set a flag, notify a condition, raise to unwind).

    Attributes
    ----------
    code : int
        ``128 + signum`` of the first signal; 0 while none came.
    """

    def __init__(
        self,
        signals: tuple[int, ...] = INTERACTIVE_SIGNALS,
        on_stop: Callable[[int], None] | None = None,
    ) -> None:
        self.signals = signals
        self.on_stop = on_stop
        self.code = 0
        self._previous: dict = {}

    @property
    def requested(self) -> bool:
        """Whether a signal came."""
        return self.code != 0

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            self._previous = {s: signal.signal(s, self._handle) for s in self.signals}
        return self

    def __exit__(self, *exc) -> None:
        for s, handler in self._previous.items():
            signal.signal(s, handler)
        self._previous = {}

    def _handle(self, signum: int, frame: object) -> None:
        if self.code:
            return  # later signals: already stopping
        self.code = 128 + signum
        if self.on_stop is not None:
            self.on_stop(signum)


class _SignalDeferral:
    """A termination signal that arrives while a recorder writes, in the main thread, is acted on
    when the write returns: a log is never left with half a message (its statistics counting a
    message its chunk does not hold)."""

    def __init__(self) -> None:
        self.depth = 0
        self.pending: int | None = None
        self.main = threading.main_thread().ident


_DEFERRAL = _SignalDeferral()


def atomic(method: Callable) -> Callable:
    """Decorate a recorder method that writes: :func:`finalize_on_signals` waits for it."""

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        if threading.get_ident() != _DEFERRAL.main:
            return method(self, *args, **kwargs)
        _DEFERRAL.depth += 1
        try:
            return method(self, *args, **kwargs)
        finally:
            _DEFERRAL.depth -= 1
            if _DEFERRAL.depth == 0 and _DEFERRAL.pending is not None:
                code, _DEFERRAL.pending = _DEFERRAL.pending, None
                raise SystemExit(code)

    return wrapper


def _exit_now_or_after_the_write(signum: int) -> None:
    if _DEFERRAL.depth:  # inside a recorder's write: exit when it returns
        _DEFERRAL.pending = 128 + signum
        return
    raise SystemExit(128 + signum)


@contextmanager
def finalize_on_signals() -> Iterator[None]:
    """Turn termination signals (:data:`DEFAULT_SIGNALS`: SIGTERM and SIGHUP) into
    :class:`SystemExit` while the block runs.

    A process stopped with SIGTERM (``kill``, ``timeout``, a launch system) then unwinds normally,
    so the ``close()`` of every recorder opened in or around the block runs and the logs are
    finalized. A signal that arrives while a recorder writes takes effect when the write returns
    (:func:`atomic`). The exit status is ``128 + signal number``, as for a default kill. Further
    signals of the set are ignored while unwinding, so a second SIGTERM cannot cut finalization
    short (SIGKILL still can). The previous handlers come back when the block ends. SIGINT is left
    alone: Python already raises :class:`KeyboardInterrupt` for it.
    """
    with StopSignals(DEFAULT_SIGNALS, on_stop=_exit_now_or_after_the_write):
        yield
