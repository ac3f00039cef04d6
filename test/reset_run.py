"""A live ``vjm_sim_node`` process reset half-way, watched by a probe: shared by the tests of
``duration`` across resets and of the logged reset event.

The node runs as a process of its own (``python -m vjm_ros.ros.node``, always reaped) on this
process's ROS domain; the probe, in an rclpy context of its own, reads ``/clock`` (ns) and
``~/events`` with real subscribers and calls ``~/reset`` once ``/clock`` has passed a time.
Wall-clock timeouts are hang guards, never speed limits.
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))

import subprocess  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
from pathlib import Path  # noqa: E402

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import SetBool, Trigger  # noqa: E402
from waiting import nanoseconds, wait_for

from vjm_ros.ros.runtime import Spinner  # noqa: E402

DOMAIN = int(os.environ["ROS_DOMAIN_ID"])
ROOT = Path(__file__).resolve().parents[1]
NODE = "/vjm_sim_node"
DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)


class Probe:
    """Reads ``/clock`` (ns) and ``~/events`` in a context of its own; calls ``~/reset``."""

    def __init__(self, name: str):
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=DOMAIN, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.ctx)
        self.lock = threading.Lock()
        self.clocks: list[int] = []
        self.events: list[str] = []
        self.node.create_subscription(Clock, "/clock", self._on_clock, DEEP)
        self.node.create_subscription(String, f"{NODE}/events", self._on_event, DEEP)
        self.reset = self.node.create_client(Trigger, f"{NODE}/reset")
        self.pause = self.node.create_client(SetBool, f"{NODE}/pause")
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.spinner = Spinner(self.executor).start()

    def _on_clock(self, msg):
        with self.lock:
            self.clocks.append(nanoseconds(msg.clock))

    def _on_event(self, msg):
        with self.lock:
            self.events.append(msg.data)

    def last_clock(self) -> int:
        with self.lock:
            return self.clocks[-1] if self.clocks else -1

    def close(self):
        self.spinner.stop()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def run_with_reset(parameters: list[str], reset_after: float, name: str):
    """Run the node in realtime with ``parameters`` (``name:=value``), paused until the probe
    sees it, reset it once ``/clock`` has passed ``reset_after`` s, and wait for it to stop by
    itself (it needs a ``duration``).

    Returns
    -------
    probe : Probe
        Closed; its ``clocks`` and ``events`` hold what it heard.
    returncode : int
    out : str
        The node's standard output and error.
    """
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(DOMAIN),
               PYTHONPATH=str(ROOT))
    # started paused, resumed once the probe sees it: a node that ran its whole duration before
    # discovery finished (seconds on a loaded machine) left the probe waiting for a service
    cmd = [sys.executable, "-m", "vjm_ros.ros.node", "--ros-args", "-p", "realtime:=true",
           "-p", "wait_for_command:=false", "-p", "start_paused:=true"]
    for parameter in parameters:
        cmd += ["-p", parameter]
    probe = Probe(name)
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        assert probe.reset.wait_for_service(timeout_sec=60.0), "no ~/reset service"
        assert probe.pause.wait_for_service(timeout_sec=60.0), "no ~/pause service"
        wait_for(lambda: all(probe.node.count_publishers(t) > 0
                             for t in ("/clock", f"{NODE}/events")), 60.0, "the node's topics")
        resumed = probe.pause.call_async(SetBool.Request(data=False))
        wait_for(resumed.done, 30.0, "the resume's answer")
        assert resumed.result().success, resumed.result().message
        wait_for(lambda: probe.last_clock() >= round(reset_after * 1e9), 60.0,
                 f"/clock to pass {reset_after} s")
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
    return probe, proc.returncode, out
