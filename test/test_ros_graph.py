"""The node among other nodes: namespaces, the scene for late joiners, initial positions, and a
node's own log read by rosbags across a reset.

The simulators run as separate processes (``python -m vjm_ros.ros.node``, as users start them) on
this process's ROS domain; a probe node in a private context listens and commands, and every
process is reaped. Assertions are on names, message contents and simulated time.
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))

import io  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import rclpy  # noqa: E402
import waiting
import yourdfpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray, String  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from waiting import nanoseconds

from vjm_ros.ros.runtime import Spinner  # noqa: E402
from vjm_ros.ros.scene_client import wait_for_scene_description  # noqa: E402
from vjm_ros.scene import load_scene, parse_scene  # noqa: E402
from vjm_ros.scene.assembly import closure_residual  # noqa: E402

pytestmark = pytest.mark.ros

DOMAIN = int(os.environ["ROS_DOMAIN_ID"])
ROOT = Path(__file__).resolve().parents[1]
DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""What robot_state_publisher offers and its clients ask for."""


def start_node(*params, namespace=None):
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(DOMAIN),
               PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "vjm_ros.ros.node", "--ros-args"]
    if namespace:
        cmd += ["-r", f"__ns:={namespace}"]
    for p in params:
        cmd += ["-p", p]
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def reap(proc, sig=signal.SIGINT, timeout=60.0):
    if sig is not None and proc.poll() is None:
        proc.send_signal(sig)
    try:
        out, _ = proc.communicate(timeout=timeout)  # a hang guard
    finally:
        if proc.poll() is None:
            proc.kill()
            out, _ = proc.communicate()
    return proc.returncode, out


class Probe:
    """A node of its own context: collects messages per topic, publishes, calls services."""

    def __init__(self, name="probe", namespace=None):
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=DOMAIN, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.ctx, namespace=namespace)
        self.got: dict[str, list] = {}
        self.lock = threading.Lock()
        self.executor = None

    def listen(self, topic, kind, qos=None):
        self.got[topic] = []

        def store(msg):
            with self.lock:
                self.got[topic].append(msg)

        self.node.create_subscription(kind, topic, store, qos or DEEP)

    def spin(self):
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.spinner = Spinner(self.executor).start()

    def messages(self, topic):
        with self.lock:
            return list(self.got[topic])

    def close(self):
        if self.executor is not None:
            self.spinner.stop()
            self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def wait_for(predicate, timeout=60.0, what="condition"):
    """:func:`waiting.wait_for` with this file's hang guard, 60.0 s."""
    waiting.wait_for(predicate, timeout, what)


def test_two_simulators_side_by_side_under_namespaces():
    """/a runs five_bar, /b four_bar; each controller topic reaches only its own node, and each
    node's URDF is on its own namespace's ``robot_description``, naming its joint states."""
    a = start_node("scene:=five_bar", "wait_for_command:=true", "command_timeout:=0.0",
                   "realtime:=false", "duration:=0.2", namespace="/a")
    b = start_node("scene:=four_bar", "wait_for_command:=true", "command_timeout:=0.0",
                   "realtime:=false", "duration:=0.2", namespace="/b")
    probe = Probe()
    try:
        for topic in ("/a/joint_states", "/b/joint_states", "/joint_states"):
            probe.listen(topic, JointState)
        for topic in ("/a/robot_description", "/b/robot_description", "/robot_description"):
            probe.listen(topic, String, LATCHED)  # published before the probe joins
        pub_a = probe.node.create_publisher(Float64MultiArray, "/a/vjm_sim_node/effort_commands", 10)
        probe.spin()
        wait_for(lambda: probe.messages("/a/joint_states") and probe.messages("/b/joint_states"),
                 what="both held start states")
        assert list(probe.messages("/a/joint_states")[0].name)[0] == "left_base"
        assert list(probe.messages("/b/joint_states")[0].name) == [
            "crank_joint", "coupler_joint", "rocker_joint"]
        wait_for(lambda: probe.messages("/a/robot_description")
                 and probe.messages("/b/robot_description"), what="both descriptions")
        for ns in ("/a", "/b"):
            text = probe.messages(f"{ns}/robot_description")[0].data
            robot = yourdfpy.URDF.load(io.BytesIO(text.encode()), build_scene_graph=False,
                                       load_meshes=False)
            assert robot.actuated_joint_names == list(
                probe.messages(f"{ns}/joint_states")[0].name)
        # Command /a only: /a starts (wait_for_command) and runs its duration; /b keeps holding.
        wait_for(lambda: pub_a.get_subscription_count() > 0, what="/a's command subscription")
        pub_a.publish(Float64MultiArray(data=[0.5, -0.5]))
        assert a.wait(timeout=120) == 0  # a hang guard
        time.sleep(0.3)  # /b republishes its held state every 0.1 s: it must still be at t = 0
        held_b = probe.messages("/b/joint_states")
        assert held_b and all(nanoseconds(m.header.stamp) == 0 for m in held_b)
        assert all(list(m.effort) == [0.0, 0.0, 0.0] for m in held_b)
        ran_a = probe.messages("/a/joint_states")
        assert max(nanoseconds(m.header.stamp) for m in ran_a) == 200_000_000
        assert any(list(m.effort)[0] == 0.5 for m in ran_a)
        assert not probe.messages("/joint_states")  # nothing on the root namespace
        assert not probe.messages("/robot_description")
    finally:
        probe.close()
        for proc in (a, b):
            reap(proc)


def test_scene_description_reaches_a_late_joiner_and_loads_the_simulated_model():
    node = start_node("scene:=five_bar", "start_paused:=true", "initial_positions.left_base:=-0.6")
    first = Probe("first_controller")
    try:
        # A paused node publishes its state once, before the first tick: a subscriber that
        # matches later (slow discovery on a loaded machine) never sees it. The description is
        # transient-local: receiving it here shows the node is up and has published it.
        try:
            assert wait_for_scene_description(first.node, timeout=60.0)
        finally:
            first.close()
        late = Probe("later_controller")  # joins after the description was published
        try:
            text = wait_for_scene_description(late.node, timeout=30.0)
        finally:
            late.close()
        assert text is not None
        scene = parse_scene(text, source="scene_description")
        q, _ = scene.model.initial_state()
        names = scene.model.joint_names
        assert q[names.index("left_base")] == pytest.approx(-0.6, abs=1e-12)
        # the others assembled so that the pin closes (assembly tolerance 1e-10 m)
        assert np.max(np.abs(closure_residual(scene.model, q))) < 1e-9
        reference = load_scene("five_bar").model
        assert scene.model.links == reference.links and scene.model.closures == reference.closures
    finally:
        reap(node)


def test_initial_positions_the_closures_cannot_meet_are_refused():
    cases = [
        (("initial_positions.crank_joint:=0.0", "initial_positions.rocker_joint:=0.3"),
         "initial_positions: expected joint values the closures can meet"),
        (("initial_positions.knee:=0.1",),
         "initial_positions.knee: expected a joint of four_bar (crank_joint, coupler_joint, "
         "rocker_joint), found 'knee'"),
    ]
    for params, message in cases:
        node = start_node("scene:=four_bar", "duration:=0.01", "realtime:=false", *params)
        code, out = reap(node, sig=None)
        assert code == 2 and message in out, out


def test_the_nodes_own_log_keeps_time_increasing_across_a_reset(tmp_path):
    from rosbags.highlevel import AnyReader

    mcap = tmp_path / "node.mcap"
    node = start_node("scene:=four_bar", "realtime:=false", "start_paused:=true",
                      f"mcap:={mcap}")
    probe = Probe()
    try:
        probe.listen("/joint_states", JointState)
        probe.listen("/vjm_sim_node/events", String)
        step = probe.node.create_client(Trigger, "/vjm_sim_node/step")
        reset = probe.node.create_client(Trigger, "/vjm_sim_node/reset")
        probe.spin()
        for client in (step, reset):
            assert client.wait_for_service(timeout_sec=60.0)

        def call(client):
            future = client.call_async(Trigger.Request())
            wait_for(future.done, what="a service answer")
            assert future.result().success, future.result().message

        for _ in range(3):
            call(step)
        call(reset)
        for _ in range(2):
            call(step)
        # the state at t = 0 is published when the node starts, maybe before this subscriber
        # is matched (volatile QoS): the live graph is sure to see the six that follow calls
        wait_for(lambda: len(probe.messages("/joint_states")) >= 6, what="six states")
    finally:
        probe.close()
        code, out = reap(node)
    assert code == 0, out
    live = [nanoseconds(m.header.stamp) for m in probe.messages("/joint_states")]
    with AnyReader([mcap]) as reader:
        counts = Counter(c.topic for c, _, _ in reader.messages())
        conns = [c for c in reader.connections if c.topic in ("/clock", "/joint_states")]
        clock, stamps = [], []
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/clock":
                clock.append(msg.clock.sec * 10**9 + msg.clock.nanosec)
            else:
                stamps.append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
    tick = 1_000_000
    # t = 0, three steps, the reset state one tick after the last, two steps
    assert stamps == [0, tick, 2 * tick, 3 * tick, 4 * tick, 5 * tick, 6 * tick]
    assert clock == stamps and live == stamps[-len(live):]  # the log and the live graph agree
    assert counts["/vjm_sim_node/events"] >= 1
