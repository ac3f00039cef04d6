"""Refilled per-tick messages equal freshly built ones (rclpy message types, no node started).

Oracle: the conversion functions that build each message from scratch. Refilling must leave no
field of the previous tick behind, so the comparison runs over consecutive ticks of a real run
(three_chain: two closures, so two wrench messages refilled by index).
"""

from __future__ import annotations

import numpy as np

from vjm_ros.ros import conversions as conv
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator


def test_refilled_messages_equal_fresh_ones_tick_after_tick():
    scene = load_scene("three_chain")
    sim = Simulator(scene.model, SimulationSettings(), scene.gains)
    sim.set_efforts([a.effort for a in scene.model.actuators])
    model = scene.model
    messages = conv.TickMessages(model.joint_names, model.closure_names)
    forces_layout = conv.labelled_layout(model.closure_names, len(conv.FORCE_COMPONENTS))
    energy_layout = conv.labelled_layout(conv.ENERGY_LABELS, 1)
    for _ in range(5):
        sim.advance()
        s = sim.sample()
        t = s.t + 1e-4  # not a whole number of ticks: the nanoseconds must be refilled too
        assert messages.fill_joint_state(t, s.q, s.qd, s.effort) == conv.joint_state(
            model.joint_names, t, s.q, s.qd, s.effort)
        assert messages.fill_constraint_forces(s.closure_force) == conv.constraint_forces(
            forces_layout, s.closure_force)
        assert messages.fill_energy(s.energy) == conv.energy(energy_layout, s.energy)
        for i, force in enumerate(s.closure_force):
            assert messages.fill_wrench(i, force, t) == conv.wrench(force, t)
        assert messages.fill_clock(t) == conv.clock(t)
        assert np.asarray(messages.joint.position).tolist() == s.q.tolist()
