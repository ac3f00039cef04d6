"""The MJCF export against MuJoCo, a simulator we did not write.

MuJoCo compiles the exported text with its own compiler and integrates it with its own
dynamics and soft equality constraints; at tight settings its joint coordinates and link ends
must follow vjm's exact-closure reference of the same scene, for every built-in scene and every
closure kind.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from vjm_ros.core.model import REVOLUTE
from vjm_ros.core.readers import forward_kinematics
from vjm_ros.formats.mjcf_out import INITIAL_KEY, MjcfSettings, carriage_mass, scene_mjcf
from vjm_ros.scene.loader import builtin_scenes, load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator
from vjm_ros.studies import compare_mujoco

mujoco = pytest.importorskip("mujoco")

KINDS = str(Path(__file__).with_name("export_closure_kinds.yaml"))
"""Every closure kind: a slider on a moving link's line and an angle closure (see
test_export_urdf.py)."""
SCENES = [*builtin_scenes(), KINDS]
IDEAL = [s for s in SCENES if not (load_scene(s).model.has_joint_efforts
                                   or load_scene(s).model.has_plant_terms)]
"""The scenes without joint friction, stops, damping or loads: MuJoCo's frictionloss and joint
limits are soft constraints, not vjm's sticking friction and impacts, so the scenes with them
are compared in test_export_joint_plant.py (sliding friction and damping to 2e-10, stops before
the impact to 1e-9) rather than here."""
TIGHT = dict(integrator="RK4", solref=(-1e7, -2e3), solimp=(0.9999, 0.9999, 0.001, 0.5, 2.0))
"""MuJoCo's equalities as stiff as its RK4 carries at 0.25 ms: solref negative is
``(-stiffness, -damping)`` in acceleration units, omega_n = sqrt(1e7) = 3.2e3 rad/s
(omega_n h = 0.8 at 4 substeps of 1 ms), impedance 0.9999 (MuJoCo's largest)."""
EFFORT = 2.0
"""Constant effort on every actuator on both sides (N m or N): the motors' mapping is checked
too."""


def _reference(scene, ticks, effort=EFFORT):
    """vjm's exact-closure solution at tight tolerance: q and link ends per tick."""
    settings = SimulationSettings(closure="exact", rate=1000.0, integrator="dop853",
                                  rtol=1e-12, atol=1e-14)
    sim = Simulator(scene.model, settings, scene.gains)
    if scene.model.actuators:
        sim.set_efforts(np.full(len(scene.model.actuators), effort))
    q, ends = [sim.q.copy()], [_ends(scene.model, sim.q)]
    for _ in range(ticks):
        sim.advance()
        q.append(sim.q.copy())
        ends.append(_ends(scene.model, sim.q))
    return np.array(q), np.array(ends)


def _ends(model, q):
    kin = forward_kinematics(model, q)
    return kin.origin[: model.n] + model.length[:, None] * kin.rotation[: model.n, :, 0]


def _qpos_index(m, model):
    return np.array([m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.name)]
                     for j in model.joints])


def _run_mujoco(scene, ticks, substeps, effort=EFFORT):
    settings = compare_mujoco.MujocoSettings(substeps=substeps, **TIGHT)
    with compare_mujoco.MujocoSimulator(scene.model, settings) as sim:
        if scene.model.actuators:
            sim.set_efforts(np.full(len(scene.model.actuators), effort))
        idx = _qpos_index(sim.m, scene.model)
        q, ends, closure = [sim.d.qpos[idx].copy()], [sim.link_ends()], []
        for _ in range(ticks):
            sim.advance()
            sim.refresh()
            q.append(sim.d.qpos[idx].copy())
            ends.append(sim.link_ends())
            closure.append(sim.closure_errors().max(initial=0.0))
    return np.array(q), np.array(ends), max(closure)


@pytest.mark.parametrize("spec", IDEAL, ids=lambda s: Path(s).stem)
def test_mujoco_follows_vjm(spec):
    """0.2 s of MuJoCo RK4 at 0.25 ms on the exported MJCF (carriages of negligible mass, see
    ``stiffen_carriages``) against vjm's reference: joint coordinates and link ends agree.

    Tolerance 1e-6 (m, rad): MuJoCo's equality is a spring-damper in acceleration, so its
    closure gives way by about ``a / k`` = 10 m/s^2 / 1e7 s^-2 = 1e-6 m under the mechanisms'
    accelerations, and the motion follows from the closure; RK4's own error at 0.25 ms is far
    below. Measured: 7e-13 (pendulum, no closure) to 2e-8 m.
    """
    scene = load_scene(spec)
    ticks = 200
    q_ref, ends_ref = _reference(scene, ticks)
    q, ends, closure = _run_mujoco(scene, ticks, substeps=4)
    assert np.ptp(q_ref, axis=0).max() > 0.01, "the mechanism moves"
    # at t = 0: the keyframe is the scene's initial state, exactly
    np.testing.assert_allclose(q[0], q_ref[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ends[0], ends_ref[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-6)
    np.testing.assert_allclose(ends, ends_ref, rtol=0, atol=1e-6)
    assert closure < 1e-6


@pytest.mark.slow
@pytest.mark.parametrize("spec", IDEAL, ids=lambda s: Path(s).stem)
def test_mujoco_follows_vjm_for_a_second(spec):
    """1 s at 62.5 us under gravity alone (constant efforts spin slider_crank's crank up to
    ~180 rad/s within the second, where a / k grows past the bound): within 1e-6 (m, rad) as
    over 0.2 s, measured 4e-12 m (pendulum) to 7e-8 m and 2.2e-7 rad (rrr_platform);
    five_bar's symmetric start amplifies differences ~100x per second, docs/accuracy.md."""
    scene = load_scene(spec)
    q_ref, ends_ref = _reference(scene, 1000, effort=0.0)
    q, ends, closure = _run_mujoco(scene, 1000, substeps=16, effort=0.0)
    np.testing.assert_allclose(ends, ends_ref, rtol=0, atol=1e-6)
    np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-6)
    assert closure < 1e-6


@pytest.mark.parametrize("spec", SCENES, ids=lambda s: Path(s).stem)
def test_mjcf_names_masses_and_initial_state(spec):
    """MuJoCo's compiled model of the default export: the scene's joints by name and type,
    ``qpos0`` and the keyframe its initial state, masses and mass centres, gravity in the
    plane, one motor per actuator with the limit as ``ctrlrange``."""
    model = load_scene(spec).model
    m = mujoco.MjModel.from_xml_string(scene_mjcf(model))
    q0, qd0 = model.initial_state()
    idx = _qpos_index(m, model)
    for joint in model.joints:
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint.name)
        expected = mujoco.mjtJoint.mjJNT_HINGE if joint.kind == REVOLUTE else mujoco.mjtJoint.mjJNT_SLIDE
        assert m.jnt_type[j] == expected
    np.testing.assert_array_equal(m.qpos0[idx], q0)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, INITIAL_KEY))
    np.testing.assert_array_equal(d.qpos[idx], q0)
    np.testing.assert_array_equal(d.qvel[[m.jnt_dofadr[mujoco.mj_name2id(
        m, mujoco.mjtObj.mjOBJ_JOINT, j.name)] for j in model.joints]], qd0)
    for lk in model.links:
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, lk.name)
        assert m.body_mass[b] == max(lk.mass, 1e-12)
        np.testing.assert_allclose(m.body_ipos[b], [*lk.com, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(m.opt.gravity, [*model.gravity, 0.0])
    assert m.nu == len(model.actuators)
    for k, a in enumerate(model.actuators):
        assert m.actuator_trnid[k, 0] == mujoco.mj_name2id(
            m, mujoco.mjtObj.mjOBJ_JOINT, model.joints[a.joint].name)
        np.testing.assert_array_equal(m.actuator_ctrlrange[k], [-a.limit, a.limit])
    # the velocities MuJoCo starts from satisfy its equalities (carriage rates included)
    mujoco.mj_forward(m, d)
    if m.neq:
        assert np.abs(d.efc_vel[: d.nefc]).max() < 1e-12
        assert np.abs(d.efc_pos[: d.nefc]).max() < 1e-12


@pytest.mark.parametrize("name", ["double_slider", "slider_crank", KINDS], ids=lambda s: Path(s).stem)
def test_exported_file_holds_slider_and_angle_closures(name):
    """The file as written (carriages of a thousandth of the lightest link, the tight
    solref/solimp) holds its slider and angle closures to 1e-5 m for 0.2 s and follows vjm to
    a small share of the motion.

    MuJoCo softens an equality by its bodies' inverse masses: with the carriage at 1e-3 of a
    link the regularization is ~0.1-0.2 of the link's own weight, so the closure gives way by
    ~0.2 a / k, about 1e-6 m (measured 1.2e-6 m on slider_crank, 1e-7 m on double_slider).
    The carriages are mass vjm does not have (a few 1e-4 of the mechanism's, moving at the
    points' speed): measured 3e-5 to 1.8e-3 of the largest joint travel, bound 5e-3.
    """
    scene = load_scene(name)
    settings = MjcfSettings(timestep=0.00025, **TIGHT)
    m = mujoco.MjModel.from_xml_string(scene_mjcf(scene.model, settings))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    a = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"cl_{c.name}_a") for c in scene.model.closures]
    b = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"cl_{c.name}_b") for c in scene.model.closures]
    idx = _qpos_index(m, scene.model)
    if scene.model.actuators:
        d.ctrl[:] = EFFORT
    q_ref, _ = _reference(scene, 200)
    worst, q = 0.0, [d.qpos[idx].copy()]
    for _ in range(200):
        mujoco.mj_step(m, d, nstep=4)
        worst = max(worst, np.abs(d.site_xpos[a] - d.site_xpos[b]).max())
        q.append(d.qpos[idx].copy())
    assert worst < 1e-5
    travel = np.ptp(q_ref, axis=0).max()
    np.testing.assert_allclose(q, q_ref, rtol=0, atol=5e-3 * travel)
    assert carriage_mass(scene.model, settings) == 1e-3 * min(lk.mass for lk in scene.model.links
                                                             if lk.mass > 0)


def test_refuses_a_name_the_carriage_needs():
    text = Path(KINDS).read_text().replace("name: boom,", "name: slot_carriage,")
    from vjm_ros.scene.loader import parse_scene

    with pytest.raises(ValueError, match="slot_carriage"):
        scene_mjcf(parse_scene(text).model)


def test_bench_model_is_the_export():
    """One MJCF writer: the bench's MuJoCo model is the export at the bench's settings."""
    model = load_scene("four_bar").model
    s = compare_mujoco.MujocoSettings(integrator="Euler", rate=500.0, substeps=2)
    assert scene_mjcf(model, s) == scene_mjcf(model, MjcfSettings(
        timestep=0.001, integrator="Euler", carriage_mass=s.inertia_epsilon))
    assert math.isclose(s.timestep, 0.001)


def _plant_scene(tmp_path, gear="", ram=""):
    """The all-kinds scene with actuator dynamics: ``gear`` on the crank, ``ram`` keys on the ram."""
    text = Path(KINDS).read_text()
    text = text.replace("{joint: crank_joint, limit: 20.0}", f"{{joint: crank_joint, limit: 20.0{gear}}}")
    text = text.replace("{joint: ram_slide, limit: 50.0}", f"{{joint: ram_slide, limit: 50.0{ram}}}")
    path = tmp_path / "plant.yaml"
    path.write_text(text)
    return load_scene(str(path))


def _plant_runs(scene, substeps_list, ticks=200):
    """vjm's reference and MuJoCo runs at each substep count, with efforts (1, 3) on the motors."""
    effort = np.array([1.0, 3.0])
    settings = SimulationSettings(closure="exact", rate=1000.0, integrator="dop853",
                                  rtol=1e-12, atol=1e-14)
    sim = Simulator(scene.model, settings, scene.gains, scene.plant)
    sim.set_efforts(effort)
    q_ref = [sim.q.copy()]
    for _ in range(ticks):
        sim.advance()
        q_ref.append(sim.q.copy())
    errors = []
    for substeps in substeps_list:
        ms = compare_mujoco.MujocoSettings(substeps=substeps, **TIGHT)
        with compare_mujoco.MujocoSimulator(scene.model, ms, scene.plant) as mj:
            mj.set_efforts(effort)
            idx = _qpos_index(mj.m, scene.model)
            q = [mj.d.qpos[idx].copy()]
            for _ in range(ticks):
                mj.advance()
                q.append(mj.d.qpos[idx].copy())
        errors.append(np.abs(np.array(q) - np.array(q_ref)).max())
    return errors, mj.m


def test_gear_is_the_motor_gear(tmp_path):
    """A gear of 3 (joint effort = 3 x command): MuJoCo's motor gear, the command bounded by the
    limit; the run agrees with vjm's as without gears (1e-6, test_mujoco_follows_vjm)."""
    scene = _plant_scene(tmp_path, gear=", gear: 3.0")
    (error,), m = _plant_runs(scene, [4])
    assert m.actuator_gear[0, 0] == 3.0 and tuple(m.actuator_ctrlrange[0]) == (-20.0, 20.0)
    assert error < 1e-6, error


def test_lag_and_delay_converge_to_vjm(tmp_path):
    """A first-order lag (20 ms) and a 3 ms delay on the ram: MuJoCo's ``filterexact`` actuator
    and its ``delay`` carry them. vjm holds each tick's mean effort, MuJoCo integrates the lag and
    looks the delayed control up per RK4 stage, so the two differ by a share of a MuJoCo step:
    the difference shrinks with the step (first order: 0.25 ms -> 62.5 us divides it by about 4;
    measured 3.8e-4 -> 9.6e-5 m)."""
    scene = _plant_scene(tmp_path, ram=", time_constant: 0.02, delay: 0.003")
    (coarse, fine), m = _plant_runs(scene, [4, 16])
    ram = 1
    assert m.actuator_dyntype[ram] == mujoco.mjtDyn.mjDYN_FILTEREXACT
    assert m.actuator_dynprm[ram, 0] == 0.02
    assert fine < 0.35 * coarse and fine < 2e-4, (coarse, fine)
