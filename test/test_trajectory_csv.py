"""``trajectory.csv`` written in batches gives the text of a row-by-row :mod:`csv` writer.

The oracle is the writer the CSV had before it was batched: ``csv.writer`` with
``repr(float(x))`` per value, one row at a time. Equality is exact (the file is compared as bytes).
"""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest

from vjm_ros.scene.loader import load_scene
from vjm_ros.sim import trajectory
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import SampleBlock, Simulator
from vjm_ros.sim.trajectory import Trajectory, csv_rows


def row_by_row(columns: list[str], table: np.ndarray) -> bytes:
    """The oracle: one ``csv.writer.writerow`` per row, ``repr(float(x))`` per value."""
    fh = io.StringIO(newline="")
    w = csv.writer(fh)
    w.writerow(columns)
    for row in table:
        w.writerow([repr(float(x)) for x in row])
    return fh.getvalue().encode()


AWKWARD = [0.0, -0.0, 1.0, -1.5, 1e-5, 1.2345e-4, 0.1 + 0.2, 1e16, 123456789012345678.0,
           5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, np.pi, -np.e, 1 / 3,
           float("nan"), float("inf"), float("-inf")]


@pytest.mark.parametrize("columns", [1, 3, len(AWKWARD)])
def test_rows_equal_the_csv_writer_on_awkward_values(columns):
    rng = np.random.default_rng(columns)
    table = rng.choice(np.array(AWKWARD), size=(40, columns))
    table[:, 0] = rng.standard_normal(40) * 10.0 ** rng.integers(-20, 20, 40)
    text = ",".join(f"c{i}" for i in range(columns)) + "\r\n" + csv_rows(table)
    assert text.encode() == row_by_row([f"c{i}" for i in range(columns)], table)


def test_no_rows_is_no_text():
    assert csv_rows(np.zeros((0, 4))) == ""


@pytest.mark.parametrize("scene", ["four_bar", "double_slider", "three_chain"])
def test_written_file_equals_the_row_by_row_writer(scene, tmp_path, monkeypatch):
    """Real runs (slider and several closures), across several batches of rows."""
    sc = load_scene(scene)
    sim = Simulator(sc.model, SimulationSettings(closure="exact"), sc.gains)
    traj = Trajectory(sc.model)
    traj.append(sim.sample())
    block = SampleBlock(sc.model, 50)
    for _ in range(3):
        sim.advance_block(block, 50)
        traj.extend(block)
    monkeypatch.setattr(trajectory, "CSV_BATCH_ROWS", 64)  # 151 rows: three batches
    path = traj.write_csv(tmp_path / "trajectory.csv")
    assert path.read_bytes() == row_by_row(traj.columns(), traj.table())
