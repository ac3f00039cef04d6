"""The thesis figure set: six PNG files that carry the run's data."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from matplotlib.image import imread

from vjm_ros.app.plotting import (
    FIGURE_NAMES,
    absolute_rates,
    chrono_cyclograph_figure,
    energy_figure,
    kinematics_figure,
    write_figures,
)
from vjm_ros.scene.loader import builtin_scenes, load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator
from vjm_ros.sim.trajectory import Trajectory

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def simulate(scene: str, steps: int) -> Trajectory:
    """Penalty-closure run of a built-in scene, one sample per control tick."""
    sc = load_scene(scene)
    sim = Simulator(sc.model, SimulationSettings(closure="penalty"), sc.gains)
    traj = Trajectory(sc.model)
    traj.append(sim.sample())
    for _ in range(steps):
        sim.advance()
        traj.append(sim.sample())
    return traj


@pytest.fixture(scope="module")
def four_bar() -> Trajectory:
    return simulate("four_bar", 1500)


def png_size(data: bytes) -> tuple[int, int]:
    """Width and height from the IHDR chunk that must follow the PNG signature."""
    assert data[:8] == PNG_SIGNATURE
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_writes_six_valid_pngs(four_bar, tmp_path):
    out = tmp_path / "figures"  # not yet there: write_figures creates it
    paths = write_figures(four_bar, out, dpi=80)
    assert [p.name for p in paths] == [f"{stem}.png" for stem in FIGURE_NAMES]
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in paths)
    for path in paths:
        data = path.read_bytes()
        width, height = png_size(data)
        assert 400 <= width <= 2000 and 250 <= height <= 2000, (path.name, width, height)
        assert len(data) > 10_000, path.name
        pixels = imread(path)  # decodes the whole file
        assert pixels.shape[:2] == (height, width)
        assert np.ptp(pixels[..., :3]) > 0.5, f"{path.name} is blank"


def test_energy_axis_holds_the_total_energy(four_bar):
    total = four_bar["energy"][:, 3]
    fig = energy_figure(four_bar, "four_bar")
    (ax,) = fig.axes
    lo, hi = ax.get_ylim()
    assert lo <= total.min() and total.max() <= hi
    assert "four_bar" in fig.get_suptitle()
    labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert {"kinetic T", "potential V", "total"} <= set(labels)


def test_chrono_cyclograph_shows_every_tip_position(four_bar):
    fig = chrono_cyclograph_figure(four_bar, "four_bar")
    fig.canvas.draw()  # applies the equal aspect ratio to the limits
    ax = fig.axes[0]
    assert ax.get_aspect() == 1.0
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    names = [p.name for p in four_bar.model.points]
    for chain in four_bar.model.chains:
        tip = four_bar["points"][:, names.index(f"{chain.name}_tip")]
        assert x0 <= tip[:, 0].min() and tip[:, 0].max() <= x1
        assert y0 <= tip[:, 1].min() and tip[:, 1].max() <= y1
    # every link end of the run lies in view as well
    ends = four_bar["segments"].reshape(-1, 2)
    assert x0 <= ends[:, 0].min() and ends[:, 0].max() <= x1
    assert y0 <= ends[:, 1].min() and ends[:, 1].max() <= y1


def test_absolute_rates_are_the_derivative_of_the_link_angles(four_bar):
    t, theta = four_bar["t"], four_bar["theta"]
    omega = absolute_rates(four_bar.model, four_bar["qd"])
    alpha = absolute_rates(four_bar.model, four_bar["qdd"])
    inner = slice(5, -5)  # central differences; skip the penalty transient at the ends
    dtheta = np.gradient(theta, t, axis=0)
    domega = np.gradient(omega, t, axis=0)
    assert np.allclose(dtheta[inner], omega[inner], atol=1e-3 * np.abs(omega).max())
    assert np.allclose(domega[50:-5], alpha[50:-5], atol=2e-2 * np.abs(alpha).max())


@pytest.mark.skipif("double_slider" not in builtin_scenes(), reason="no double_slider scene")
def test_prismatic_joints_get_a_linear_panel(tmp_path):
    traj = simulate("double_slider", 300)
    fig = kinematics_figure(traj, "double_slider", "displacements")
    angular, linear = fig.axes[:2]
    assert "(rad)" in angular.get_ylabel() and "(m)" in linear.get_ylabel()
    prismatic = [j.name for j in traj.model.joints if j.kind == "prismatic"]
    assert [line.get_label() for line in linear.get_lines()] == prismatic
    assert len(write_figures(traj, tmp_path, title="double slider", dpi=60)) == 6


def test_empty_trajectory_is_refused(four_bar, tmp_path):
    with pytest.raises(ValueError, match="empty"):
        write_figures(Trajectory(four_bar.model), tmp_path)
