"""A joint's damping, armature and friction in the exports: URDF ``<dynamics>``, MuJoCo's joint
``damping``, ``armature`` and ``frictionloss``; MuJoCo against vjm where both model the same."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from vjm_ros.formats.mjcf_out import scene_mjcf
from vjm_ros.formats.urdf_out import scene_urdf
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator
from vjm_ros.studies import compare_mujoco

mujoco = pytest.importorskip("mujoco")

KINDS = Path(__file__).with_name("export_closure_kinds.yaml")
TIGHT = dict(integrator="RK4", solref=(-1e7, -2e3), solimp=(0.9999, 0.9999, 0.001, 0.5, 2.0))
"""As test_export_mjcf.py."""


def _scene(tmp_path, friction=""):
    """The all-kinds scene with damping on the lever and the ram, armature on the crank."""
    text = KINDS.read_text()
    for old, new in (
        ("{name: lever_joint, type: revolute, angle: 80.0}",
         f"{{name: lever_joint, type: revolute, angle: 80.0, damping: 0.5{friction}}}"),
        ("{name: crank_joint, type: revolute, angle: 60.0, velocity: 90.0}",
         "{name: crank_joint, type: revolute, angle: 60.0, velocity: 90.0, armature: 0.01}"),
        ("{name: ram_slide, type: prismatic, angle: -5.0, slide: 0.04, velocity: 0.1}",
         "{name: ram_slide, type: prismatic, angle: -5.0, slide: 0.04, velocity: 0.1, "
         "damping: 2.0}"),
    ):
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "joint_plant.yaml"
    path.write_text(text)
    return load_scene(str(path))


def test_damping_armature_and_friction_run_in_mujoco_as_in_vjm(tmp_path):
    """Viscous damping and armature are the same terms in both (a generalized force
    ``-d qdot``, a mass-matrix diagonal entry), and so is Coulomb friction while the joint
    slides (``-f sign(qdot)``; the lever's rate keeps its sign over the run): 0.2 s with efforts
    on the motors agree within the 1e-6 of test_mujoco_follows_vjm (measured 2e-10). vjm runs
    rk4 at 0.25 ms here: its sticking friction acts between fixed steps."""
    scene = _scene(tmp_path, friction=", friction: 0.3")
    effort = np.array([1.0, 3.0])
    sim = Simulator(scene.model, SimulationSettings(closure="exact", rate=1000.0,
                                                    integrator="rk4", substeps=4),
                    scene.gains, scene.plant)
    sim.set_efforts(effort)
    q_ref, lever_rate = [sim.q.copy()], []
    for _ in range(200):
        sim.advance()
        q_ref.append(sim.q.copy())
        lever_rate.append(sim.qd[1])
    assert np.all(np.array(lever_rate) > 0) or np.all(np.array(lever_rate) < 0), "sliding"
    settings = compare_mujoco.MujocoSettings(substeps=4, **TIGHT)
    with compare_mujoco.MujocoSimulator(scene.model, settings, scene.plant) as mj:
        mj.set_efforts(effort)
        names = [j.name for j in scene.model.joints]
        idx = [mj.m.jnt_qposadr[mujoco.mj_name2id(mj.m, mujoco.mjtObj.mjOBJ_JOINT, n)]
               for n in names]
        dof = [mj.m.jnt_dofadr[mujoco.mj_name2id(mj.m, mujoco.mjtObj.mjOBJ_JOINT, n)]
               for n in names]
        np.testing.assert_array_equal(mj.m.dof_damping[dof], [0.0, 0.5, 0.0, 0.0, 2.0])
        np.testing.assert_array_equal(mj.m.dof_armature[dof], [0.01, 0.0, 0.0, 0.0, 0.0])
        np.testing.assert_array_equal(mj.m.dof_frictionloss[dof], [0.0, 0.3, 0.0, 0.0, 0.0])
        q = [mj.d.qpos[idx].copy()]
        for _ in range(200):
            mj.advance()
            q.append(mj.d.qpos[idx].copy())
    np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-6)


def test_friction_and_damping_in_both_files(tmp_path):
    """Coulomb friction: URDF ``<dynamics friction>``, MuJoCo ``frictionloss`` (its friction
    constraint as stiff as the equalities)."""
    scene = _scene(tmp_path, friction=", friction: 0.3")
    urdf = ET.fromstring(scene_urdf(scene.model))
    dyn = urdf.find("joint[@name='lever_joint']/dynamics")
    assert (float(dyn.get("damping")), float(dyn.get("friction"))) == (0.5, 0.3)
    assert urdf.find("joint[@name='crank_joint']/dynamics") is None
    m = mujoco.MjModel.from_xml_string(scene_mjcf(scene.model))
    lever = m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "lever_joint")]
    assert m.dof_frictionloss[lever] == 0.3 and m.dof_damping[lever] == 0.5


def _pendulum_with_stop(tmp_path, restitution):
    """The built-in pendulum with a stop at -100 deg (it swings down from -30 deg into it)."""
    text = load_scene("pendulum").text.replace(
        "joint: {name: pivot, type: revolute, angle: -30.0}",
        f"joint: {{name: pivot, type: revolute, angle: -30.0, range: [-100.0, 0.0], "
        f"restitution: {restitution}}}")
    path = tmp_path / f"stop_{restitution}.yaml"
    path.write_text(text)
    return load_scene(str(path))


def test_stops_are_urdf_limits_and_mujoco_ranges(tmp_path):
    """A range makes the URDF joint ``revolute`` with the range as limits (in the file's
    positions: less ``q0`` with ``zero="initial"``) and the MuJoCo joint limited to it."""
    scene = _pendulum_with_stop(tmp_path, 0.5)
    lo, hi = math.radians(-100.0), 0.0
    q0 = scene.model.initial_state()[0][0]
    for zero, shift in (("coordinates", 0.0), ("initial", q0)):
        limit = ET.fromstring(scene_urdf(scene.model, zero)).find("joint[@name='pivot']")
        assert limit.get("type") == "revolute"
        bounds = limit.find("limit")
        assert (float(bounds.get("lower")), float(bounds.get("upper"))) == (lo - shift, hi - shift)
    m = mujoco.MjModel.from_xml_string(scene_mjcf(scene.model))
    assert m.jnt_limited[0] and tuple(m.jnt_range[0]) == (lo, hi)


@pytest.mark.parametrize("restitution", [0.0, 0.5])
def test_a_stop_in_mujoco_and_in_vjm(tmp_path, restitution):
    """Until the stop the runs agree (1e-9 rad); at the stop vjm applies an impact of the given
    restitution and MuJoCo a soft unilateral spring-damper whose damping ratio gives that
    restitution to a linear one: the fastest rebound differs by less than 0.15 of the impact
    speed (measured 0.05 for 0, 0.09 for 0.5; gravity acts during MuJoCo's soft contact)."""
    scene = _pendulum_with_stop(tmp_path, restitution)
    sim = Simulator(scene.model, SimulationSettings(rate=1000.0, integrator="rk4", substeps=4),
                    scene.gains, scene.plant)
    settings = compare_mujoco.MujocoSettings(substeps=4, **TIGHT)
    q_ref, v_ref, q, v = [], [], [], []
    with compare_mujoco.MujocoSimulator(scene.model, settings, scene.plant) as mj:
        for _ in range(1500):
            sim.advance()
            mj.advance()
            q_ref.append(sim.q[0])
            v_ref.append(sim.qd[0])
            q.append(mj.d.qpos[0])
            v.append(mj.d.qvel[0])
    q_ref, v_ref, q, v = map(np.array, (q_ref, v_ref, q, v))
    impact = int(np.argmax(v_ref >= 0.0))  # the first tick its fall is stopped
    assert impact > 100 and q_ref.min() < math.radians(-99.0), "a swing into the stop"
    np.testing.assert_allclose(q[: impact - 5], q_ref[: impact - 5], rtol=0, atol=1e-9)
    speed = abs(v_ref[impact - 5 : impact + 1]).max()
    assert abs(v[impact:].max() - v_ref[impact:].max()) < 0.15 * speed
