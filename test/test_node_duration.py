"""``duration`` of a live ``vjm_sim_node`` counts simulated time since its start, across resets.

The node runs as a process of its own (``python -m vjm_ros.ros.node``, always reaped) on this
process's ROS domain; a probe in a context of its own reads ``/clock`` and ``~/events`` and calls
``~/reset`` half-way. Assertions are on simulated time and tick counts; wall-clock timeouts are
hang guards.
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))

import json  # noqa: E402
import re  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402
import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from vjm_ros.ros.conversions import nanoseconds  # noqa: E402
from vjm_ros.ros.runtime import Spinner  # noqa: E402

pytestmark = pytest.mark.ros

DOMAIN = int(os.environ["ROS_DOMAIN_ID"])
ROOT = Path(__file__).resolve().parents[1]
NODE = "/vjm_sim_node"
DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)


def wait_for(predicate, timeout, what):
    """Poll ``predicate`` until true; ``timeout`` is a hang guard (wall s), not a speed limit."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.005)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


class Probe:
    """Reads ``/clock`` (ns) and ``~/events`` in a context of its own; calls ``~/reset``."""

    def __init__(self):
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=DOMAIN, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("duration_probe", context=self.ctx)
        self.lock = threading.Lock()
        self.clocks: list[int] = []
        self.events: list[str] = []
        self.node.create_subscription(Clock, "/clock", self._on_clock, DEEP)
        self.node.create_subscription(String, f"{NODE}/events",
                                      lambda m: self.events.append(m.data), DEEP)
        self.reset = self.node.create_client(Trigger, f"{NODE}/reset")
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.spinner = Spinner(self.executor).start()

    def _on_clock(self, msg):
        with self.lock:
            self.clocks.append(nanoseconds(msg.clock))

    def last_clock(self) -> int:
        with self.lock:
            return self.clocks[-1] if self.clocks else -1

    def close(self):
        self.spinner.stop()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def test_duration_is_simulated_time_since_start_also_after_a_reset():
    # 100 Hz ticks (two substeps keep the thesis gains inside rk4's bound) for 2 s of simulated
    # time; the reset comes once /clock has passed 1 s.
    rate, duration = 100.0, 2.0
    tick_ns = round(1e9 / rate)
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(DOMAIN),
               PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "vjm_ros.ros.node", "--ros-args", "-p", f"rate_hz:={rate}",
           "-p", "substeps:=2", "-p", f"duration:={duration}", "-p", "realtime:=true",
           "-p", "wait_for_command:=false"]
    probe = Probe()
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        assert probe.reset.wait_for_service(timeout_sec=60.0), "no ~/reset service"
        wait_for(lambda: probe.last_clock() >= 1_000_000_000, 60.0, "/clock to pass 1 s")
        future = probe.reset.call_async(Trigger.Request())
        wait_for(future.done, 30.0, "the reset's answer")
        assert future.result().success, future.result().message
        out, _ = proc.communicate(timeout=60.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        probe.close()
    assert proc.returncode == 0, out
    clocks = probe.clocks
    assert any(e.startswith("reset:") for e in probe.events), probe.events
    assert all(b > a for a, b in zip(clocks, clocks[1:], strict=False))
    # The reset came half-way: the episode before it ended after 1 s of simulated time.
    ended = float(re.search(r"reset: .* after t = (\S+) s", "\n".join(probe.events)).group(1))
    assert 1.0 <= ended < duration
    # The last /clock is the duration, within one tick (the reset's state takes a tick of
    # simulated time without a step of the physics).
    assert abs(clocks[-1] - round(duration * 1e9)) <= tick_ns, clocks[-1]
    assert re.search(r"stopped \(duration\) at t = 2 s after \d+ ticks", out), out
    summary = json.loads(re.search(r"summary (\{.*\})", out).group(1))
    assert summary["reason"] == "duration"
    assert summary["sim_time"] == pytest.approx(clocks[-1] * 1e-9, abs=1e-9)
    # every tick of both episodes, less the reset's
    assert summary["ticks"] == round(duration * rate) - 1
    assert summary["realtime_factor"] == pytest.approx(summary["sim_time"] / summary["wall_time"])
