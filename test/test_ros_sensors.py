"""The node with a scene that has actuator dynamics and sensors, over real ROS 2.

``joint_states`` carries what the sensors measure and ``~/ground_truth/joint_states`` the exact
state at the same stamps; both equal, to the bit, the plain simulator run with the same commands
(the same seed, so the same noise), and the efforts are the applied ones (after gear, delay and
lag). The node runs in this process on this process's own ``ROS_DOMAIN_ID`` (``conftest.py``)
with a fresh context, as in ``test_ros_node.py``, whose harness starts and reaps it.
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from test_ros_node import NODE, Harness, stamps_ns  # noqa: E402
from waiting import wait_for  # noqa: E402

from vjm_ros.scene.loader import load_scene  # noqa: E402
from vjm_ros.sim.settings import SimulationSettings  # noqa: E402
from vjm_ros.sim.simulator import Simulator

pytestmark = pytest.mark.ros

TRUTH = f"{NODE}/ground_truth/joint_states"
SCENE = """\
name: sensed_pendulum
units: {angle: degrees}
chains:
  - name: arm
    links:
      - {name: rod, length: 1.0, mass: 1.0, inertia: 0.0833333333333333, com: [0.5, 0.0],
         joint: {name: pivot, type: revolute, angle: -30.0}}
actuators:
  - {joint: pivot, limit: 20.0, gear: 2.0, time_constant: 0.01, delay: 0.002}
sensors:
  joint_states:
    position: {noise: 0.05, resolution: 0.01}
    velocity: {noise: 0.5, bias: 0.2}
    effort: {noise: 0.1}
    delay: 0.001
    seed: 77
defaults: {integrator: rk4, rate: 1000, duration: 1}
"""


@pytest.fixture
def sensed(tmp_path):
    path = tmp_path / "sensed_pendulum.yaml"
    path.write_text(SCENE)
    made = []
    yield lambda **params: made.append(Harness(scene=str(path), **params)) or made[-1]
    for h in made:
        h.close()


def test_joint_states_are_measured_and_the_ground_truth_is_exact(sensed, tmp_path):
    """Live topics, and the node's MCAP log (rows collected tick by tick) read by rosbags."""
    from rosbags.highlevel import AnyReader

    log = tmp_path / "run.mcap"
    h = sensed(rate_hz=1000.0, lockstep=True, lockstep_timeout=10.0, command_timeout=0.0,
               realtime=False, duration=0.2, publish_clock=False, mcap=str(log))
    h.listen(TRUTH, JointState)
    h.on_joint_state(lambda msg: h.efforts.publish(Float64MultiArray(data=[3.0])))
    h.start()
    h.efforts.publish(Float64MultiArray(data=[3.0]))  # the answer to t = 0
    assert h.join() == 0
    assert h.node.loop.lockstep_timeouts == 0
    wait_for(lambda: len(h.messages("/joint_states")) >= 201, 10.0, "joint states")
    wait_for(lambda: len(h.messages(TRUTH)) >= 201, 10.0, "ground truth")
    measured, truth = h.messages("/joint_states")[:201], h.messages(TRUTH)[:201]
    assert stamps_ns(measured) == stamps_ns(truth) == [k * 1_000_000 for k in range(201)]
    assert truth[0].name == measured[0].name == ["pivot"]

    scene = load_scene(h.node.config.scene)
    ref = Simulator(scene.model, SimulationSettings(integrator="rk4", closure="penalty"),
                    scene.gains, scene.plant)
    states, readings = [(ref.q[0], ref.qd[0], ref.tau[0])], [ref.measured[:, 0].copy()]
    for _ in range(200):
        ref.advance([3.0])
        states.append((ref.q[0], ref.qd[0], ref.tau[0]))
        readings.append(ref.measured[:, 0].copy())
    got_truth = [(m.position[0], m.velocity[0], m.effort[0]) for m in truth]
    got_measured = [(m.position[0], m.velocity[0], m.effort[0]) for m in measured]
    assert np.array_equal(got_truth, states)
    assert np.array_equal(got_measured, readings)
    # the applied effort: zero through the 2-tick delay, then the lag's tick means up to 6
    effort = np.array([s[2] for s in got_truth])
    assert np.all(effort[:3] == 0.0) and 0.0 < effort[3] < effort[50] < 6.0
    assert not np.array_equal(np.array(got_measured)[:, 2], effort)  # noise on the effort

    h.node.close()  # the log finalized (again at teardown: idempotent)
    logged: dict[str, list] = {}
    with AnyReader([log]) as reader:
        for conn, _, raw in reader.messages():
            if conn.msgtype == "sensor_msgs/msg/JointState":
                m = reader.deserialize(raw, conn.msgtype)
                logged.setdefault(conn.topic, []).append(
                    (m.position[0], m.velocity[0], m.effort[0]))
    assert np.array_equal(logged["/joint_states"][:201], got_measured)
    assert np.array_equal(logged[TRUTH][:201], got_truth)


def test_a_scene_without_sensors_has_no_ground_truth_topic(harness_plain):
    assert "/vjm_sim_node/ground_truth/joint_states" not in {
        p.topic_name for p in harness_plain.node.publishers}


@pytest.fixture
def harness_plain():
    h = Harness(realtime=False, duration=0.01)
    yield h
    h.close()
