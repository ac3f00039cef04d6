"""The reset event in a live node's MCAP log is the message the node published on ``~/events``.

``vjm_sim_node`` runs as a process of its own (``python -m vjm_ros.ros.node``, always reaped) on
this process's ROS domain, recording an MCAP; a probe in a context of its own reads ``~/events``
and ``/clock`` with real subscribers and calls ``~/reset`` half-way. The log is read back with
rosbags. Wall-clock timeouts are hang guards.
"""

import pytest
from reset_run import NODE
from rosbags.highlevel import AnyReader

from vjm_ros.logs import events

pytestmark = pytest.mark.ros


def test_the_logged_reset_event_is_the_one_published(reset_run):
    # The session's run reset half-way (conftest.py ``reset_run``: 100 Hz ticks for 2 s of
    # simulated time, the reset once /clock has passed 1 s, recording an MCAP), shared with
    # test_node_duration.py: which tick the reset comes at does not matter here, only that the
    # logged event is the published one and names the log's own times.
    probe, returncode, out, mcap = reset_run[:4]
    assert returncode == 0, out
    (live,) = [e for e in probe.events if e.startswith("reset:")]

    with AnyReader([mcap]) as reader:
        conns = [c for c in reader.connections if c.topic in (f"{NODE}/events", "/clock")]
        logged, clocks = [], []
        for conn, ns, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/clock":
                clocks.append(ns)
            else:
                logged.append((ns, msg.data))
    ((reset_ns, text),) = logged
    assert text == live
    # The text states the log's own times: the episode ended at the last /clock before the
    # event, and the next one starts at the event's log time, which is the next /clock.
    ended = max(t for t in clocks if t < reset_ns)
    assert min(t for t in clocks if t >= reset_ns) == reset_ns
    assert text == events.reset_line(ended * 1e-9, reset_ns * 1e-9)
