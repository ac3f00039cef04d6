"""Termination signals, one mechanism: recorded by the handler, first one wins, handlers restored."""

from __future__ import annotations

import os
import signal

import pytest

from vjm_ros.logs.signals import StopSignals


def test_first_signal_is_recorded_later_ones_ignored_and_handlers_restored():
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    calls = []
    with StopSignals(on_stop=calls.append) as stop:
        assert not stop.requested and stop.code == 0
        os.kill(os.getpid(), signal.SIGTERM)  # delivered to the main thread before kill returns
        os.kill(os.getpid(), signal.SIGINT)  # a second signal: already stopping
        assert stop.code == 128 + signal.SIGTERM and stop.requested
    assert calls == [signal.SIGTERM]
    assert {s: signal.getsignal(s) for s in before} == before


def test_a_handler_that_raises_unwinds_the_block():
    def stop_now(signum):
        raise SystemExit(128 + signum)

    with pytest.raises(SystemExit) as exc, StopSignals((signal.SIGTERM,), on_stop=stop_now):
        os.kill(os.getpid(), signal.SIGTERM)
    assert exc.value.code == 128 + signal.SIGTERM
