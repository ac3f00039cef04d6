"""External wrenches: the ROS-free buffer, the loads they make, and the node's
``~/external_wrench`` through a real rclpy publisher."""

from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import WrenchStamped
from std_msgs.msg import Float64MultiArray
from test_ros_node import harness, plain_simulator  # noqa: F401 (the fixture)
from waiting import wait_for

from vjm_ros.core.model import Load
from vjm_ros.realtime.wrenches import WrenchBuffer
from vjm_ros.scene.loader import load_scene

NODE = "/vjm_sim_node"


class FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def test_buffer_takes_replaces_times_out_and_refuses():
    points = load_scene("five_bar").model.points
    clock = FakeClock()
    buf = WrenchBuffer(points, timeout=0.5, clock=clock)
    assert buf.latch() is None  # nothing yet, nothing changed
    assert buf.submit("left_tip", (1.0, 2.0), 0.5) is None
    (load,) = buf.latch()
    assert load.point == next(p.ref for p in points if p.name == "left_tip")
    assert load.force == (1.0, 2.0) and load.torque == 0.5
    assert buf.latch() is None  # unchanged since
    clock.now = 0.3
    buf.submit("left_tip", (3.0, 0.0), 0.0)  # replaces the one at the same point
    assert [ld.force for ld in buf.latch()] == [(3.0, 0.0)]
    clock.now = 0.7  # 0.4 s after the last one: kept
    assert buf.latch() is None
    clock.now = 0.81  # 0.51 s: dropped
    assert buf.latch() == ()
    why = buf.submit("elbow", (1.0, 0.0), 0.0)
    assert "header.frame_id" in why and "left_tip" in why and "'elbow'" in why
    assert "finite" in buf.submit("left_tip", (float("nan"), 0.0), 0.0)
    assert (buf.accepted, buf.refused) == (2, 2)
    buf.submit("left_tip", (1.0, 0.0), 0.0)
    buf.clear()
    assert buf.latch() == ()


def test_loads_set_on_a_simulator_act_from_its_next_tick():
    """A wrench at the tip equals the same load written in the scene: the packed loads are the
    scene's plus the external ones."""
    sim, ref = plain_simulator("four_bar"), plain_simulator("four_bar")
    tip = next(p.ref for p in sim.model.points if p.name == "chain1_tip")
    push = Load("push", tip, (4.0, -2.0), 0.3)
    sim.set_external_loads((push,))
    text = load_scene("four_bar").text + (
        "loads:\n  - {name: push, point: {link: rocker, at: tip}, force: [4.0, -2.0], "
        "torque: 0.3}\n")
    from vjm_ros.scene.loader import parse_scene

    written = parse_scene(text)
    ref.mechanism = type(ref.mechanism)(written.model, ref.method)
    for _ in range(50):
        sim.advance()
        ref.advance()
    np.testing.assert_array_equal(sim.q, ref.q)  # the same arrays reach the kernel
    sim.set_external_loads(())
    assert sim.mechanism.packed.par[6] == 0.0  # four_bar alone has no plant terms


def test_node_applies_a_wrench_from_the_next_tick(harness):  # noqa: F811
    h = harness(rate_hz=1000.0, lockstep=True, lockstep_timeout=10.0, command_timeout=0.0,
                realtime=False, duration=0.2)
    pub = h.probe.create_publisher(WrenchStamped, f"{NODE}/external_wrench", 10)
    wait_for(lambda: pub.get_subscription_count() > 0, what="the wrench subscription")
    msg = WrenchStamped()
    msg.header.frame_id = "chain1_tip"
    msg.wrench.force.x, msg.wrench.force.y, msg.wrench.torque.z = 4.0, -2.0, 0.3
    h.on_joint_state(lambda m: h.efforts.publish(Float64MultiArray(data=[0.0])))
    h.start()  # lockstep: the first tick waits for the first command
    pub.publish(msg)
    wait_for(lambda: h.node.loop.wrenches.accepted == 1, what="the wrench")
    h.efforts.publish(Float64MultiArray(data=[0.0]))
    assert h.join() == 0
    wait_for(lambda: len(h.messages("/joint_states")) >= 201, 10.0, "joint states")
    js = h.messages("/joint_states")[:201]
    ref = plain_simulator("four_bar")
    tip = next(p.ref for p in ref.model.points if p.name == "chain1_tip")
    ref.set_external_loads((Load("push", tip, (4.0, -2.0), 0.3),))
    q = [ref.q.copy()]
    for _ in range(200):
        ref.advance([0.0])
        q.append(ref.q.copy())
    # the node ticks in compiled blocks of one tick, the reference tick by tick: the same
    # numbers to round-off (test_ros_node's lockstep test holds 1e-9 the same way)
    assert np.max(np.abs(np.array([m.position for m in js]) - q)) <= 1e-9
    free = plain_simulator("four_bar")
    for _ in range(200):
        free.advance([0.0])
    assert np.max(np.abs(free.q - q[-1])) > 1e-3  # the wrench made a difference


@pytest.mark.parametrize("frame", ["nowhere", ""])
def test_node_refuses_a_wrench_at_an_unknown_point(harness, frame):  # noqa: F811
    h = harness(rate_hz=1000.0, realtime=False, duration=0.05)
    pub = h.probe.create_publisher(WrenchStamped, f"{NODE}/external_wrench", 10)
    wait_for(lambda: pub.get_subscription_count() > 0, what="the wrench subscription")
    msg = WrenchStamped()
    msg.header.frame_id = frame
    msg.wrench.force.x = 1.0
    h.start()
    pub.publish(msg)
    wait_for(lambda: h.node.loop.wrenches.refused == 1, what="the refusal")
    assert h.node.loop.wrenches.accepted == 0


def test_node_drops_a_wrench_after_command_timeout(harness):  # noqa: F811
    """A realtime node at 200 Hz with ``command_timeout`` 0.3 s gets one wrench: it pushes for a
    span of ticks, then the node drops it and never applies it again.

    Oracle: each published tick replayed from the state published one tick before, once with the
    wrench and once without, by a simulator of the node's scene and settings; the node's tick
    matches exactly one of the two. The replay and the node compute the same tick in the same
    compiled code, so a match is within round-off (1e-9 rad, as the lockstep tests hold it); the
    20 N push moves the tip by some 2.5e-4 m in one 5 ms tick, so the other replay misses by far
    more than that."""
    from vjm_ros.sim.simulator import Simulator

    h = harness(rate_hz=200.0, realtime=True, command_timeout=0.3, duration=1.5)
    pub = h.probe.create_publisher(WrenchStamped, f"{NODE}/external_wrench", 10)
    wait_for(lambda: pub.get_subscription_count() > 0, what="the wrench subscription")
    msg = WrenchStamped()
    msg.header.frame_id = "chain1_tip"
    msg.wrench.force.y = -20.0
    h.start()
    wait_for(lambda: len(h.messages("/joint_states")) > 20, 10.0, "joint states")
    pub.publish(msg)
    assert h.join() == 0
    assert h.node.loop.wrenches.accepted == 1
    js = h.messages("/joint_states")
    assert len(js) == 301  # 1.5 s at 200 Hz and the first state
    node_sim = h.node.loop.sim
    tip = next(p.ref for p in node_sim.model.points if p.name == "chain1_tip")
    push = (Load("external_wrench.chain1_tip", tip, (0.0, -20.0), 0.0),)
    replay = Simulator(node_sim.model, node_sim.settings, node_sim.scene_gains, node_sim.plant)
    pushed = []
    for before, after in zip(js, js[1:], strict=False):
        errors = []
        for loads in ((), push):
            replay.q = np.array(before.position)
            replay.qd = np.array(before.velocity)
            replay.tau = np.array(after.effort)  # the joints' applied efforts, N m
            replay.set_external_loads(loads)
            replay.advance()
            errors.append(max(np.max(np.abs(replay.q - after.position)),
                              np.max(np.abs(replay.qd - after.velocity))))
        assert min(errors) <= 1e-9 < 1e-6 <= max(errors), errors
        pushed.append(errors[1] < errors[0])
    ticks = np.flatnonzero(pushed)
    assert ticks.size, "the wrench never acted"
    # one span, then never again: the drop reached the simulator
    assert np.array_equal(ticks, np.arange(ticks[0], ticks[-1] + 1))
    assert ticks[-1] + 1 < len(pushed)
    # held for about command_timeout of wall time: paced ticks never run ahead of the wall clock,
    # so the span stays near or below 0.3 s of simulated time (0.6 s allows a catch-up after a
    # stall, as the command timeout test allows)
    assert 0.0 < (ticks[-1] + 1 - ticks[0]) * 0.005 <= 0.6
