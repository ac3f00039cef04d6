"""The reset event in a live node's MCAP log is the message the node published on ``~/events``.

``vjm_sim_node`` runs as a process of its own (``python -m vjm_ros.ros.node``, always reaped) on
this process's ROS domain, recording an MCAP; a probe in a context of its own reads ``~/events``
and ``/clock`` with real subscribers and calls ``~/reset`` half-way. The log is read back with
rosbags. Wall-clock timeouts are hang guards.
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))

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
from rosbags.highlevel import AnyReader  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from vjm_ros.logs import events  # noqa: E402
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
        self.node = rclpy.create_node("reset_event_probe", context=self.ctx)
        self.lock = threading.Lock()
        self.last_clock = -1
        self.events: list[str] = []
        self.node.create_subscription(Clock, "/clock", self._on_clock, DEEP)
        self.node.create_subscription(String, f"{NODE}/events", self._on_event, DEEP)
        self.reset = self.node.create_client(Trigger, f"{NODE}/reset")
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.spinner = Spinner(self.executor).start()

    def _on_clock(self, msg):
        with self.lock:
            self.last_clock = nanoseconds(msg.clock)

    def _on_event(self, msg):
        with self.lock:
            self.events.append(msg.data)

    def close(self):
        self.spinner.stop()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def test_the_logged_reset_event_is_the_one_published(tmp_path):
    # 100 Hz ticks (two substeps keep the thesis gains inside rk4's bound) for 1.5 s of simulated
    # time; the reset comes once /clock has passed 0.5 s.
    mcap = tmp_path / "run.mcap"
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(DOMAIN),
               PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "vjm_ros.ros.node", "--ros-args", "-p", "rate_hz:=100.0",
           "-p", "substeps:=2", "-p", "duration:=1.5", "-p", "realtime:=true",
           "-p", "wait_for_command:=false", "-p", f"mcap:={mcap}"]
    probe = Probe()
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        assert probe.reset.wait_for_service(timeout_sec=60.0), "no ~/reset service"
        wait_for(lambda: probe.last_clock >= 500_000_000, 60.0, "/clock to pass 0.5 s")
        future = probe.reset.call_async(Trigger.Request())
        wait_for(future.done, 30.0, "the reset's answer")
        assert future.result().success, future.result().message
        wait_for(lambda: any(e.startswith("reset:") for e in probe.events), 30.0,
                 "the live reset event")
        out, _ = proc.communicate(timeout=60.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        probe.close()
    assert proc.returncode == 0, out
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
