"""Serialized per-tick messages (ros/wire.py) read back as the messages built from scratch.

Oracle: rclpy's own deserializer applied to the refilled bytes, against the conversion functions
that build each message fresh (ros/conversions.py); no node is started (the node tests read the
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

from vjm_ros.ros import conversions as conv
from vjm_ros.ros.wire import TickWire
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator


@pytest.mark.parametrize("scene_name", ["three_chain", "four_bar", "pendulum"])
def test_refilled_bytes_read_back_as_fresh_messages_tick_after_tick(scene_name):
    scene = load_scene(scene_name)
    model = scene.model
    sim = Simulator(model, SimulationSettings(), scene.gains)
    if model.actuators:
        sim.set_efforts([a.effort for a in model.actuators])
    wire = TickWire(model.joint_names, model.closure_names)
    forces_layout = conv.labelled_layout(model.closure_names, len(conv.FORCE_COMPONENTS))
    energy_layout = conv.labelled_layout(conv.ENERGY_LABELS, 1)
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
