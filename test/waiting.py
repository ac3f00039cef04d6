"""Waiting in tests for what another thread or process does, and the times it stamps."""

from __future__ import annotations

import time


def wait_for(predicate, timeout=10.0, what="condition", poll=0.005):
    """Poll ``predicate`` until true; ``timeout`` is a hang guard (wall s), not a speed limit."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(poll)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def nanoseconds(msg_stamp) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time``."""
    return msg_stamp.sec * 1_000_000_000 + msg_stamp.nanosec
