"""The reset event in a live node's MCAP log is the message the node published on ``~/events``.

``vjm_sim_node`` runs as a process of its own (``python -m vjm_ros.ros.node``, always reaped) on
this process's ROS domain, recording an MCAP; a probe in a context of its own reads ``~/events``
and ``/clock`` with real subscribers and calls ``~/reset`` half-way. The log is read back with
rosbags. Wall-clock timeouts are hang guards.
"""

import pytest
from reset_run import NODE, run_with_reset
from rosbags.highlevel import AnyReader

from vjm_ros.logs import events

pytestmark = pytest.mark.ros


def test_the_logged_reset_event_is_the_one_published(tmp_path):
    # 100 Hz ticks (two substeps keep the thesis gains inside rk4's bound) for 1.5 s of simulated
    # time; the reset comes once /clock has passed 0.5 s.
    mcap = tmp_path / "run.mcap"
    probe, returncode, out = run_with_reset(
        ["rate_hz:=100.0", "substeps:=2", "duration:=1.5", f"mcap:={mcap}"], 0.5,
        "reset_event_probe")
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
