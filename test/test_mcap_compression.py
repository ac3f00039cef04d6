"""Chunks compressed at the recorder's zstd level hold what the ``mcap`` writer's own chunks hold.

The oracle is the pinned ``mcap`` writer's own chunk writing (``Writer.__finalize_chunk``, zstd at
its level 3): at that level the recorder's file is the writer's byte for byte, and at the
recorder's level (:data:`vjm_ros.logs.mcap_block.ZSTD_LEVEL`) every record of the file, chunks
decompressed, is the same except the compressed bytes and the offsets and sizes that follow
from them.
"""

from __future__ import annotations

import dataclasses
import io
import types

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import (
    AttachmentIndex,
    Chunk,
    ChunkIndex,
    Footer,
    MetadataIndex,
    SummaryOffset,
)
from mcap.stream_reader import StreamReader

from vjm_ros.logs import mcap_block, mcap_recorder
from vjm_ros.logs.mcap_block import BlockWriter
from vjm_ros.logs.mcap_recorder import McapRecorder
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator


@pytest.fixture(scope="module")
def run():
    scene = load_scene("four_bar")
    sim = Simulator(scene.model, SimulationSettings(closure="exact"), scene.gains)
    sim.set_efforts(np.full(len(scene.model.actuators), 0.5))
    first = sim.sample()
    blocks = []
    for _ in range(6):
        block = SampleBlock(scene.model, 100)
        sim.advance_block(block, 100)
        blocks.append(block)
    return scene, sim, first, blocks


def write(folder, run, compression="zstd"):
    """The log of ``run`` as ``folder/run.mcap`` (one name: the bag metadata holds it)."""
    scene, sim, first, blocks = run
    folder.mkdir()
    path = folder / "run.mcap"
    with McapRecorder(path, scene.model, sim.describe(), scene.text, chunk_seconds=0.1,
                      compression=compression) as rec:
        rec.write(first)
        for block in blocks:
            rec.write_block(block)
    return path.read_bytes()


@pytest.fixture
def frozen_clocks(monkeypatch):
    monkeypatch.setattr(mcap_recorder, "time",
                        types.SimpleNamespace(monotonic=lambda: 0.0, time_ns=lambda: 7))


def stock_chunks(monkeypatch):
    """Chunks closed by the ``mcap`` writer's own code (zstd level 3)."""
    monkeypatch.delattr(BlockWriter, "_Writer__finalize_chunk")


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_at_the_writers_level_the_file_is_the_writers(run, tmp_path, monkeypatch, frozen_clocks,
                                                      compression):
    monkeypatch.setattr(mcap_block, "ZSTD_LEVEL", 3)
    monkeypatch.setattr(BlockWriter.__init__, "__kwdefaults__", {"zstd_level": 3})
    ours = write(tmp_path / "ours", run, compression)
    stock_chunks(monkeypatch)
    assert ours == write(tmp_path / "stock", run, compression)


def records(data: bytes) -> list:
    """Every record, chunks decompressed, without what depends on the compressed sizes (the
    chunks themselves, their indexes, the file offsets of later records)."""
    out = []
    for r in StreamReader(io.BytesIO(data), skip_magic=False).records:
        if isinstance(r, (Chunk, ChunkIndex, Footer, SummaryOffset)):
            continue
        if isinstance(r, (MetadataIndex, AttachmentIndex)):
            r = dataclasses.replace(r, offset=0)
        out.append(r)
    return out


def test_at_the_recorders_level_the_records_are_the_writers(run, tmp_path, monkeypatch,
                                                            frozen_clocks):
    ours = write(tmp_path / "ours", run)
    stock_chunks(monkeypatch)
    stock = write(tmp_path / "stock", run)
    assert ours != stock
    assert records(ours) == records(stock)
    with open(tmp_path / "ours" / "run.mcap", "rb") as f:  # the seeking reader, CRCs checked
        reader = make_reader(f, validate_crcs=True)
        count = sum(1 for _ in reader.iter_messages())
        assert count == reader.get_summary().statistics.message_count > 0
