"""The force of a joint's stop, reported like a closure force.

A joint with a ``range`` adds an entry ``<joint>_stop`` after the closures (``Model.force_names``)
to the samples, the CSV (``f.<joint>_stop.z`` or ``.x``/``.y``), the MCAP logs
(``constraint_forces`` and ``closures/<joint>_stop/wrench``), the rerun series and the node's
topics. Oracle: statics. A body at rest on its stop is held by it against gravity alone, so the
stop's effort is minus the gravity's generalized force: ``m g p cos(stop)`` for a rod hanging
on a pivot stop, ``-m (g . n) n`` for a block on a slide along ``n``. Away from the stop the
stop applies nothing.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from test_joint_friction import MGP, STOP
from test_joint_friction import ROD as rod_text
from test_rerun_recorder import columns

from vjm_ros.scene.loader import parse_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator

ROD = rod_text % ("0.0", f"range: [{STOP!r}, 3.0]") + (
    "defaults: {integrator: rk4, rate: 1000, duration: 1.5}\n")
"""The rod of test_joint_friction.py with a stop it falls onto at ~0.41 s (MGP, STOP there)."""
SLIDE_ANGLE = 2.0  # the slide runs along n(2 rad) = (-0.909, -0.416): gravity pushes it to hi
BLOCK = f"""\
name: block
chains:
  - name: guide
    angle: {SLIDE_ANGLE}
    links:
      - {{name: block, length: 0.2, mass: 2.0, com: [0.1, 0.0],
         joint: {{name: slide, type: prismatic, slide: 0.0, angle: 0.3, range: [-1.0, 0.3]}}}}
"""
TICKS = 1500


def _ticks_and_block(text: str):
    """The same run tick by tick (``Simulator.sample``) and as one compiled block."""
    model = parse_scene(text).model
    settings = SimulationSettings(integrator="rk4", rate=1000.0)
    a, b = Simulator(model, settings, {}), Simulator(model, settings, {})
    samples = []
    for _ in range(TICKS):
        a.advance()
        samples.append(a.sample())
    block = SampleBlock(model, TICKS)
    b.advance_block(block, TICKS)
    return model, samples, block


def test_a_rod_resting_on_its_stop_is_held_by_the_moment_gravity_asks():
    model, samples, block = _ticks_and_block(ROD)
    assert model.force_names == ["pivot_stop"] and model.force_is_moment == [True]
    q = np.array([s.q[0] for s in samples])
    force = np.array([s.closure_force[0] for s in samples])
    # Along the motion: both paths give the same numbers at every tick, the impact included.
    np.testing.assert_array_equal(block.force, force[:, None, :])
    np.testing.assert_array_equal(block.cpoints, np.zeros((TICKS, 1, 2)))  # the pivot
    assert np.all(force[:, :2] == 0.0)  # a revolute stop acts as a moment only
    # Falling, before it reaches the stop: the stop applies nothing.
    free = q > STOP + 0.05
    assert free[:300].all() and np.all(force[free, 2] == 0.0)
    # Resting (e = 0) on the stop from 0.5 s: statics, s = -Q_gravity = m g p cos(stop); the
    # effort is solved to round-off from the same accelerations (measured ~1e-15 N m).
    rest = slice(500, None)
    assert np.max(np.abs(q[rest] - STOP)) < 1e-9
    np.testing.assert_allclose(force[rest, 2], MGP * np.cos(STOP), rtol=1e-9)


def test_a_block_resting_on_a_slide_stop_is_pushed_back_along_the_slide():
    model, samples, block = _ticks_and_block(BLOCK)
    assert model.force_names == ["slide_stop"] and model.force_is_moment == [False]
    last = samples[-1]
    n = np.array([-np.sin(SLIDE_ANGLE), np.cos(SLIDE_ANGLE)])
    gravity = 2.0 * np.array([0.0, -9.81])
    assert last.q[0] == pytest.approx(0.3, abs=1e-9)  # on the upper stop
    # statics along the slide: the stop's force cancels gravity's component along n, and acts
    # at the joint, the block's origin B n(theta_pred) = 0.3 n (round-off: ~1e-15 N)
    np.testing.assert_allclose(last.closure_force[0], [*(-(gravity @ n) * n), 0.0], rtol=1e-9)
    np.testing.assert_allclose(last.closure_points[0], 0.3 * n, rtol=1e-12)
    np.testing.assert_array_equal(block.force[-1], last.closure_force)
    np.testing.assert_array_equal(block.cpoints[-1], last.closure_points)


def test_a_scene_without_ranges_reports_its_closures_only():
    model = parse_scene(ROD.replace(f", range: [{STOP!r}, 3.0]", "")).model
    assert model.force_names == [] and len(model.stop_joints) == 0
    assert SampleBlock(model, 2).force.shape == (2, 0, 3)


def _vjm(*args, cwd):
    out = subprocess.run([sys.executable, "-m", "vjm_ros.app.cli", *args], capture_output=True,
                         text=True, timeout=300, cwd=cwd,
                         env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"))
    assert out.returncode == 0, out.stderr
    return out


def test_vjm_run_writes_the_stop_force_in_the_csv_the_mcap_and_the_rrd(tmp_path):
    """Read back with rosbags and rerun's own reader: the same numbers as the CSV."""
    (tmp_path / "rod.yaml").write_text(ROD)
    _vjm("run", "rod.yaml", "--out", "out", "--mcap", "rod.mcap", "--rrd", "rod.rrd",
         cwd=tmp_path)
    with (tmp_path / "out" / "trajectory.csv").open() as f:
        rows = list(csv.DictReader(f))
    moment = np.array([float(r["f.pivot_stop.z"]) for r in rows])
    assert "f.pivot_stop.x" not in rows[0]
    assert moment[-1] == pytest.approx(MGP * np.cos(STOP), rel=1e-9)  # at rest (test above)
    node = "/vjm_sim_node"
    got: dict[str, list] = {f"{node}/constraint_forces": [], f"{node}/closures/pivot_stop/wrench": []}
    with AnyReader([tmp_path / "rod.mcap"]) as reader:
        conns = [c for c in reader.connections if c.topic in got]
        assert len(conns) == 2
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic.endswith("constraint_forces"):
                assert [(d.label, d.size) for d in msg.layout.dim] == [("pivot_stop", 3)]
                got[conn.topic].append(msg.data[2])
            else:
                assert msg.header.frame_id == "world"
                got[conn.topic].append(msg.wrench.torque.z)
    for values in got.values():
        np.testing.assert_array_equal(np.array(values), moment)  # the CSV's 17 digits: exact
    _, series = columns(tmp_path / "rod.rrd", "/series/constraint_forces", "Scalars:scalars")
    np.testing.assert_allclose(np.concatenate(series), moment, rtol=1e-15, atol=0)
    _vjm("replay", "rod.mcap", "-o", "replayed.rrd", cwd=tmp_path)  # stops read back by name
    _, replayed = columns(tmp_path / "replayed.rrd", "/series/constraint_forces",
                          "Scalars:scalars")
    np.testing.assert_allclose(np.concatenate(replayed), moment, rtol=1e-15, atol=0)


def test_a_closure_named_like_a_stop_is_refused_naming_the_key():
    from vjm_ros.core.errors import SceneError

    text = ROD + """closures:
  - {name: pivot_stop, type: hinge, point: {link: rod, at: tip}, target: {ground: [1.0, 0.0]}}
"""
    with pytest.raises(SceneError, match=r"closures\[0\]\.name") as info:
        parse_scene(text)
    assert "<joint>_stop" in str(info.value)
