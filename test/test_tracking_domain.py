"""The tracking study runs its simulator and controller on the environment's ``ROS_DOMAIN_ID``.

A user who sets ``ROS_DOMAIN_ID`` (to watch the run, or to keep it apart from other graphs on the
machine) gets the study on that domain; only without one does the study pick its own, and says
which on stderr.
"""

import os
import time

import pytest

from vjm_ros.studies import tracking

OWN = 110 + os.getpid() % 21
"""A domain for these tests, apart from the suite's per-process 1-101 (conftest.py)."""


def test_the_environment_domain_is_used(monkeypatch, capsys):
    monkeypatch.setenv("ROS_DOMAIN_ID", str(OWN))
    assert tracking.ros_domain() == OWN
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("unset", ["missing", ""])
def test_without_a_domain_the_study_picks_one_and_says_which(unset, monkeypatch, capsys):
    if unset == "missing":
        monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    else:
        monkeypatch.setenv("ROS_DOMAIN_ID", "")
    domain = tracking.ros_domain()
    assert 0 <= domain <= 101
    err = capsys.readouterr().err
    assert "ROS_DOMAIN_ID" in err and f"domain {domain}" in err, err


@pytest.mark.parametrize("value", ["robot", "-1", "233", "1.5"])
def test_a_bad_domain_is_refused_naming_the_variable(value, monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", value)
    with pytest.raises(ValueError, match=rf"ROS_DOMAIN_ID: expected .*found '{value}'"):
        tracking.ros_domain()


@pytest.mark.slow
@pytest.mark.ros
def test_a_run_publishes_on_the_environment_domain(monkeypatch):
    """A listener on the environment's domain hears the study's simulator (the run itself:
    simulator and controller processes, lockstep, 1.7 s so that the 1.5 s settling leaves some)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import JointState

    from vjm_ros.ros.runtime import Spinner

    monkeypatch.setenv("ROS_DOMAIN_ID", str(OWN))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=OWN, signal_handler_options=SignalHandlerOptions.NO)
    heard = []
    node = rclpy.create_node("tracking_listener", context=context)
    node.create_subscription(JointState, "/joint_states", heard.append,
                             QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = Spinner(executor).start()
    try:
        time.sleep(0.5)  # discovery of the listener before the run starts
        result = tracking.run_case("five_bar_circle", "lockstep", duration=1.7)
    finally:
        spinner.stop()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert result.states > 1000
    assert len(heard) > 100, f"heard {len(heard)} joint states on domain {OWN}"


def test_the_command_line_refuses_a_bad_domain(monkeypatch, capsys):
    monkeypatch.setenv("ROS_DOMAIN_ID", "robot")
    with pytest.raises(SystemExit) as info:
        tracking.main(["--cases", "five_bar_circle", "--modes", "lockstep"])
    assert info.value.code == 2
    assert "ROS_DOMAIN_ID: expected a whole number from 0 to 232, found 'robot'" in \
        capsys.readouterr().err
