"""``vjm export``: the files it writes, and exit 2 with a clear message on bad arguments."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import pytest

from vjm_ros.app.cli import main
from vjm_ros.scene.loader import load_scene

yourdfpy = pytest.importorskip("yourdfpy")
mujoco = pytest.importorskip("mujoco")


def test_writes_urdf_and_mjcf(tmp_path):
    urdf, mjcf = tmp_path / "five_bar.urdf", tmp_path / "five_bar.xml"
    assert main(["export", "five_bar", "--urdf", str(urdf)]) == 0
    assert main(["export", "five_bar", "--mjcf", str(mjcf), "--integrator", "implicitfast"]) == 0
    model = load_scene("five_bar").model
    robot = yourdfpy.URDF.load(str(urdf), build_scene_graph=False, load_meshes=False)
    assert robot.actuated_joint_names == model.joint_names
    m = mujoco.MjModel.from_xml_path(str(mjcf))
    # the scene's tick (1 kHz, one substep) and the integrator asked for
    assert m.opt.timestep == 0.001 and m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert [m.joint(i).name for i in range(m.njnt)] == model.joint_names


def test_zero_initial_and_standard_output(capsys):
    assert main(["export", "four_bar", "--urdf", "-", "--zero", "initial"]) == 0
    text = capsys.readouterr().out
    robot = yourdfpy.URDF.load(io.BytesIO(text.encode()), build_scene_graph=False,
                               load_meshes=False)
    assert "zero pose = initial state" in text and robot.validate()


@pytest.mark.parametrize(("argv", "message"), [
    (["export", "four_bar"], "one of the arguments --urdf --mjcf is required"),
    (["export", "four_bar", "--urdf", "a", "--mjcf", "b"], "not allowed with argument"),
    (["export", "four_bar", "--urdf", "a", "--zero", "home"], "invalid choice: 'home'"),
])
def test_argument_errors_exit_2(argv, message, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize(("argv", "message"), [
    (["export", "no_such_scene", "--urdf", "-"], "no_such_scene"),
    (["export", "four_bar", "--mjcf", "-", "--zero", "initial"], "--zero initial: a URDF option"),
    (["export", "four_bar", "--urdf", "-", "--timestep", "0.001"], "MJCF options, given with --urdf"),
    (["export", "four_bar", "--mjcf", "-", "--timestep", "0"], "--timestep: expected a positive"),
    (["export", "four_bar", "--urdf", "/no/such/dir/x.urdf"], "/no/such/dir/x.urdf: cannot write"),
])
def test_bad_input_exits_2_naming_it(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("vjm: error:") and message in err


def test_a_name_the_format_reserves_exits_2(tmp_path, capsys):
    text = load_scene("four_bar").text.replace("name: crank,", "name: world,")
    scene = tmp_path / "world_link.yaml"
    scene.write_text(text)
    assert main(["export", str(scene), "--urdf", "-"]) == 2
    assert "link 'world'" in capsys.readouterr().err


def test_the_installed_command():
    """The ``vjm`` entry point, as a user runs it."""
    vjm = Path(sys.executable).with_name("vjm")
    out = subprocess.run([str(vjm), "export", "slider_crank", "--mjcf", "-"], check=True,
                         capture_output=True, text=True, timeout=60,  # hang guard
                         env={**os.environ, "VJM_TIERED": "0"})
    m = mujoco.MjModel.from_xml_string(out.stdout)
    assert m.neq == 1 and m.nu == 1
