"""Serialized per-tick messages (ros/wire.py) read back as the messages built from scratch.

Oracle: rclpy's own deserializer applied to the refilled bytes, against the conversion functions
that build each message fresh (benchmarks/ros_messages.py); no node is started (the node tests read the
published topics with real rclpy subscribers). The comparison runs over consecutive ticks of a
real run, so a refill that left a field of the previous tick behind would show.
"""

from __future__ import annotations

import pytest
from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from benchmarks import ros_messages as conv
from vjm_ros.ros.conversions import TipTrace
from vjm_ros.ros.wire import TickWire
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator


def _running(scene_name: str):
    """A scene's model, its simulator (default efforts applied), a :class:`TickWire` and the
    rclpy layouts of the two ``Float64MultiArray`` messages."""
    scene = load_scene(scene_name)
    model = scene.model
    sim = Simulator(model, SimulationSettings(), scene.gains)
    if model.actuators:
        sim.set_efforts([a.effort for a in model.actuators])
    return (model, sim, TickWire(model.joint_names, model.closure_names),
            conv.labelled_layout(model.closure_names, len(conv.FORCE_COMPONENTS)),
            conv.labelled_layout(conv.ENERGY_LABELS, 1))


@pytest.mark.parametrize("scene_name", ["three_chain", "four_bar", "pendulum"])
def test_refilled_bytes_read_back_as_fresh_messages_tick_after_tick(scene_name):
    model, sim, wire, forces_layout, energy_layout = _running(scene_name)
    for _ in range(5):
        sim.advance()
        s = sim.sample()
        t = s.t + 1e-4  # not a whole number of ticks: the nanoseconds must be refilled too
        pairs = [
            (wire.joint_state(t, s.q, s.qd, s.effort),
             conv.joint_state(model.joint_names, t, s.q, s.qd, s.effort), JointState),
            (wire.constraint_forces(s.closure_force),
             conv.constraint_forces(forces_layout, s.closure_force), Float64MultiArray),
            (wire.energy_values(s.energy), conv.energy(energy_layout, s.energy),
             Float64MultiArray),
            (wire.clock_at(t), conv.clock(t), Clock),
        ]
        pairs += [(wire.wrench(i, force, t), conv.wrench(force, t), WrenchStamped)
                  for i, force in enumerate(s.closure_force)]
        for raw, fresh, kind in pairs:
            assert isinstance(raw, bytes)
            assert len(raw) == len(serialize_message(fresh))
            assert deserialize_message(raw, kind) == fresh, kind.__name__


def test_a_stamp_is_refilled_for_every_message_each_time():
    """The stamp of each message follows the last time given, whichever message set it."""
    wire = TickWire(["a", "b"], ["pin"])
    wire.joint_state(1.5, *([[0.0, 0.0]] * 3))
    force = [1.0, 2.0, 3.0]
    wire.wrench(0, force, 2.25)
    joint = deserialize_message(wire.joint_state(2.25, *([[0.0, 0.0]] * 3)), JointState)
    clock = deserialize_message(wire.clock_at(2.25), Clock)
    wrench = deserialize_message(wire.wrench(0, force, 2.25), WrenchStamped)
    for stamp in (joint.header.stamp, clock.clock, wrench.header.stamp):
        assert (stamp.sec, stamp.nanosec) == (2, 250_000_000)
    assert (wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.torque.z) == (1.0, 2.0, 3.0)


@pytest.mark.parametrize("scene_name", ["three_chain", "five_bar", "pendulum"])
def test_refilled_markers_read_back_as_fresh_markers(scene_name):
    """``~/markers`` refilled by :class:`~vjm_ros.ros.wire.MarkerWire` read back by rclpy as the
    MarkerArray built from scratch with rclpy's message classes (:func:`conv.markers`), over a
    run whose tip traces fill up and are cleared by a reset (time going back)."""
    from visualization_msgs.msg import MarkerArray

    from vjm_ros.ros.wire import MarkerWire

    scene = load_scene(scene_name)
    model = scene.model
    sim = Simulator(model, SimulationSettings(), scene.gains)
    if model.actuators:
        sim.set_efforts([a.effort for a in model.actuators])
    wire = MarkerWire()
    trace = TipTrace(len(model.chains), length=6, spacing=0.002)
    layouts = set()
    checked = 0
    for episode in range(2):
        sim.reset()
        for tick in range(25):
            sim.advance()
            s = sim.sample()
            trace.add(s)
            strips = trace.strips()
            t = s.t + 1e-4 * episode
            raw = wire.markers(s, t, strips)
            # the colors are float32 on the wire: the fresh message goes through rclpy's
            # serializer too, as publishing it would
            fresh = deserialize_message(serialize_message(conv.markers(s, t, strips)), MarkerArray)
            assert deserialize_message(raw, MarkerArray) == fresh, tick
            layouts.add(wire._key)
            checked += 1
    assert checked == 50
    # the traces keep one length: one layout for the whole run (two with no closure arrows
    # and no named points would be the same), so the template is written once
    assert len(layouts) == 1


def test_tip_trace_keeps_the_last_positions_oldest_first():
    """The ring of :class:`TipTrace`: the first position fills the strip, later ones push
    the oldest out, a reset (time going back) starts over."""
    import numpy as np

    class _S:
        def __init__(self, t, x):
            self.t, self.points = t, np.array([[x, -x]])

    trace = TipTrace(1, length=4, spacing=1.0)
    assert trace.strips()[0].shape == (0, 2)
    trace.add(_S(0.0, 1.0))
    np.testing.assert_array_equal(trace.strips()[0][:, 0], [1, 1, 1, 1])
    trace.add(_S(0.5, 9.0))  # less than spacing after the last kept one: skipped
    for t, x in ((1.0, 2.0), (2.0, 3.0), (3.0, 4.0), (4.0, 5.0)):
        trace.add(_S(t, x))
    np.testing.assert_array_equal(trace.strips()[0][:, 0], [2, 3, 4, 5])
    np.testing.assert_array_equal(trace.strips()[0][:, 1], [-2, -3, -4, -5])
    trace.add(_S(0.0, 7.0))  # a reset
    np.testing.assert_array_equal(trace.strips()[0][:, 0], [7, 7, 7, 7])


def _same_but_padding(ours: bytes, theirs: bytes) -> bool:
    """Equal length and equal bytes except in CDR padding: rclpy (Fast CDR) leaves its padding
    uninitialized, so a byte may differ only where ours is a zero pad, a run of fewer than 8 bytes
    that ends on a 4-aligned offset (counted from the end of the encapsulation header)."""
    if len(ours) != len(theirs):
        return False
    i = 0
    while i < len(ours):
        if ours[i] == theirs[i]:
            i += 1
            continue
        end = i + 1  # the differing run, then up to the next 4-aligned offset
        while end < len(ours) and (ours[end] != theirs[end] or (end - 4) % 4):
            end += 1
        if (end - 4) % 4 or end - i >= 8 or any(ours[i:end]):
            return False
        i = end
    return True


@pytest.mark.parametrize("scene_name", ["three_chain", "pendulum"])
def test_node_bytes_are_the_logs_bytes_rosbags_and_rclpy(scene_name):
    """The node's per-tick bytes come from the logs' layouts: along a run they equal the
    layouts' own encoding and rosbags' serializer byte for byte, and rclpy's ``serialize_message`` in every
    byte but padding (the one difference from rosbags: an empty ``Float64MultiArray.data``,
    which rclpy pads to 8 bytes)."""
    from rosbags_cdr import TYPESTORE, build  # the tests' own rosbags message builder

    from vjm_ros.logs import cdr, messages

    def rosbags(type_name, value):
        return bytes(TYPESTORE.serialize_cdr(build(type_name, value), type_name))

    model, sim, wire, forces_layout, energy_layout = _running(scene_name)
    for tick in range(5):
        sim.advance()
        s = sim.sample()
        t = s.t + 1e-4 + 4.3 * tick  # stamps past 2**32 ns too
        ns = messages.seconds_to_ns(t)
        logs = [
            (wire.joint_state(t, s.q, s.qd, s.effort),
             cdr.joint_state_layout(model.joint_names).encode(ns, s.q, s.qd, s.effort),
             rosbags(messages.JOINT_STATE, messages.joint_state(model.joint_names, s, ns)),
             conv.joint_state(model.joint_names, t, s.q, s.qd, s.effort)),
            (wire.energy_values(s.energy),
             cdr.multi_array_layout(messages.labelled_layout(messages.ENERGY_LABELS, 1), 4).encode(
                 0, s.energy),
             rosbags(messages.FLOAT64_MULTI_ARRAY, messages.energy(s)),
             conv.energy(energy_layout, s.energy)),
            (wire.clock_at(t), cdr.CLOCK_LAYOUT.encode(ns),
             rosbags(messages.CLOCK, messages.clock(ns)),
             conv.clock(t)),
        ]
        logs += [(wire.wrench(i, force, t), cdr.wrench_stamped_layout().encode(ns, force[:2],
                                                                               force[2:]),
                  rosbags(messages.WRENCH_STAMPED, messages.wrench(s, i, ns)),
                  conv.wrench(force, t)) for i, force in enumerate(s.closure_force)]
        for raw, log, theirs, fresh in logs:
            assert raw == log == theirs, type(fresh).__name__
            assert _same_but_padding(raw, serialize_message(fresh)), type(fresh).__name__
        raw = wire.constraint_forces(s.closure_force)
        theirs = rosbags(messages.FLOAT64_MULTI_ARRAY,
                         messages.constraint_forces(model.closure_names, s))
        assert raw == (theirs if len(model.closures) else theirs + bytes(4))
        assert _same_but_padding(
            raw, serialize_message(conv.constraint_forces(forces_layout, s.closure_force)))


def test_padding_check_tells_padding_from_data():
    """The helper above accepts differences in pad bytes only."""
    ours = bytes([0, 1, 0, 0, 5, 0, 0, 0, 9, 9, 9, 9])
    assert _same_but_padding(ours, ours[:5] + b"\x07\x08\x09" + ours[8:])
    assert not _same_but_padding(ours, ours[:4] + b"\x06" + ours[5:])  # a data byte
    assert not _same_but_padding(ours, ours[:8] + b"\x00" + ours[9:])  # a nonzero byte of ours
    assert not _same_but_padding(ours, ours[:-1])
