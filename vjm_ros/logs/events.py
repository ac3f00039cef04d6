"""The text of the simulator's events, one source for ``~/events`` and for the logs.

A ``std_msgs/String`` on ``~/events`` holds ``kind: text`` (:func:`line`), for example
``reset: reset to the initial state after t = 1.23 s; simulated time goes on from t = 1.231 s``.
The reset is also recorded in the MCAP and rerun logs, with the same line: the node publishes
the text of :func:`reset_text` and the recorders write :func:`reset_line` of their own time axis,
which is the one published (:class:`~vjm_ros.logs.Timebase`).
"""

from __future__ import annotations

RESET = "reset"
"""Kind of the event that marks a reset of the simulator."""


def line(kind: str, text: str) -> str:
    """The ``~/events`` message of an event: ``kind: text``."""
    return f"{kind}: {text}"


def reset_text(ended: float, start: float) -> str:
    """What a reset event says.

    Parameters
    ----------
    ended : float
        Published (monotonic) simulated time of the last state of the ending episode, s.
    start : float
        Published simulated time at which the new episode starts, s.
    """
    return (f"reset to the initial state after t = {ended:.6g} s; simulated time goes on from "
            f"t = {start:.6g} s")


def reset_line(ended: float, start: float) -> str:
    """The ``~/events`` message of a reset (:func:`line` of :func:`reset_text`)."""
    return line(RESET, reset_text(ended, start))
