"""A ``rate_hz`` changed at run time takes effect at the next reset; a log being recorded keeps
its times equal to the node's stamps across it.

The node runs in this process on its own ``ROS_DOMAIN_ID`` (``conftest.py``) with the harness of
``test_ros_node.py``, paused and stepped tick by tick through its services; the MCAP log is read
back with rosbags.
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))

import pytest  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from test_ros_node import NODE, Harness  # noqa: E402

pytestmark = pytest.mark.ros


def test_log_times_stay_the_stamps_when_a_reset_changes_the_rate(tmp_path):
    log = tmp_path / "run.mcap"
    h = Harness(start_paused=True, rate_hz=1000.0, mcap=str(log))
    try:
        h.start()
        step = Trigger.Request()
        for _ in range(3):
            assert h.call(Trigger, f"{NODE}/step", step).success
        request = SetParameters.Request(
            parameters=[Parameter("rate_hz", value=250.0).to_parameter_msg()])
        assert h.call(SetParameters, f"{NODE}/set_parameters", request).results[0].successful
        assert h.call(Trigger, f"{NODE}/reset", step).success
        for _ in range(3):
            assert h.call(Trigger, f"{NODE}/step", step).success
    finally:
        h.close()  # the log is finalized here
    stamps = []
    with AnyReader([log]) as reader:
        conns = [c for c in reader.connections if c.topic == "/joint_states"]
        for conn, log_ns, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            stamps.append((log_ns, stamp))
    assert [log_ns for log_ns, _ in stamps] == [stamp for _, stamp in stamps]
    # t = 0 and three 1 ms ticks; the new episode one new (4 ms) tick later, then 4 ms ticks
    ms = 1_000_000
    assert [stamp for _, stamp in stamps] == [0, ms, 2 * ms, 3 * ms, 7 * ms, 11 * ms, 15 * ms,
                                              19 * ms]
