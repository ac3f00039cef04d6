"""``trajectory.csv`` written in batches gives the text of a row-by-row :mod:`csv` writer.

The oracle is the writer the CSV had before it was batched: ``csv.writer`` with
``repr(float(x))`` per value, one row at a time. Equality is exact (the file is compared as bytes),
for the compiled number formatting (:mod:`vjm_ros.sim.float_text`) and for the ``repr`` path used
without numba.
"""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest

from vjm_ros.scene.loader import load_scene
from vjm_ros.sim import float_text, trajectory
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator
from vjm_ros.sim.trajectory import CsvStream, Trajectory


def csv_rows(table: np.ndarray) -> str:
    """CSV text of the rows of ``table`` as ``trajectory.csv`` formats them: compiled
    (:func:`vjm_ros.sim.float_text.csv_bytes`) or by ``repr``, as the trajectory's writer picks."""
    if len(table) == 0:
        return ""
    if trajectory._compiled_writer(len(table)):
        return float_text.csv_bytes(table).decode("ascii")
    return trajectory._repr_bytes(table).decode("ascii")


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


@pytest.fixture(params=["compiled", "repr"])
def formatting(request, monkeypatch):
    """Both ways of formatting the numbers (the compiled one only where numba is installed)."""
    if request.param == "compiled" and not float_text.COMPILED:
        pytest.skip("numba is not installed")
    monkeypatch.setattr(float_text, "COMPILED", request.param == "compiled")
    return request.param


@pytest.mark.parametrize("columns", [1, 3, len(AWKWARD)])
def test_rows_equal_the_csv_writer_on_awkward_values(columns, formatting):
    rng = np.random.default_rng(columns)
    table = rng.choice(np.array(AWKWARD), size=(40, columns))
    table[:, 0] = rng.standard_normal(40) * 10.0 ** rng.integers(-20, 20, 40)
    text = ",".join(f"c{i}" for i in range(columns)) + "\r\n" + csv_rows(table)
    assert text.encode() == row_by_row([f"c{i}" for i in range(columns)], table)


def test_no_rows_is_no_text():
    assert csv_rows(np.zeros((0, 4))) == ""


@pytest.mark.parametrize("scene", ["four_bar", "double_slider", "three_chain"])
def test_written_file_equals_the_row_by_row_writer(scene, tmp_path, monkeypatch, formatting):
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
    path = tmp_path / "trajectory.csv"
    with CsvStream(traj, path) as stream:
        stream.catch_up()
    assert path.read_bytes() == row_by_row(traj.columns(), traj.table())


def random_doubles(rng: np.random.Generator, n: int) -> np.ndarray:
    """Doubles of every kind: random bit patterns (all exponents, subnormals, NaN payloads),
    normals over 60 decades, integers up to 1e17 and tick times."""
    return np.concatenate((
        rng.integers(0, 2**64, n, dtype=np.uint64).view(np.float64),
        rng.standard_normal(n) * 10.0 ** rng.integers(-30, 30, n),
        rng.integers(-10**17, 10**17, n).astype(float),
        np.arange(n) * 1e-3,
        np.nextafter(10.0 ** rng.integers(-25, 25, n), np.inf),  # next to powers of ten
        2.0 ** rng.integers(-1074, 1024, n),  # powers of two: the uneven interval below them
    ))


@pytest.mark.skipif(not float_text.COMPILED, reason="numba is not installed")
@pytest.mark.parametrize("seed", [0, 1])
def test_compiled_formatting_equals_repr_on_random_doubles(seed):
    """Ryu's digits and Python's formatting rules against ``repr`` itself, value by value
    (6 x 50 000 doubles per seed; ``python -m`` runs of millions agreed as well)."""
    values = random_doubles(np.random.default_rng(seed), 50_000)
    text = float_text.csv_bytes(values[:, None]).decode("ascii")
    assert text.split("\r\n")[:-1] == [repr(float(v)) for v in values]


@pytest.mark.skipif(not float_text.COMPILED, reason="numba is not installed")
def test_compiled_formatting_of_edges():
    edges = [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 2.225073858507201e-308,
             1.7976931348623157e308, 1e-4, 9.999999999999999e-05, 1e-5, 1e15, 1e16,
             9999999999999998.0, 1e22, 1e23, 9007199254740993.0, 0.1, 0.5, 1.0, 10.0, 100.0,
             123.0, 1e100, 1e-100, 1e-300, 1e300, float("nan"), -float("nan"), float("inf"),
             -float("inf")]
    text = float_text.csv_bytes(np.array(edges)[None, :]).decode("ascii")
    assert text == ",".join(repr(v) for v in edges) + "\r\n"
