"""URDF models as scenes, against the same mechanisms written by hand.

* ``test/models/four_bar.urdf``: a four-bar lying on a table (x-y plane, axes +z) as a URDF tree
  closed by an SDFormat joint in ``<gazebo>``, its base welded to a ``world`` link, the crank
  driven through a ``<transmission>``; ``four_bar_xy.yaml`` is it by hand. The plane is
  horizontal, so gravity has no part in it; the import's basis is ``e1 = x``, ``e2 = y``.
* ``test/models/slider_crank.urdf`` (and ``slider_crank_gazebo.urdf``, closed by a prismatic
  ``<gazebo>`` joint instead): a slider-crank in the x-z plane (axes -y) whose block slides
  on a prismatic joint and is pinned to the rod by urdfdom's proposed ``<constraint>``, the crank
  driven through ``<ros2_control>``; ``slider_crank_xz.yaml`` is it by hand. ``N = -y`` gives
  ``e2 = z`` (against gravity) and ``e1 = x``: the hand-written plane itself.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from model_runs import MODELS, run

from vjm_ros.core.errors import SceneError
from vjm_ros.formats.importing import import_model
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

ROUND_OFF = 1e-10
"""rad or m: two runs of one mechanism in different link frames agree to round-off amplified
over 1000 rk4 ticks of a non-chaotic motion (1e-13 seen)."""


def test_gazebo_closed_four_bar_driven_through_its_transmission():
    imported, hand = load_scene(MODELS / "four_bar.urdf"), load_scene(MODELS / "four_bar_xy.yaml")
    assert imported.model.gravity.tolist() == [0.0, 0.0]  # the table's plane
    assert imported.model.actuator_names == ["crank_joint"]
    assert imported.model.actuators[0].limit == 10.0  # the joint's <limit effort>
    a, b = run(imported, 1.0, efforts=[0.5]), run(hand, 1.0, efforts=[0.5])
    zero = {"crank_joint": 0.0, "coupler_joint": math.pi / 3, "rocker_joint": -2 * math.pi / 3}
    for joint, q0 in zero.items():
        assert np.ptp(b["q"][joint]) > 0.1
        np.testing.assert_allclose(a["q"][joint], b["q"][joint] - q0, rtol=0, atol=ROUND_OFF)


def test_constraint_closed_slider_crank_under_gravity():
    imported = load_scene(MODELS / "slider_crank.urdf")
    hand = load_scene(MODELS / "slider_crank_xz.yaml")
    assert imported.model.actuator_names == ["crank_joint"]  # <ros2_control> effort interface
    a, b = run(imported, 1.0), run(hand, 1.0)
    theta, phi = hand.model.joints[0].angle, hand.model.joints[1].angle
    for joint, q0 in (("crank_joint", theta), ("rod_joint", phi), ("block_slide", 0.0)):
        assert np.ptp(b["q"][joint]) > 0.05
        np.testing.assert_allclose(a["q"][joint], b["q"][joint] - q0, rtol=0, atol=ROUND_OFF)


def test_prismatic_loop_joint_is_a_slider_and_an_angle_closure():
    """``slider_crank_gazebo.urdf``: the same slider-crank as one chain (crank, rod, block pinned
    to the rod) closed by a prismatic joint in ``<gazebo>``: a slider (the block's origin on the
    line along x) and an angle closure (the block does not turn). The block's pin turns by minus
    the rod's absolute turn."""
    imported = load_scene(MODELS / "slider_crank_gazebo.urdf")
    assert imported.model.closure_names == ["block_slide", "block_slide_angle"]
    hand = load_scene(MODELS / "slider_crank_xz.yaml")
    a, b = run(imported, 1.0), run(hand, 1.0)
    theta, phi = hand.model.joints[0].angle, hand.model.joints[1].angle
    crank, rod = b["q"]["crank_joint"] - theta, b["q"]["rod_joint"] - phi
    assert np.ptp(crank) > 0.5
    # The loop is cut elsewhere (a slide coordinate by hand, slider and angle rows here), so the
    # two runs differ by rk4's truncation error, not round-off: 3e-8 rad at 1 kHz, 2e-9 at
    # 2 kHz, 1.2e-10 at 4 kHz (fourth order); 1e-7 bounds it at 1 kHz.
    np.testing.assert_allclose(a["q"]["crank_joint"], crank, rtol=0, atol=1e-7)
    np.testing.assert_allclose(a["q"]["rod_joint"], rod, rtol=0, atol=1e-7)
    np.testing.assert_allclose(a["q"]["block_pin"], -(crank + rod), rtol=0, atol=1e-7)


def _urdf(joints: str) -> str:
    link = ('<link name="{n}"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" '
            'iyy="1" iyz="0" izz="1"/></inertial></link>\n')
    return ('<?xml version="1.0"?>\n<robot name="r">\n<link name="base"/>\n'
            + "".join(link.format(n=n) for n in ("a", "b")) + joints + "</robot>\n")


JA = ('<joint name="ja" type="revolute"><parent link="base"/><child link="a"/>'
      '<axis xyz="0 0 1"/><limit effort="1" lower="-1" upper="1" velocity="1"/></joint>\n')


@pytest.mark.parametrize("joints, where, why", [
    ('<joint name="ja" type="floating"><parent link="base"/><child link="a"/></joint>\n'
     '<joint name="jb" type="fixed"><parent link="a"/><child link="b"/></joint>\n',
     "joint 'ja'", "floating base"),
    (JA + '<joint name="jb" type="revolute"><parent link="a"/><child link="b"/>'
     '<origin xyz="1 0 0"/><axis xyz="0 0 1"/><mimic joint="ja"/>'
     '<limit effort="1" lower="-1" upper="1" velocity="1"/></joint>\n',
     "joint 'jb' <mimic>", "mimic"),
    (JA + '<joint name="jb" type="revolute"><parent link="a"/><child link="b"/>'
     '<origin xyz="1 0 0"/><axis xyz="0 0 -1"/>'
     '<limit effort="1" lower="-1" upper="1" velocity="1"/></joint>\n',
     "joint 'jb'", "opposite"),
    (JA + '<joint name="jb" type="revolute"><parent link="a"/><child link="b"/>'
     '<origin xyz="1 0 0"/><axis xyz="0 0 1"/>'
     '<limit effort="1" lower="-1" upper="1" velocity="1"/></joint>\n'
     '<gazebo><joint name="loop" type="ball"><parent>b</parent><child>base</child></joint>'
     "</gazebo>\n",
     "<gazebo> joint 'loop'", "loop joint"),
])
def test_what_the_planar_model_cannot_represent_is_refused_by_name(tmp_path, joints, where, why):
    path = tmp_path / "r.urdf"
    path.write_text(_urdf(joints))
    with pytest.raises(SceneError) as err:
        import_model(path)
    message = str(err.value)
    assert str(path) in message and where in message and why in message, message


def test_an_axis_opposite_to_the_others_moves_the_loop_closure_onto_it(tmp_path):
    """A revolute joint whose axis is -N cannot be a chain joint walked from parent to child
    (its coordinate would be minus the file's position); in a loop the chains go round it and
    it becomes the closure instead, so every coordinate left is still the file's position."""
    text = (MODELS / "four_bar.urdf").read_text()
    flipped = text.replace(
        '<origin xyz="0.8 0 0" rpy="0 0 -2.0943951023931953"/>\n    <axis xyz="0 0 1"/>',
        '<origin xyz="0.8 0 0" rpy="0 0 -2.0943951023931953"/>\n    <axis xyz="0 0 -1"/>')
    assert flipped != text
    path = tmp_path / "flipped.urdf"
    path.write_text(flipped)
    scene = load_scene(path)
    assert "rocker_joint" in scene.model.closure_names
    assert "ground_joint" in scene.model.joint_names
    a, b = run(scene, 0.5, efforts=[0.5]), run(load_scene(MODELS / "four_bar.urdf"), 0.5,
                                                    efforts=[0.5])
    for joint in ("crank_joint", "coupler_joint"):
        np.testing.assert_allclose(a["q"][joint], b["q"][joint], rtol=0, atol=ROUND_OFF)
    # the loop joint's position: the rocker's turn relative to the base, the sum of the others
    rocker = b["q"]["crank_joint"] + b["q"]["coupler_joint"] + b["q"]["rocker_joint"]
    assert np.ptp(rocker) > 0.1
    np.testing.assert_allclose(a["q"]["ground_joint"], rocker, rtol=0, atol=ROUND_OFF)


def test_a_pose_that_does_not_close_is_assembled(tmp_path):
    """The constraint's point on the rod written 0.2 mm off the block (as a rounded file would
    have it; an SDFormat or <gazebo> joint sits at one place and always closes): the loop does
    not close within the scene tolerance (1e-6 m), so the scene asks for assembly and says so;
    assembly closes it to its tolerance (1e-10) near the file's pose."""
    text = (MODELS / "slider_crank.urdf").read_text().replace(
        '<child_origin xyz="0.4 0 0" rpy="0 0 0"/>', '<child_origin xyz="0.4002 0 0" rpy="0 0 0"/>')
    assert text != (MODELS / "slider_crank.urdf").read_text()
    path = tmp_path / "rounded.urdf"
    path.write_text(text)
    imported = import_model(path)
    assert imported.document["assemble"] == {"fixed": []}
    assert "assembled" in imported.document["provenance"]
    assert imported.scene.assembly_residual <= 1e-10
    q0 = imported.scene.model.initial_state()[0]
    assert 0 < np.max(np.abs(q0)) < 0.01  # moved a little from the file's pose, rad or m


@pytest.mark.parametrize("name, basis", [
    ("four_bar.urdf", ((1, 0, 0), (0, 1, 0))),  # N = +z: e1 = x, e2 = y
    ("slider_crank.urdf", ((1, 0, 0), (0, 0, 1))),  # N = -y: e2 = z against gravity, e1 = x
])
def test_coordinates_are_the_files_joint_positions_for_yourdfpy(name, basis):
    """Along the imported scene's motion, the scene's joint coordinates given to yourdfpy (a
    maintained URDF library) as the file's joint positions place every link's frame where the
    scene's link starts (the joint in front of it): the same pose, 1e-12 m (round-off of two
    forward kinematics)."""
    import yourdfpy

    scene = load_scene(MODELS / name)
    urdf = yourdfpy.URDF.load(str(MODELS / name), load_meshes=False,
                              build_collision_scene_graph=False)
    sim = Simulator(scene.model, SimulationSettings(integrator="rk4", closure="exact"),
                    scene.gains, scene.plant)
    e = np.array(basis, dtype=float)
    start = None
    for tick in range(500):
        sim.advance(np.array([0.5]))
        if tick % 50:
            continue
        sample = sim.sample()
        q = dict(zip(scene.model.joint_names, sample.q, strict=True))
        start = q if start is None else start
        urdf.update_cfg({j: q[j] for j in urdf.actuated_joint_names})
        for i, link in enumerate(scene.model.links):
            world = urdf.get_transform(link.name, "world" if "world" in urdf.link_map
                                       else urdf.base_link)[:3, 3]
            np.testing.assert_allclose(e @ world, sample.segments[i][0], rtol=0, atol=1e-12)
    assert max(abs(q[j] - start[j]) for j in q) > 0.1  # it moved, rad or m
