"""MJCF models as scenes, against MuJoCo itself and against the same mechanism written by hand.

``test/models/five_bar.xml`` is a five-bar in the x-z plane as MuJoCo users write one: capsule
geoms give the masses and inertias, hinge axes along +y, a ``connect`` equality joins the legs'
tips, motors with gear 2 drive the bases, and the right elbow has ``ref="20"`` (degrees), so its
``qpos`` is 20 deg at the pose the file writes. The import's coordinates are MuJoCo's ``qpos``.
``five_bar_xz.yaml`` is the mechanism by hand (angles counter-clockwise seen with z up, i.e.
about -y; masses and inertias from the capsule formula in its description).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from model_runs import MODELS, run

from vjm_ros.core.errors import SceneError
from vjm_ros.formats.importing import import_model
from vjm_ros.scene.loader import load_scene

mujoco = pytest.importorskip("mujoco")

JOINTS = ["left_base", "left_elbow", "right_base", "right_elbow"]
CONTROLS = [0.3, -0.2]
"""Constant motor controls (command units; joint torque = 2 x control), N m."""


@pytest.fixture(scope="module")
def imported():
    return run(load_scene(MODELS / "five_bar.xml"), 1.0, efforts=CONTROLS)


def mujoco_qpos(path, seconds: float = 1.0) -> np.ndarray:
    """MuJoCo's ``qpos`` at every 1 ms over ``seconds``, the file run at tight settings: RK4 at
    0.1 ms and equality constraints stiff (solref 2 ms, solimp 0.99999), shape (ticks, nq)."""
    m = mujoco.MjModel.from_xml_path(str(path))
    m.opt.timestep = 1e-4
    m.eq_solref[:] = [2e-3, 1.0]
    m.eq_solimp[:] = [0.99999, 0.99999, 0.001, 0.5, 2]
    d = mujoco.MjData(m)
    if m.nkey:  # the file's start, as the import takes it
        mujoco.mj_resetDataKeyframe(m, d, 0)
    d.ctrl[:] = CONTROLS
    qpos = []
    for _ in range(int(round(seconds * 1000))):
        for _ in range(10):
            mujoco.mj_step(m, d)
        qpos.append(d.qpos.copy())
    return np.array(qpos)


def test_coordinates_are_mujocos_qpos_along_a_driven_motion(imported):
    """MuJoCo's soft constraint is the difference left: halving its time constants and step
    took the gap from 6e-7 to 2e-7 rad; 2e-6 rad bounds it over 1 s of motion spanning more
    than 3 rad per joint."""
    qpos = mujoco_qpos(MODELS / "five_bar.xml")
    m = mujoco.MjModel.from_xml_path(str(MODELS / "five_bar.xml"))
    assert math.isclose(m.qpos0[3], math.radians(20.0))
    assert imported["q"]["right_elbow"][0] == pytest.approx(math.radians(20.0), abs=0.05)
    for k, joint in enumerate(JOINTS):
        assert np.ptp(qpos[:, k]) > 2.0
        np.testing.assert_allclose(imported["q"][joint], qpos[:, k], rtol=0, atol=2e-6)


@pytest.mark.parametrize("variant, closures", [
    ("sites", ["pin_joint"]),
    ("weld", ["pin_joint", "pin_joint_angle"]),
    ("losses", ["pin_joint"]),
])
def test_site_connect_weld_and_joint_losses_follow_mujoco(tmp_path, variant, closures):
    """The pin written between two sites, or as a weld (which also locks the distal links'
    relative angle: a four-bar whose coupler is the two distal links), or every joint with
    damping and armature (the scene's joint keys of the same meaning), against MuJoCo as above
    (2e-6 rad)."""
    text = (MODELS / "five_bar.xml").read_text()
    if variant == "losses":
        text = text.replace('<joint type="hinge" axis="0 1 0"/>',
                            '<joint type="hinge" axis="0 1 0" damping="0.05" armature="0.002"/>')
        scene_joints = import_model_text(tmp_path, text)["chains"][0]["links"]
        assert [lk["joint"]["damping"] for lk in scene_joints] == [0.05, 0.05]
        assert [lk["joint"]["armature"] for lk in scene_joints] == [0.002, 0.002]
    elif variant == "sites":
        text = text.replace('<geom fromto="0 0 0 0.5 0 0"/>\n      </body>',
                            '<geom fromto="0 0 0 0.5 0 0"/>\n        '
                            '<site name="pin_r" pos="0.5 0 0"/>\n      </body>')
        text = text.replace('body1="left_distal" body2="right_distal" anchor="0.5 0 0"',
                            'site1="pin" site2="pin_r"')
    else:
        text = text.replace('<connect name="pin_joint" body1="left_distal" body2="right_distal" '
                            'anchor="0.5 0 0"/>',
                            '<weld name="pin_joint" body1="left_distal" body2="right_distal"/>')
    path = tmp_path / "five_bar.xml"
    path.write_text(text)
    assert text != (MODELS / "five_bar.xml").read_text()
    scene = load_scene(path)
    assert scene.model.closure_names == closures
    ours = run(scene, 1.0, efforts=CONTROLS)
    qpos = mujoco_qpos(path)
    for k, joint in enumerate(JOINTS):
        assert np.ptp(qpos[:, k]) > 0.3
        np.testing.assert_allclose(ours["q"][joint], qpos[:, k], rtol=0, atol=2e-6)


def test_a_weld_at_an_explicit_relpose_from_a_keyframe_follows_mujoco(tmp_path):
    """A weld whose ``relpose`` is the distal links' relative pose at another configuration
    than ``qpos0`` (where MuJoCo's connect run has taken the five-bar after 0.3 s), the model
    starting there from a keyframe: the weld's points and angle come from ``relpose``, not from
    ``qpos0``. Against MuJoCo as above (2e-6 rad)."""
    m = mujoco.MjModel.from_xml_path(str(MODELS / "five_bar.xml"))
    d = mujoco.MjData(m)
    d.ctrl[:] = CONTROLS
    for _ in range(300):
        mujoco.mj_step(m, d)
    mujoco.mj_kinematics(m, d)
    b1, b2 = (mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n)
              for n in ("left_distal", "right_distal"))
    r1, r2 = d.xmat[b1].reshape(3, 3), d.xmat[b2].reshape(3, 3)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, (r1.T @ r2).flatten())
    relpose = [*(r1.T @ (d.xpos[b2] - d.xpos[b1])), *quat]
    assert np.linalg.norm(d.qpos - m.qpos0) > 0.3  # far from qpos0
    text = (MODELS / "five_bar.xml").read_text().replace(
        '<connect name="pin_joint" body1="left_distal" body2="right_distal" anchor="0.5 0 0"/>',
        '<weld name="pin_joint" body1="left_distal" body2="right_distal" '
        f'relpose="{" ".join(repr(float(x)) for x in relpose)}"/>')
    text = text.replace("</mujoco>", "  <keyframe><key qpos=\""
                        + " ".join(repr(float(x)) for x in d.qpos) + "\"/></keyframe>\n</mujoco>")
    path = tmp_path / "five_bar_weld.xml"
    path.write_text(text)
    scene = load_scene(path)
    assert "assemble" not in import_model(path).document  # the keyframe closes the weld
    ours = run(scene, 1.0, efforts=CONTROLS)
    qpos = mujoco_qpos(path)
    for k, joint in enumerate(JOINTS):
        assert np.ptp(qpos[:, k]) > 0.1
        np.testing.assert_allclose(ours["q"][joint], qpos[:, k], rtol=0, atol=2e-6)


def import_model_text(tmp_path, text: str) -> dict:
    path = tmp_path / "probe.xml"
    path.write_text(text)
    return import_model(path).document


def test_masses_from_capsules_and_the_hand_written_five_bar(imported):
    scene = load_scene(MODELS / "five_bar.xml")
    hand_scene = load_scene(MODELS / "five_bar_xz.yaml")
    # MuJoCo's masses and inertias from the geoms equal the capsule formula written by hand
    # (the same closed form evaluated in another order: 1e-12 relative)
    for a, b in zip(scene.model.links, hand_scene.model.links, strict=True):
        assert a.mass == pytest.approx(b.mass, rel=1e-12)
        assert a.inertia == pytest.approx(b.inertia, rel=1e-12)
    # a motor torque about +y is minus the hand-written torque about -y
    hand = run(hand_scene, 1.0, efforts=[-c for c in CONTROLS])
    zero = {j.name: q for j, q in zip(hand_scene.model.joints,
                                       hand_scene.model.initial_state()[0], strict=True)}
    ref = {"right_elbow": math.radians(20.0)}
    for joint in JOINTS:
        # qpos about +y = minus the hand-written angle about -y, from the file's pose (plus ref);
        # the same equations in other frames: round-off over 1000 ticks (1e-12 seen)
        expected = -(hand["q"][joint] - zero[joint]) + ref.get(joint, 0.0)
        np.testing.assert_allclose(imported["q"][joint], expected, rtol=0, atol=1e-9)
    pin = imported["points"]["pin"]
    np.testing.assert_allclose(np.c_[-pin[:, 0], pin[:, 1]], hand["points"]["pin"], rtol=0,
                               atol=1e-9)


def test_motors_become_geared_actuators_and_sites_points():
    doc = import_model(MODELS / "five_bar.xml").document
    assert doc["actuators"] == [{"joint": "left_base", "gear": 2.0, "limit": 5.0},
                                {"joint": "right_base", "gear": 2.0, "limit": 5.0}]
    assert [p["name"] for p in doc["points"]] == ["pin"]
    assert [c["name"] for c in doc["closures"]] == ["pin_joint"]


MJCF = """<mujoco model="m">
  <worldbody>
    <body name="a"><joint name="ja" type="{kind}" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.01"/>
      <body name="b" pos="0.3 0 0"><joint name="jb" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.01"/></body>
    </body>
  </worldbody>
  {extra}
</mujoco>
"""


@pytest.mark.parametrize("kind, extra, where, why", [
    ("ball", "", "joint 'ja'", "ball joint"),
    ("free", "", "joint 'ja'", "floating base"),
    ("hinge", '<equality><joint joint1="ja" joint2="jb"/></equality>', "<equality>",
     "connect or weld"),
])
def test_what_the_planar_model_cannot_represent_is_refused_by_name(tmp_path, kind, extra,
                                                                    where, why):
    path = tmp_path / "m.xml"
    path.write_text(MJCF.format(kind=kind, extra=extra))
    with pytest.raises(SceneError) as err:
        import_model(path)
    message = str(err.value)
    assert str(path) in message and where in message and why in message, message
