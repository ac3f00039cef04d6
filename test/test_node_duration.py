"""``duration`` of a live ``vjm_sim_node`` counts simulated time since its start, across resets.

The node runs as a process of its own (``python -m vjm_ros.ros.node``, always reaped) on this
process's ROS domain; a probe in a context of its own reads ``/clock`` and ``~/events`` and calls
``~/reset`` half-way. Assertions are on simulated time and tick counts; wall-clock timeouts are
hang guards.
"""

import json
import re

import pytest

pytestmark = pytest.mark.ros


def test_duration_is_simulated_time_since_start_also_after_a_reset(reset_run):
    # The session's run reset half-way (conftest.py ``reset_run``, shared with
    # test_log_reset_event.py): ``rate`` Hz ticks for ``duration`` s of simulated time; the reset
    # comes once /clock has passed ``reset_after`` s.
    probe, returncode, out, _, rate, duration, reset_after = reset_run
    tick_ns = round(1e9 / rate)
    assert returncode == 0, out
    clocks = probe.clocks
    assert any(e.startswith("reset:") for e in probe.events), probe.events
    assert all(b > a for a, b in zip(clocks, clocks[1:], strict=False))
    # The reset came half-way: the episode before it ended after reset_after of simulated time.
    ended = float(re.search(r"reset: .* after t = (\S+) s", "\n".join(probe.events)).group(1))
    assert reset_after <= ended < duration
    # The last /clock is the duration, within one tick (the reset's state takes a tick of
    # simulated time without a step of the physics).
    assert abs(clocks[-1] - round(duration * 1e9)) <= tick_ns, clocks[-1]
    assert re.search(rf"stopped \(duration\) at t = {duration:g} s after \d+ ticks", out), out
    summary = json.loads(re.search(r"summary (\{.*\})", out).group(1))
    assert summary["reason"] == "duration"
    assert summary["sim_time"] == pytest.approx(clocks[-1] * 1e-9, abs=1e-9)
    # every tick of both episodes, less the reset's
    assert summary["ticks"] == round(duration * rate) - 1
    assert summary["realtime_factor"] == pytest.approx(summary["sim_time"] / summary["wall_time"])
