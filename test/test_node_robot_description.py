"""The node's ``robot_description``: the running scene's URDF for robot_state_publisher.

The simulator runs as its own process (``python -m vjm_ros.ros.node``); a subscriber in a
private rclpy context joins late, with transient-local durability as robot_state_publisher's
clients do, and parses the URDF with yourdfpy. Its joints must be the ``joint_states`` names, and
its forward kinematics at the published positions the simulator's pose.
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
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from vjm_ros.core.readers import forward_kinematics  # noqa: E402
from vjm_ros.ros.runtime import Spinner  # noqa: E402
from vjm_ros.scene import load_scene  # noqa: E402

yourdfpy = pytest.importorskip("yourdfpy")

pytestmark = pytest.mark.ros

DOMAIN = int(os.environ["ROS_DOMAIN_ID"])
ROOT = Path(__file__).resolve().parents[1]
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""What robot_state_publisher offers and its clients ask for."""


def _listen(name, topic, kind, qos):
    """A node of its own context collecting ``topic``; returns (close, messages)."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(name, context=ctx)
    got, lock = [], threading.Lock()

    def store(msg):
        with lock:
            got.append(msg)

    node.create_subscription(kind, topic, store, qos)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    spinner = Spinner(executor).start()

    def close():
        spinner.stop()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)

    def messages():
        with lock:
            return list(got)

    return close, messages


def _wait(messages, timeout, what):
    """Poll until a message came; ``timeout`` is a hang guard (wall s), not a speed limit."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if messages():
            return messages()
        time.sleep(0.01)
    raise AssertionError(f"timed out waiting for {what}")


def test_robot_description_reaches_a_late_joiner_and_matches_joint_states():
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(DOMAIN),
               PYTHONPATH=str(ROOT))
    # held at its start state (republished every 0.1 s) until a command that never comes
    proc = subprocess.Popen(
        [sys.executable, "-m", "vjm_ros.ros.node", "--ros-args", "-p", "scene:=slider_crank",
         "-p", "wait_for_command:=true", "-p", "command_timeout:=0.0",
         "-p", "initial_positions.crank_joint:=1.2"],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    closers = []
    try:
        close, states = _listen("state_probe", "/joint_states", JointState,
                                QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        closers.append(close)
        state = _wait(states, 60.0, "joint_states")[-1]
        # the node has published its description by now (before its first state):
        # this subscriber joins after it and gets it from the publisher's history
        close, descriptions = _listen("late_joiner", "/robot_description", String, LATCHED)
        closers.append(close)
        text = _wait(descriptions, 30.0, "robot_description")[0].data
    finally:
        for close in closers:
            close()
        proc.send_signal(signal.SIGINT)
        try:
            proc.communicate(timeout=60)  # a hang guard
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    robot = yourdfpy.URDF.load(io.BytesIO(text.encode()), build_scene_graph=False,
                               load_meshes=False)
    assert robot.validate(), robot.errors
    assert robot.actuated_joint_names == list(state.name)
    # yourdfpy's frames at the published positions are the simulator's at its start state
    q = np.array(state.position)
    assert q[0] == pytest.approx(1.2, abs=1e-12)
    robot.update_cfg(q)
    kin = forward_kinematics(load_scene("slider_crank").model, q)
    poses = {"world": np.eye(4)}
    for joint in robot.robot.joints:  # parents come first in the export
        matrix, _ = robot._forward_kinematics_joint(joint, q=float(q[list(state.name).index(joint.name)]))
        poses[joint.child] = poses[joint.parent] @ matrix
    for i, link in enumerate(robot.robot.links[1:]):
        # 1e-12 m: the same transforms composed in another order (test_export_urdf.py)
        np.testing.assert_allclose(poses[link.name][:2, 3], kin.origin[i], rtol=0, atol=1e-12)
