"""SDFormat models as scenes, against the same mechanisms written by hand.

``test/models/four_bar.sdf`` (SDFormat 1.6: joint poses in the child link's frame, axes in the
joint frame) and ``four_bar_relative.sdf`` (1.9: poses ``relative_to`` other frames, in degrees,
an axis ``expressed_in`` the model frame, a named ``<frame>``) describe one four-bar in the x-z
plane with axes along +y; ``four_bar_xz.yaml`` is it written by hand (angles counter-clockwise
seen with z up, i.e. about -y). The import takes the plane's normal from the first axis
(``N = +y``), ``e2`` against gravity (``+z``) and ``e1 = e2 x N = -x``: a point ``(a, b)`` of the
imported scene is ``(x, z) = (-a, b)``, and each joint coordinate is the file's joint position:
minus the hand-written relative angle, from zero at the file's pose.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from model_runs import MODELS, run

from vjm_ros.core.errors import SceneError
from vjm_ros.formats.importing import import_model
from vjm_ros.scene.loader import load_scene

HAND_ZERO = {"crank_joint": 0.0, "coupler_joint": math.pi / 3, "rocker_joint": -2 * math.pi / 3}
"""The hand-written coordinates at the file's pose (its zero), rad."""


@pytest.fixture(scope="module")
def hand():
    return run(load_scene(MODELS / "four_bar_xz.yaml"), 1.0)


@pytest.mark.parametrize("name", ["four_bar.sdf", "four_bar_relative.sdf"])
def test_sdformat_four_bar_moves_as_the_hand_written_one(name, hand):
    imported = run(load_scene(MODELS / name), 1.0)
    for joint, zero in HAND_ZERO.items():
        assert np.ptp(hand["q"][joint]) > 0.5  # it does swing (rad)
        # Both runs integrate the same equations in different frames: they agree to round-off
        # amplified over 1000 rk4 ticks of a non-chaotic swing (1e-14 seen; 1e-10 leaves room).
        np.testing.assert_allclose(imported["q"][joint], -(hand["q"][joint] - zero),
                                   rtol=0, atol=1e-10)


def test_a_named_frame_is_a_point_moving_with_its_link(hand):
    imported = run(load_scene(MODELS / "four_bar_relative.sdf"), 1.0)
    a = imported["points"]["coupler_mid"]
    x_z = np.c_[-a[:, 0], a[:, 1]]
    assert np.ptp(hand["points"]["coupler_mid"][:, 1]) > 0.1  # m: it moves
    np.testing.assert_allclose(x_z, hand["points"]["coupler_mid"], rtol=0, atol=1e-10)


def test_the_file_pose_is_the_start_and_loop_joint_a_closure():
    doc = import_model(MODELS / "four_bar.sdf").document
    assert [lk["joint"]["name"] for lk in doc["chains"][0]["links"]] == list(HAND_ZERO)
    assert [c["name"] for c in doc["closures"]] == ["ground_joint"]
    assert "assemble" not in doc  # the file's pose closes exactly
    scene = load_scene(MODELS / "four_bar.sdf")
    assert scene.model.initial_state()[0].tolist() == [0.0, 0.0, 0.0]
    assert scene.model.gravity.tolist() == [0.0, -9.81]


# ------------------------------------------------------------------------------ refusals
def _sdf(body: str, version: str = "1.7") -> str:
    return (f'<?xml version="1.0"?>\n<sdf version="{version}">\n<model name="m">\n'
            '<link name="a"><pose>0 0 0 0 0 0</pose></link>\n'
            '<link name="b"><pose>1 0 0 0 0 0</pose></link>\n'
            f"{body}</model>\n</sdf>\n")


J1 = ('<joint name="j1" type="revolute"><parent>world</parent><child>a</child>'
      "<axis><xyz>0 0 1</xyz></axis></joint>\n")


@pytest.mark.parametrize("body, where, why", [
    (J1 + '<joint name="j2" type="revolute"><parent>a</parent><child>b</child>'
     "<axis><xyz>1 0 0</xyz></axis></joint>\n",
     "joint 'j2'", "parallel"),
    (J1 + '<joint name="j2" type="ball"><parent>a</parent><child>b</child></joint>\n',
     "joint 'j2'", "revolute, continuous, prismatic or fixed"),
    (J1 + '<joint name="j2" type="universal"><parent>a</parent><child>b</child></joint>\n',
     "joint 'j2'", "revolute, continuous, prismatic or fixed"),
    (J1, "link 'b'", "floating"),
    (J1 + '<joint name="j2" type="revolute"><parent>a</parent><child>b</child>'
     "<axis><xyz>0 0 1</xyz></axis></joint>\n"
     '<link name="c"><pose>2 0 0 0 0 0</pose></link>'
     '<joint name="j4" type="revolute"><parent>a</parent><child>c</child>'
     "<axis><xyz>0 0 1</xyz></axis></joint>\n",
     "link 'c'", "branch"),
    ('<model name="inner"/>', "<model>", "nested"),
])
def test_what_the_planar_model_cannot_represent_is_refused_by_name(tmp_path, body, where, why):
    path = tmp_path / "m.sdf"
    path.write_text(_sdf(body))
    with pytest.raises(SceneError) as err:
        import_model(path)
    message = str(err.value)
    assert str(path) in message and where in message and why in message, message


def test_malformed_xml_names_its_line_and_column(tmp_path):
    path = tmp_path / "bad.sdf"
    path.write_text('<?xml version="1.0"?>\n<sdf version="1.7">\n  <model name="m">\n'
                    '    <link name="a"></lnk>\n  </model>\n</sdf>\n')
    with pytest.raises(SceneError) as err:
        import_model(path)
    # expat points at the mismatched name, 'lnk' (columns counted from 1)
    assert "line 4, column 22" in str(err.value), str(err.value)


def test_vjm_import_exits_2_naming_the_element_and_writes_yaml_otherwise(tmp_path):
    bad = tmp_path / "m.sdf"
    bad.write_text(_sdf(J1 + '<joint name="j2" type="ball"><parent>a</parent><child>b</child>'
                        "</joint>\n"))
    cmd = [sys.executable, "-m", "vjm_ros.app.cli"]
    out = subprocess.run([*cmd, "import", str(bad)], capture_output=True, text=True,
                         timeout=120)  # a hang guard: the import takes well under a second
    assert out.returncode == 2 and "joint 'j2'" in out.stderr and "ball" in out.stderr
    good = tmp_path / "four_bar.yaml"
    out = subprocess.run([*cmd, "import", str(MODELS / "four_bar.sdf"), "--actuate",
                          "crank_joint", "-o", str(good)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert "collision and visual geometry" in out.stderr  # what is ignored is said once
    assert out.stderr.count("collision") == 1
    scene = load_scene(good)
    assert scene.model.actuator_names == ["crank_joint"]


@pytest.mark.parametrize("version, axis_xml, expected", [
    ("1.4", "<xyz>0 1 0</xyz>", [0, 1, 0]),  # 1.4: the model frame
    ("1.5", "<xyz>0 1 0</xyz>", [0, -1, 0]),  # from 1.5: the joint frame (the child's, rolled)
    ("1.6", "<xyz>0 1 0</xyz><use_parent_model_frame>true</use_parent_model_frame>", [0, 1, 0]),
    ("1.7", "<xyz>0 1 0</xyz>", [0, -1, 0]),
    ("1.7", '<xyz expressed_in="__model__">0 1 0</xyz>', [0, 1, 0]),
    ("1.8", "<xyz>0 1 0</xyz>", [0, -1, 0]),  # 1.8 and 1.10 keep 1.7's rule
    ("1.10", '<xyz expressed_in="frame_b">0 1 0</xyz>', [0, 0, 1]),
    ("1.11", '<xyz expressed_in="frame_b">0 1 0</xyz>', [0, 0, 1]),
])
def test_joint_axes_are_read_in_the_frame_of_the_files_version(tmp_path, version, axis_xml,
                                                                 expected):
    """The child link is rolled half a turn about x, so its frame's y is the model's -y;
    ``frame_b`` (1.7+) is the model frame turned a quarter about x (its y is the model's z)."""
    from vjm_ros.formats.sdformat import read_sdformat

    frame = ('<frame name="frame_b"><pose>0 0 0 1.5707963267948966 0 0</pose></frame>'
             if version not in ("1.4", "1.5", "1.6") else "")
    path = tmp_path / "axis.sdf"
    path.write_text(f'<sdf version="{version}"><model name="m">'
                    '<link name="a"><pose>0 0 0 3.141592653589793 0 0</pose></link>'
                    f'{frame}<joint name="j" type="revolute"><parent>world</parent>'
                    f'<child>a</child><axis>{axis_xml}</axis></joint></model></sdf>')
    (joint,) = read_sdformat(str(path)).joints
    np.testing.assert_allclose(joint.axis, expected, atol=1e-15)


def test_actuate_adds_actuators_and_keeps_the_actuated_joint_a_coordinate():
    doc = import_model(MODELS / "four_bar.sdf", ("ground_joint",)).document
    names = [lk["joint"]["name"] for ch in doc["chains"] for lk in ch["links"]]
    assert "ground_joint" in names  # in a joint graph an actuated joint is put in a chain
    assert doc["actuators"] == [{"joint": "ground_joint"}]
    assert len(doc["closures"]) == 1 and doc["closures"][0]["name"] != "ground_joint"
    with pytest.raises(SceneError) as err:
        import_model(MODELS / "four_bar.sdf", ("no_such_joint",))
    assert "--actuate" in str(err.value) and "no_such_joint" in str(err.value)


def test_another_cut_of_the_loop_when_a_link_would_point_away_from_its_next_joint(tmp_path):
    """A loop world - a - b - c - d - world whose links a, b, c point at 0, 120 and 240 deg at
    the file's pose: one chain a-b-c-d would need one frame angle for a, b, c with each next
    joint ahead (impossible over 240 deg), so the loop is cut at c-d instead (chains a-b-c and
    d). The file's pose closes the loops in the frames placed (no assembly: the scene's own
    closure check, 1e-6)."""
    pts = {"a": (0.0, 0.0, 0.0), "b": (1.0, 0.0, 120.0), "c": (0.5, 0.8660254037844386, 240.0),
           "d": (0.0, 0.0, 180.0)}
    links = "".join(f'<link name="{n}"><pose>{x!r} {y!r} 0 0 0 {math.radians(a)!r}</pose></link>'
                    for n, (x, y, a) in pts.items())
    joints = "".join(
        f'<joint name="j{c}" type="revolute"><parent>{p}</parent><child>{c}</child>'
        "<axis><xyz>0 0 1</xyz></axis></joint>"
        for p, c in (("world", "a"), ("a", "b"), ("b", "c"), ("c", "d")))
    joints += ('<joint name="jw" type="revolute"><pose relative_to="__model__">-1 0 0 0 0 0'
               "</pose><parent>world</parent><child>d</child><axis><xyz>0 0 1</xyz></axis>"
               "</joint>")
    path = tmp_path / "zigzag.sdf"
    path.write_text(f'<sdf version="1.7"><model name="zigzag">{links}{joints}</model></sdf>')
    doc = import_model(path).document
    assert [[lk["name"] for lk in ch["links"]] for ch in doc["chains"]] == [["a", "b", "c"], ["d"]]
    assert [c["name"] for c in doc["closures"]] == ["jd"]
    assert "assemble" not in doc


REFUSED = {
    "axis.sdf": (_sdf(J1 + '<joint name="j2" type="revolute"><parent>a</parent><child>b</child>'
                      "<axis><xyz>1 0 0</xyz></axis></joint>\n"), "parallel"),
    "ball.sdf": (_sdf(J1 + '<joint name="j2" type="ball"><parent>a</parent><child>b</child>'
                      "</joint>\n"), "ball"),
    "floating.sdf": (_sdf(J1), "floating"),
    "loop.urdf": ('<robot name="r"><link name="base"/><link name="a"><inertial><mass value="1"/>'
                  '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
                  '<joint name="ja" type="continuous"><parent link="base"/><child link="a"/>'
                  '<axis xyz="0 0 1"/></joint><gazebo><joint name="loop" type="universal">'
                  "<parent>a</parent><child>base</child></joint></gazebo></robot>", "universal"),
    "free.xml": ('<mujoco><worldbody><body name="b"><freejoint name="f"/><geom size="0.1"/>'
                 "</body></worldbody></mujoco>", "floating base"),
    "malformed.xml": ("<mujoco>\n  <worldbody>\n</mujoco>\n", "line 3, column 3"),
}


@pytest.mark.parametrize("name", sorted(REFUSED))
def test_vjm_import_refuses_with_exit_2_naming_why(tmp_path, capsys, name):
    from vjm_ros.app.cli import main

    text, why = REFUSED[name]
    path = tmp_path / name
    path.write_text(text)
    assert main(["import", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and why in err, err
