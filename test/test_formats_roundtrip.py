"""``import(export(scene))`` simulates every built-in scene as the scene itself does.

Each built-in scene, and ``test/export_closure_kinds.yaml`` (slider and angle closures, a
prismatic joint, initial rates), is exported (:mod:`vjm_ros.formats.urdf_out`,
:mod:`vjm_ros.formats.mjcf_out`), imported again and run beside the original for 1 s (rk4 at
1 kHz, exact closure). The exports write closures their formats lack (slider, angle) through
carriages of negligible mass, which the import turns back into the closures.

* MJCF: ``qpos`` is the scene's coordinate. The export adds ``inertia_epsilon`` to every inertia
  and gives carriages a mass (MuJoCo needs them); both are set to 1e-15 here, so the file is the
  scene to 1e-15 in its parameters.
* URDF, written with ``zero="initial"`` (the zero pose is the initial state, as Gazebo builds
  closure joints at the pose it loads): a joint position is ``q - q0``. URDF holds no gravity,
  and the scene's plane is the URDF's x-y plane, so the import has none: the imported model is
  run with the original's gravity (its in-plane basis is the original's x and y).

Tolerance: the two runs integrate the same equations from parameters equal to 1e-15, in link
frames placed differently; round-off grows along the motion (five_bar and three_chain amplify it
10-100x per second, docs/design.md section 6), to 2.5e-13 rad or m seen over 1 s (1.6e-12 for
slider_crank's crank, 20 rad from its start: 1e-13 of it); 1e-12 times the largest coordinate
(at least 1) bounds it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vjm_ros.core.model import Model
from vjm_ros.formats.mjcf_out import MjcfSettings, scene_mjcf
from vjm_ros.formats.urdf_out import scene_urdf
from vjm_ros.scene.loader import builtin_scenes, load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

SCENES = [*builtin_scenes(), str(Path(__file__).resolve().parent / "export_closure_kinds.yaml")]
TOLERANCE = 1e-12


def _run(model, scene, seconds: float = 1.0) -> np.ndarray:
    sim = Simulator(model, SimulationSettings(integrator="rk4", closure="exact"), scene.gains,
                    scene.plant)
    out = []
    for _ in range(int(round(seconds * 1000))):
        sim.advance()
        out.append(sim.q.copy())
    return np.array(out)


def _compare(original, imported_model, imported, offset) -> None:
    model = original.model
    idx = [imported_model.joint_names.index(j) for j in model.joint_names]
    assert sorted(imported_model.closure_names) == sorted(model.closure_names)
    ours, theirs = _run(imported_model, imported)[:, idx] + offset, _run(model, original)
    assert np.max(np.ptp(theirs, axis=0)) > 0.01  # it moves (rad or m)
    # round-off scales with the coordinates: slider_crank's crank turns 20 rad in the second
    scale = max(1.0, float(np.max(np.abs(theirs))))
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=TOLERANCE * scale)


@pytest.mark.parametrize("scene", SCENES, ids=lambda s: Path(s).stem)
def test_mjcf_round_trip(scene, tmp_path):
    pytest.importorskip("mujoco")
    original = load_scene(scene)
    path = tmp_path / "model.xml"
    path.write_text(scene_mjcf(original.model,
                               MjcfSettings(inertia_epsilon=1e-15, carriage_mass=1e-15)))
    imported = load_scene(path)
    _compare(original, imported.model, imported, 0.0)


@pytest.mark.parametrize("scene", SCENES, ids=lambda s: Path(s).stem)
def test_urdf_round_trip(scene, tmp_path):
    original = load_scene(scene)
    path = tmp_path / "model.urdf"
    path.write_text(scene_urdf(original.model, zero="initial"))
    imported = load_scene(path)
    m = imported.model
    assert m.gravity.tolist() == [0.0, 0.0]  # URDF holds none
    with_gravity = Model.build(m.name, m.chains, m.links, m.joints, m.closures, m.actuators,
                               m.points, tuple(original.model.gravity))
    _compare(original, with_gravity, imported, original.model.initial_state()[0])
