"""Cost of importing a 20-link model (target: under 1 s per import) and of running it.

Run with ``python -m pytest -m bench test/bench_import.py --benchmark-enable -p no:cacheprovider``
(without ``--benchmark-enable`` each case runs once as a smoke test, and the targets are not
judged). The model: two legs of ten links each, from ground pivots at x = 0 and x = 1 m, straight
along 45 and 135 degrees so that their tips meet at (0.5, 0.5) m and are pinned, written in each
format the way its community writes it (SDFormat 1.7 poses relative to the joints, a URDF tree
closed in ``<gazebo>``, MJCF nested bodies of capsules and a ``connect`` equality).

``test_imported_scene_runs_as_fast_as_the_hand_written`` sets the imported five-bar's ticks
against the same mechanism written by hand: the same kernels run both, so the ratio is 1 up to
the machine's noise (compare within one run: the machine is shared).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from model_runs import MODELS

from vjm_ros.formats.importing import import_model
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

pytestmark = pytest.mark.bench

LINKS_PER_LEG = 10
TARGET_IMPORT = 1.0  # s, per import of the 20-link model
STEP = math.sqrt(0.5) / LINKS_PER_LEG  # m, one link


def _legs():
    """``(leg, k, x, y, angle)`` of every link's origin, base first."""
    for leg, (x0, angle) in (("l", (0.0, math.pi / 4)), ("r", (1.0, 3 * math.pi / 4))):
        for k in range(LINKS_PER_LEG):
            yield leg, k, x0 + k * STEP * math.cos(angle), k * STEP * math.sin(angle), angle


def sdformat_text() -> str:
    parts = ['<sdf version="1.7"><model name="ladder">']
    for leg, k, x, y, a in _legs():
        name, parent = f"{leg}{k}", (f"{leg}{k - 1}" if k else "world")
        pose = (f'<pose relative_to="__model__">{x!r} {y!r} 0 0 0 {a!r}</pose>' if k == 0 else
                f'<pose relative_to="{parent}">{STEP!r} 0 0 0 0 0</pose>')
        parts.append(f'<joint name="j_{name}" type="revolute"><parent>{parent}</parent>'
                     f'<child>{name}</child>{pose}<axis><xyz>0 0 1</xyz></axis></joint>')
        parts.append(f'<link name="{name}"><pose relative_to="j_{name}"/><inertial><pose>'
                     f'{STEP / 2!r} 0 0 0 0 0</pose><mass>1</mass><inertia><ixx>1e-4</ixx>'
                     '<iyy>1e-3</iyy><izz>1e-3</izz></inertia></inertial></link>')
    parts.append('<joint name="pin" type="revolute"><pose relative_to="__model__">0.5 0.5 0 0 0 '
                 f'0</pose><parent>l{LINKS_PER_LEG - 1}</parent><child>r{LINKS_PER_LEG - 1}'
                 '</child><axis><xyz>0 0 1</xyz></axis></joint></model></sdf>')
    return "\n".join(parts)


def urdf_text() -> str:
    parts = ['<robot name="ladder"><link name="base"/>']
    for leg, k, x, y, a in _legs():
        name, parent = f"{leg}{k}", (f"{leg}{k - 1}" if k else "base")
        origin = f'xyz="{x!r} {y!r} 0" rpy="0 0 {a!r}"' if k == 0 else f'xyz="{STEP!r} 0 0"'
        parts.append(f'<link name="{name}"><inertial><origin xyz="{STEP / 2!r} 0 0"/>'
                     '<mass value="1"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-3" iyz="0" '
                     'izz="1e-3"/></inertial></link>')
        parts.append(f'<joint name="j_{name}" type="continuous"><parent link="{parent}"/>'
                     f'<child link="{name}"/><origin {origin}/><axis xyz="0 0 1"/></joint>')
    parts.append(f'<gazebo><joint name="pin" type="revolute"><pose>{STEP!r} 0 0 0 0 0</pose>'
                 f'<parent>l{LINKS_PER_LEG - 1}</parent><child>r{LINKS_PER_LEG - 1}</child>'
                 '<axis><xyz>0 0 1</xyz></axis></joint></gazebo></robot>')
    return "\n".join(parts)


def mjcf_text() -> str:
    parts = ['<mujoco model="ladder"><compiler angle="radian"/><worldbody>']
    for leg, k, x, y, a in _legs():
        pos = f'pos="{x!r} {y!r} 0" euler="0 0 {a!r}"' if k == 0 else f'pos="{STEP!r} 0 0"'
        parts.append(f'<body name="{leg}{k}" {pos}><joint name="j_{leg}{k}" axis="0 0 1"/>'
                     f'<geom type="capsule" size="0.005" fromto="0 0 0 {STEP!r} 0 0"/>')
        if k == LINKS_PER_LEG - 1:
            parts.append("</body>" * LINKS_PER_LEG)
    parts.append(f'</worldbody><equality><connect name="pin" body1="l{LINKS_PER_LEG - 1}" '
                 f'body2="r{LINKS_PER_LEG - 1}" anchor="{STEP!r} 0 0"/></equality></mujoco>')
    return "\n".join(parts)


@pytest.mark.parametrize("suffix, text", [(".sdf", sdformat_text), (".urdf", urdf_text),
                                          (".xml", mjcf_text)])
def test_import_of_a_20_link_model(benchmark, tmp_path, suffix, text):
    path = tmp_path / f"ladder{suffix}"
    path.write_text(text())
    imported = benchmark.pedantic(import_model, args=(path,), rounds=5, iterations=1)
    links = sum(len(c["links"]) for c in imported.document["chains"])
    assert links == 2 * LINKS_PER_LEG
    assert [c["name"] for c in imported.document["closures"]] == ["pin"]
    if benchmark.enabled:
        mean = benchmark.stats.stats.mean
        print(f"import of {path.name}: {mean * 1e3:.0f} ms")
        assert mean < TARGET_IMPORT


@pytest.mark.parametrize("which", ["imported", "hand_written"])
def test_imported_scene_runs_as_fast_as_the_hand_written(benchmark, which):
    scene = load_scene(MODELS / ("five_bar.xml" if which == "imported" else "five_bar_xz.yaml"))
    sim = Simulator(scene.model, SimulationSettings(integrator="rk4", closure="exact"),
                    scene.gains, scene.plant)
    benchmark.group = "five_bar tick, imported vs hand-written"
    benchmark.pedantic(sim.advance, setup=sim.reset, rounds=500, iterations=1)
    assert np.all(np.isfinite(sim.q))
