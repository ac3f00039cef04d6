"""The URDF export against yourdfpy, a URDF library we did not write.

yourdfpy parses the exported text and computes the forward kinematics of its joint tree; at the
simulator's joint coordinates along a motion, the frame it gives every link must be the link
frame the simulator reports (origin ``O_i`` and angle ``theta_i``, docs/design.md section 1).
"""

from __future__ import annotations

import io
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from vjm_ros.core.model import GROUND, HINGE, SLIDER
from vjm_ros.core.readers import forward_kinematics
from vjm_ros.formats.urdf_out import ROOT_LINK, scene_urdf
from vjm_ros.scene.loader import builtin_scenes, load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

yourdfpy = pytest.importorskip("yourdfpy")

KINDS = str(Path(__file__).with_name("export_closure_kinds.yaml"))
"""A scene with every closure kind and joint placement the built-in scenes lack: a slider on a
moving link's line, an angle closure between two links, a revolute joint with a locked slide,
a prismatic joint with a locked angle after a revolute one."""
SCENES = [*builtin_scenes(), KINDS]
TICKS = 200
"""States compared per scene: 0.2 s at 1 kHz, every tick."""
FRAME_TOLERANCE = 1e-12
"""m and rad. Both sides compose the same rigid transforms (at most five per link here) from
the same doubles, in a different order (yourdfpy with 4x4 matrices from rpy and axis-angle,
the kernel with angle sums and cos/sin): round-off of a few 1e-16 per step on lengths of about
1 m, so 1e-12 leaves a wide margin and still catches any wrong offset, sign or axis."""


def _load(text: str):
    return yourdfpy.URDF.load(io.BytesIO(text.encode("utf-8")), build_scene_graph=False,
                              load_meshes=False, build_collision_scene_graph=False)


def _motion(scene, ticks=TICKS):
    """Joint coordinates and link frames of a run (exact closure, so the closures hold)."""
    settings = SimulationSettings(integrator="rk4", closure="exact", rate=1000.0)
    sim = Simulator(scene.model, settings, scene.gains)
    if scene.model.actuators:
        sim.set_efforts(np.array([min(2.0, a.limit) for a in scene.model.actuators]))
    q, theta, origin = [], [], []
    for _ in range(ticks):
        sim.advance()
        s = sim.sample()
        q.append(s.q.copy())
        theta.append(s.theta.copy())
        origin.append(s.segments[:, 0].copy())
    return np.array(q), np.array(theta), np.array(origin)


def _transforms(robot) -> dict[str, np.ndarray]:
    """Pose of every link in the root frame (4 x 4), from yourdfpy's joint transforms.

    Composed here from ``_forward_kinematics_joint`` (yourdfpy's reading of each joint's origin,
    type and axis at the configuration set by ``update_cfg``) rather than read with
    ``get_transform``: trimesh's scene graph behind it takes a transform within 1e-8 of the
    identity for the identity, which drops slides of a few 1e-11 m (double_slider's first ticks).
    """
    poses = {ROOT_LINK: np.eye(4)}
    pending = list(robot.robot.joints)
    while pending:
        joint = next(j for j in pending if j.parent in poses)
        pending.remove(joint)
        value = None
        if joint.type in ("revolute", "continuous", "prismatic"):
            value = float(robot.cfg[robot.actuated_joint_names.index(joint.name)])
        matrix, _ = robot._forward_kinematics_joint(joint, q=value)
        poses[joint.child] = poses[joint.parent] @ matrix
    return poses


def _frames(robot, names):
    """Origin (x, y), yaw, z and z-axis z-component of each named link, from yourdfpy."""
    poses = _transforms(robot)
    return np.array([(t[0, 3], t[1, 3], math.atan2(t[1, 0], t[0, 0]), t[2, 3], t[2, 2])
                     for t in (poses[name] for name in names)])


def _cross(a, b) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _wrapped(a):
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi


@pytest.mark.parametrize("spec", SCENES, ids=lambda s: Path(s).stem)
def test_urdf_forward_kinematics_follows_the_simulator(spec):
    """yourdfpy's link frames at the simulator's coordinates are the simulator's link frames,
    for every tick of a 0.2 s run: URDF joint positions are the scene's joint coordinates."""
    scene = load_scene(spec)
    model = scene.model
    robot = _load(scene_urdf(model))
    assert robot.actuated_joint_names == model.joint_names
    q, theta, origin = _motion(scene)
    # the run must move every joint, or a wrong axis or offset could go unseen
    assert np.all(np.ptp(q, axis=0) > 1e-3), np.ptp(q, axis=0)
    frames = []
    for k in range(len(q)):
        robot.update_cfg(q[k])
        frames.append(_frames(robot, model.link_names))
    f = np.array(frames)
    np.testing.assert_allclose(f[..., :2], origin, rtol=0, atol=FRAME_TOLERANCE)
    np.testing.assert_allclose(_wrapped(f[..., 2] - theta), 0.0, rtol=0, atol=FRAME_TOLERANCE)
    # frames stay in the plane: z = 0, z axis along z
    np.testing.assert_allclose(f[..., 3], 0.0, rtol=0, atol=FRAME_TOLERANCE)
    np.testing.assert_allclose(f[..., 4], 1.0, rtol=0, atol=FRAME_TOLERANCE)


@pytest.mark.parametrize("spec", SCENES, ids=lambda s: Path(s).stem)
def test_urdf_zero_at_the_initial_state(spec):
    """``zero="initial"``: yourdfpy's zero pose is the scene's initial state, and position
    ``q - q0`` gives the frames of ``q`` (the file Gazebo should load)."""
    model = load_scene(spec).model
    robot = _load(scene_urdf(model, zero="initial"))
    q0, _ = model.initial_state()
    rng = np.random.default_rng(7)
    for q in (q0, q0 + rng.normal(scale=0.5, size=model.n)):
        robot.update_cfg(q - q0)
        kin = forward_kinematics(model, q)
        f = _frames(robot, model.link_names)
        np.testing.assert_allclose(f[:, :2], kin.origin[: model.n], rtol=0, atol=FRAME_TOLERANCE)
        np.testing.assert_allclose(_wrapped(f[:, 2] - kin.theta[: model.n]), 0.0, rtol=0,
                                   atol=FRAME_TOLERANCE)


@pytest.mark.parametrize("spec", SCENES, ids=lambda s: Path(s).stem)
def test_urdf_is_a_valid_tree(spec):
    """What urdfdom's check_urdf checks, through yourdfpy: required attributes and limits
    (``validate``), one root, every joint's links declared, each link the child of one joint;
    and the scene's names, masses, mass centres and inertias."""
    model = load_scene(spec).model
    for zero in ("coordinates", "initial"):
        # well-formed XML for a strict parser (yourdfpy's lxml recovers from some errors)
        ET.fromstring(scene_urdf(model, zero))
    robot = _load(scene_urdf(model))
    assert robot.validate(), robot.errors
    links = {lk.name for lk in robot.robot.links}
    assert links == {ROOT_LINK, *model.link_names}
    children = [j.child for j in robot.robot.joints]
    assert sorted(children) == sorted(model.link_names), "each link the child of one joint"
    assert all(j.parent in links for j in robot.robot.joints)
    assert links - set(children) == {ROOT_LINK}, "one root"
    for lk, joint in zip(model.links, model.joints, strict=True):
        j = robot.joint_map[joint.name]
        assert j.child == lk.name
        assert j.type == ("continuous" if joint.kind == "revolute" else "prismatic")
        inertial = robot.link_map[lk.name].inertial
        if lk.mass == 0.0:
            assert inertial is None
            continue
        assert inertial.mass == lk.mass
        np.testing.assert_array_equal(inertial.origin[:2, 3], lk.com)
        i = inertial.inertia
        assert i[2, 2] == lk.inertia and i[0, 0] == i[1, 1] == lk.inertia / 2
        # a physical inertia tensor: principal moments obey the triangle inequality
        assert i[0, 0] + i[1, 1] >= i[2, 2]


def _gazebo_joints(text):
    root = ET.fromstring(text)
    gz = root.find("gazebo")
    joints = {j.get("name"): j for j in gz.findall("joint")}
    carriages = {lk.get("name"): lk for lk in gz.findall("link")}
    return joints, carriages


def _pose(el):
    x, y, z, r, p, yaw = (float(v) for v in el.find("pose").text.split())
    assert z == r == p == 0.0
    return np.array([x, y]), yaw


@pytest.mark.parametrize("spec", SCENES, ids=lambda s: Path(s).stem)
def test_gazebo_closures_hold_at_the_pose_gazebo_loads(spec):
    """Gazebo builds a closure joint where its frame is at the loaded pose (the URDF's zero
    pose): in the ``zero="initial"`` file, yourdfpy's frames there put each hinge's joint (a
    pose in the child's frame) on its target, each slider's carriage on its line with its
    slide along the line, and keep each angle closure's relative angle."""
    model = load_scene(spec).model
    text = scene_urdf(model, zero="initial")
    robot = _load(text)
    robot.update_cfg(np.zeros(model.n))
    joints, carriages = _gazebo_joints(text) if model.closures else ({}, {})

    poses = _transforms(robot)

    def frame(name):
        t = poses[name]
        return t[:2, 3], t[:2, :2], math.atan2(t[1, 0], t[0, 0])

    def world(link, local):
        if link == GROUND:
            return np.asarray(local, float)
        o, r, _ = frame(model.links[link].name)
        return o + r @ np.asarray(local, float)

    for cl in model.closures:
        j = joints[cl.name]
        child = j.find("child").text
        assert child == model.links[cl.point.link].name
        local, _ = _pose(j)
        o, r, yaw = frame(child)
        at = o + r @ local
        if cl.kind == HINGE:
            assert j.get("type") == "revolute"
            parent = j.find("parent").text
            assert parent == (ROOT_LINK if cl.target.link == GROUND
                              else model.links[cl.target.link].name)
            np.testing.assert_allclose(at, world(cl.target.link, cl.target.local), atol=1e-12)
        elif cl.kind == SLIDER:
            carriage = carriages[f"{cl.name}_carriage"]
            c_at, c_yaw = _pose(carriage)
            np.testing.assert_allclose(at, c_at, atol=1e-12)
            p0 = world(cl.target.link, cl.target.local)
            d = np.asarray(cl.direction, float)
            if cl.target.link != GROUND:
                d = frame(model.links[cl.target.link].name)[1] @ d
            # the carriage sits on the line and slides (its x axis) along it
            assert abs(_cross(d, c_at - p0)) < 1e-12
            assert abs(_cross(d, [math.cos(c_yaw), math.sin(c_yaw)])) < 1e-12
            assert joints[f"{cl.name}_slide"].find("axis/xyz").text.split() == ["1.0", "0", "0"]
        else:
            ref = 0.0 if cl.target.link == GROUND else frame(model.links[cl.target.link].name)[2]
            assert abs(_wrapped(yaw - ref - cl.offset)) < 1e-12
            assert j.get("type") == "prismatic" and joints[f"{cl.name}_x"].get("type") == "prismatic"


def test_ros2_control_holds_actuators_and_initial_state():
    """Effort command interfaces on the actuated joints with their limits; every joint's
    initial position and velocity as ``initial_value``."""
    model = load_scene(KINDS).model
    root = ET.fromstring(scene_urdf(model))
    q0, qd0 = model.initial_state()
    rc = root.find("ros2_control")
    for i, joint in enumerate(model.joints):
        el = rc.find(f"joint[@name='{joint.name}']")
        state = {s.get("name"): s for s in el.findall("state_interface")}
        assert float(state["position"].find("param").text) == q0[i]
        assert float(state["velocity"].find("param").text) == qd0[i]
        cmd = el.find("command_interface[@name='effort']")
        limit = {a.joint: a.limit for a in model.actuators}.get(i)
        if limit is None:
            assert cmd is None
        else:
            params = {p.get("name"): float(p.text) for p in cmd.findall("param")}
            assert params == {"min": -limit, "max": limit}


def test_refuses_a_link_named_like_the_root():
    text = Path(KINDS).read_text().replace("name: boom,", "name: world,")
    from vjm_ros.scene.loader import parse_scene

    with pytest.raises(ValueError, match="link 'world'"):
        scene_urdf(parse_scene(text).model)
    clash = Path(KINDS).read_text().replace("name: boom_joint,", "name: slot_slide,")
    with pytest.raises(ValueError, match="joint 'slot_slide' clashes with the SDFormat joint"):
        scene_urdf(parse_scene(clash).model)
    with pytest.raises(ValueError, match="zero pose"):
        scene_urdf(load_scene("four_bar").model, zero="home")


def test_effort_bounds_are_the_joints(tmp_path):
    """With a gear of 3 the joint's effort bound is 3 x the command's limit (URDF efforts are
    joint efforts), in ``<limit effort>`` and in the ros2_control command interface."""
    path = tmp_path / "geared.yaml"
    path.write_text(Path(KINDS).read_text().replace(
        "{joint: crank_joint, limit: 20.0}", "{joint: crank_joint, limit: 20.0, gear: 3.0}"))
    scene = load_scene(str(path))
    root = ET.fromstring(scene_urdf(scene.model, plant=scene.plant))
    assert float(root.find("joint[@name='crank_joint']/limit").get("effort")) == 60.0
    assert float(root.find("joint[@name='lever_joint']/limit").get("effort")) == 0.0
    cmd = root.find("ros2_control/joint[@name='crank_joint']/command_interface")
    assert [float(p.text) for p in cmd.findall("param")] == [-60.0, 60.0]
