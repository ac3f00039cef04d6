"""Checks of model import that the format tests leave open.

* A link's inertia about the plane normal is taken from the full tensor, rotated by its
  ``<inertial><origin rpy>``: the fixtures' tensors are diagonal in frames aligned with the plane
  and have ``iyy == izz``, so reading the wrong diagonal entry, or dropping the off-diagonal
  terms or the rotation, went unseen. Oracle: the closed form of ``n^T R I R^T n`` for a roll
  ``a`` about x and the normal z, ``s^2 iyy + 2 s c iyz + c^2 izz`` (``s, c = sin a, cos a``).
* A malformed URDF is reported at its line and column; a fixed loop joint in ``<gazebo>`` welds;
  on an inclined plane only gravity's in-plane part acts.
* ``vjm run`` accepts a model file where it takes a scene; the run's end state is the one the
  same import gives when simulated directly.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from model_runs import MODELS, run

from vjm_ros.app.cli import main
from vjm_ros.scene.loader import load_scene

COUPLER = """    <inertial>
      <origin xyz="0.4 0 0" rpy="0 0 0"/>
      <mass value="1.0"/>
      <inertia ixx="1e-4" ixy="0" ixz="0" iyy="0.05333333333333334" iyz="0" izz="0.05333333333333334"/>
    </inertial>
  </link>
  <link name="rocker">"""


def test_inertia_about_the_normal_comes_from_the_rotated_full_tensor(tmp_path):
    roll, ixx, iyy, izz, iyz, ixy = 0.7, 0.01, 0.02, 0.05, 0.004, 0.003
    text = (MODELS / "four_bar.urdf").read_text()
    assert COUPLER in text
    tilted = COUPLER.replace('rpy="0 0 0"', f'rpy="{roll} 0 0"').replace(
        'ixx="1e-4" ixy="0" ixz="0" iyy="0.05333333333333334" iyz="0" izz="0.05333333333333334"',
        f'ixx="{ixx}" ixy="{ixy}" ixz="0" iyy="{iyy}" iyz="{iyz}" izz="{izz}"')
    path = tmp_path / "tilted.urdf"
    path.write_text(text.replace(COUPLER, tilted))
    model = load_scene(path).model
    coupler = model.links[model.link_names.index("coupler")]
    s, c = math.sin(roll), math.cos(roll)
    expected = s * s * iyy + 2.0 * s * c * iyz + c * c * izz  # kg m^2, closed form above
    # the tensor's rotation and projection are a few products: round-off 1e-15 relative
    assert coupler.inertia == pytest.approx(expected, rel=1e-12)
    assert coupler.mass == 1.0
    # a plain izz reading (0.05) or a dropped off-diagonal term differs by > 10 %
    assert abs(expected - izz) > 0.1 * izz and abs(expected - (s * s * iyy + c * c * izz)) > 0.05 * izz


@pytest.mark.slow  # 12 s here: the run command's start-up, not the simulation
def test_vjm_run_takes_a_model_file_as_its_scene(tmp_path, capsys):
    path = MODELS / "four_bar.sdf"
    assert main(["run", str(path), "--duration", "0.2", "--integrator", "rk4",
                 "--closure", "exact", "--out", str(tmp_path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    direct = run(load_scene(path), 0.2)
    assert summary
    # the four-bar falls from rest under gravity: the crank turns (rad)
    assert abs(direct["q"]["crank_joint"][-1] - direct["q"]["crank_joint"][0]) > 1e-3
    trajectory = (tmp_path / "trajectory.csv").read_text().splitlines()
    header = trajectory[0].split(",")
    last = dict(zip(header, trajectory[-1].split(","), strict=True))
    for joint in direct["q"]:
        column = next(h for h in header if h == f"q.{joint}")
        # same model, integrator and step: the same numbers up to CSV formatting
        assert float(last[column]) == pytest.approx(direct["q"][joint][-1], abs=1e-9)


def test_malformed_urdf_names_its_line_and_column(tmp_path):
    """The SDFormat and MJCF tests pin the position of an XML error; this one the URDF's."""
    from vjm_ros.core.errors import SceneError
    from vjm_ros.formats.importing import import_model

    path = tmp_path / "bad.urdf"
    path.write_text('<?xml version="1.0"?>\n<robot name="r">\n  <link name="a">\n</robot>\n')
    with pytest.raises(SceneError) as err:
        import_model(path)
    # the unclosed <link> is found at the closing </robot>: line 4, column 3 (1-based)
    assert str(path) in str(err.value) and "line 4, column 3" in str(err.value), str(err.value)


def test_a_fixed_gazebo_loop_joint_welds(tmp_path):
    """A ``fixed`` SDFormat joint in ``<gazebo>`` welds (a pin and an angle closure). Welding the
    four-bar's rocker to the base leaves crank and coupler a triangle with the rocker: a rigid
    structure, which the crank's torque cannot move (the pinned four-bar turns by > 0.5 rad)."""
    text = (MODELS / "four_bar.urdf").read_text()
    welded = text.replace('<joint name="ground_joint" type="revolute">',
                          '<joint name="ground_joint" type="fixed">')
    assert welded != text
    path = tmp_path / "welded.urdf"
    path.write_text(welded)
    scene = load_scene(path)
    assert sorted(scene.model.closure_names) == ["ground_joint", "ground_joint_angle"]
    pinned = run(load_scene(MODELS / "four_bar.urdf"), 0.3, efforts=[5.0])["q"]
    rigid = run(scene, 0.3, efforts=[5.0])["q"]
    assert max(float(np.ptp(q)) for q in pinned.values()) > 0.5  # rad
    for joint, q in rigid.items():
        # rad: exact closure holds a rigid structure to round-off (4e-16 seen over 300 ticks)
        assert np.ptp(q) < 1e-9, (joint, np.ptp(q))


def test_gravity_on_an_inclined_plane_is_its_in_plane_part(tmp_path):
    """The fixtures' planes are vertical or horizontal (in-plane gravity g or 0). Tilting the
    table four-bar by a roll ``a`` about x (its base weld) leaves ``g sin a`` in the plane
    (closed form: ``|g - (g . N) N|`` with ``N = (0, -sin a, cos a)``), along ``-e2``; the
    links' inertias about ``N`` do not change (their tensors turn with the plane)."""
    roll = 0.5
    text = (MODELS / "four_bar.urdf").read_text()
    weld = '    <parent link="world"/>\n    <child link="base"/>\n'
    assert weld in text
    tilted = text.replace(weld, weld + f'    <origin xyz="0 0 0" rpy="{roll} 0 0"/>\n')
    path = tmp_path / "inclined.urdf"
    path.write_text(tilted)
    model = load_scene(path).model
    flat = load_scene(MODELS / "four_bar.urdf").model
    # m/s^2: one projection of a 3-vector, round-off 1e-15
    np.testing.assert_allclose(model.gravity, [0.0, -9.81 * math.sin(roll)], rtol=0, atol=1e-12)
    assert flat.gravity.tolist() == [0.0, 0.0]
    for a, b in zip(model.links, flat.links, strict=True):
        assert a.inertia == pytest.approx(b.inertia, rel=1e-12)  # kg m^2
