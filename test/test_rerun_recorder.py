"""Rerun recorder: a valid .rrd with the mechanism, the series and a blueprint.

Its cost per tick is a benchmark (test/bench_logging.py), not asserted here.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from conftest import four_bar_samples
from rerun.chunk import RrdReader

from vjm_ros.logs.rerun_recorder import RerunRecorder, force_components

RERUN = Path(sys.executable).with_name("rerun")
TICKS = 400


@pytest.fixture(scope="module")
def run():
    return four_bar_samples(TICKS)


def columns(path: Path, entity: str, component: str, timeline: str = "sim_time"):
    """Times (ns) and values of one component of one entity, over all chunks, in time order."""
    times, values = [], []
    for chunk in RrdReader(path).store().stream():
        if str(chunk.entity_path) != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if component not in batch.schema.names:
            continue
        times += batch.column(timeline).cast(pa.int64()).to_pylist()
        values += batch.column(component).to_pylist()
    order = np.argsort(times, kind="stable")
    return [times[i] for i in order], [values[i] for i in order]


def verify(path: Path) -> None:
    out = subprocess.run([RERUN, "rrd", "verify", path], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr


@pytest.fixture(scope="module")
def recording(run, tmp_path_factory):
    scene, sim, samples = run
    path = tmp_path_factory.mktemp("rrd") / "run.rrd"
    with RerunRecorder(path, scene.model, sim.describe(), scene_text=scene.text) as rec:
        for s in samples[:300]:
            rec.write(s)
        rec.note_reset(samples[299].t)
        for s in samples[300:]:
            rec.write(s)
    return path


def test_recording_verifies_and_holds_mechanism_and_series(run, recording):
    scene, _, samples = run
    verify(recording)
    reader = RrdReader(recording)
    assert reader.blueprints(), "a default blueprint is stored with the recording"
    entities = set(reader.store().schema().entity_paths())
    expected = {
        "/mechanism",
        "/mechanism/links",
        "/mechanism/joints",
        "/mechanism/points",
        "/mechanism/forces",
        "/mechanism/traces",
        "/mechanism/cyclograph",
        "/mechanism/ground",
        "/series/joints/position",
        "/series/joints/velocity",
        "/series/constraint_forces",
        "/series/energy",
        "/series/closure_error",
        "/events",
        "/run/settings",
        "/run/scene",
    }
    assert expected <= entities

    times, q = columns(recording, "/series/joints/position", "Scalars:scalars")
    assert len(times) == TICKS and np.all(np.diff(times) > 0)
    assert times[0] == 1_000_000 and times[299] == 300_000_000
    assert times[300] == 300_000_000 + 1_000_000 + 301_000_000  # second episode after a reset
    np.testing.assert_array_equal(np.array(q), np.array([s.q for s in samples]))
    _, energy = columns(recording, "/series/energy", "Scalars:scalars")
    np.testing.assert_array_equal(np.array(energy), np.array([s.energy for s in samples]))
    rows, cols, names = force_components(scene.model)
    assert names == ["tip_pin.x", "tip_pin.y"]
    _, forces = columns(recording, "/series/constraint_forces", "Scalars:scalars")
    np.testing.assert_array_equal(
        np.array(forces), np.array([s.closure_force[rows, cols] for s in samples])
    )

    link_times, strips = columns(recording, "/mechanism/links", "LineStrips2D:strips")
    assert len(link_times) == math.ceil(300 / 10) + math.ceil(100 / 10)
    np.testing.assert_allclose(
        np.array(strips[0], dtype=float), samples[0].segments, rtol=0, atol=1e-6
    )  # positions are stored as float32
    _, events = columns(recording, "/events", "TextLog:text")
    # the line the node publishes on ~/events (the first episode ends at 0.3 s, 1 ms ticks)
    assert events == [["reset: reset to the initial state after t = 0.3 s; simulated time goes on from t = 0.301 s"]]


def test_close_is_idempotent(run, tmp_path):
    scene, sim, samples = run
    path = tmp_path / "x.rrd"
    rec = RerunRecorder(path, scene.model, sim.describe())
    rec.write(samples[0])
    rec.close()
    rec.close()
    with pytest.raises(ValueError, match="closed"):
        rec.write(samples[1])
    verify(path)


def test_columns_are_the_ones_rerun_builds():
    """The component columns built from whole arrays hold what rerun's archetype builders make
    of the same numbers: descriptors, arrow types (the batches' fast path) and values."""
    import rerun as rr

    from vjm_ros.logs import rerun_recorder as rrec

    rng = np.random.default_rng(3)
    rows, n = 7, 3
    segments, xy = rng.normal(size=(rows, n, 2, 2)), rng.normal(size=(rows, 2, 2))
    values = rng.normal(size=(rows, 4))
    flat = xy.reshape(-1, 2)
    arrows = rr.Arrows2D.columns(origins=flat, vectors=flat).partition([2] * rows)
    vectors = [c for c in arrows
               if c.component_descriptor() == rr.Arrows2D.descriptor_vectors()]
    pairs = [
        (rrec._strips(segments),
         rr.LineStrips2D.columns(strips=segments.reshape(-1, 2, 2)).partition([n] * rows)),
        (rrec._points(xy), rr.Points2D.columns(positions=flat).partition([2] * rows)),
        (rrec._points(xy, rr.Arrows2D.descriptor_vectors(), rr.components.Vector2DBatch),
         vectors),
        (rrec._scalars(values), rr.Scalars.columns(scalars=values)),
        (rrec._scalars(values[:, :0]), rr.Scalars.columns(scalars=values[:, :0])),  # no closure
    ]
    for ours, (theirs,) in pairs:
        assert ours.component_descriptor() == theirs.component_descriptor()
        assert ours.as_arrow_array().type == theirs.as_arrow_array().type
        assert ours.as_arrow_array().equals(theirs.as_arrow_array())


def chunk_rows(path: Path, entity: str) -> list[int]:
    """Rows of each chunk of ``entity`` in the file, in the order written (one chunk per send)."""
    return [chunk.num_rows for chunk in RrdReader(path).store().stream()
            if str(chunk.entity_path) == entity and not chunk.is_static]


def test_a_run_of_known_length_sends_equal_shares(run, tmp_path):
    """Told how many samples will come, the recorder evens its batch out: 400 samples at a batch
    of 199 go in two sends of 200, not 199 + 199 + 2 (the last send, a few rows whose chunks
    cost as much as full ones, after the physics has ended). The values are the same."""
    scene, sim, samples = run
    paths = {}
    for told in (None, len(samples)):
        paths[told] = tmp_path / f"told_{told}.rrd"
        with RerunRecorder(paths[told], scene.model, sim.describe(), batch=199,
                           total_samples=told) as rec:
            for s in samples:
                rec.write(s)
    entity = "/series/joints/position"
    assert chunk_rows(paths[None], entity) == [199, 199, 2]
    assert chunk_rows(paths[len(samples)], entity) == [200, 200]
    for path in paths.values():
        verify(path)
        times, values = columns(path, entity, "Scalars:scalars")
        assert len(times) == len(samples)
        np.testing.assert_array_equal(np.array(values), [s.q for s in samples])  # f64, exact


def test_vjm_run_sends_its_rerun_log_in_equal_shares(tmp_path):
    """``vjm run --duration 10 --rrd`` writes 10 001 samples at 1 kHz in two sends, 5001 and
    5000 rows, with no send of a single sample at the close."""
    from vjm_ros.app import cli

    path = tmp_path / "run.rrd"
    code = cli.main(["run", "four_bar", "--duration", "10", "--rrd", str(path), "--json"])
    assert code == 0
    assert chunk_rows(path, "/series/joints/position") == [5001, 5000]
    assert chunk_rows(path, "/series/energy") == [5001, 5000]
