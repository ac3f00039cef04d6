"""Logs written in blocks of any size (``write_block``: ``vjm run``'s blocks of up to 1000
ticks, the node's of up to 100) hold exactly what the same ticks written one at a time
(``write``, a block of one row) hold, and the MCAP records are rosbags' bytes.

Oracles: the same ticks in blocks of one row, for everything that depends on how ticks are split
into blocks (chunks, batches, sequence numbers, decimation of the markers and the geometry), and
rosbags' serializer for the MCAP records themselves (the rerun recording's content is held to
rerun's own reader in test_rerun_recorder.py). Scenes: the four-bar, a slider closure
(double_slider), two hinge closures meeting at one pin (three_chain) and a hinge plus an angle
closure (the four-bar with its crank locked), so every closure kind and several closures at once
are covered. Equality is exact: the same times and the same doubles.
"""

from __future__ import annotations

import types
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from vjm_ros.logs import mcap_recorder
from vjm_ros.logs.mcap_recorder import McapRecorder
from vjm_ros.logs.rerun_recorder import RerunRecorder
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator

LOCKED_CRANK = """  - name: crank_lock
    type: angle
    link: crank
    target: {ground: true}
actuators:"""
BLOCKS = (50, 50, 37, 50, 13, 1, 3, 9)
"""Rows of the blocks written: uneven, so batches and decimation fall mid-block, and short, so
that blocks with a single marker or none are written too (the live node's blocks)."""


def load(name: str, tmp_path: Path):
    if name != "angle_closure":
        return load_scene(name)
    text = load_scene("four_bar").text
    path = tmp_path / "angle_closure.yaml"
    path.write_text(text.replace("actuators:", LOCKED_CRANK, 1))
    scene = load_scene(path)
    assert [c.kind for c in scene.model.closures] == ["hinge", "angle"]
    return scene


SCENES = ["four_bar", "double_slider", "three_chain", "angle_closure"]


@pytest.fixture(params=SCENES)
def run(request, tmp_path):
    """``(scene, simulator, first sample, blocks)``: the blocks of :data:`BLOCKS`, each kept."""
    scene = load(request.param, tmp_path)
    sim = Simulator(scene.model, SimulationSettings(closure="exact"), scene.gains)
    if scene.model.actuators:
        sim.set_efforts(np.full(len(scene.model.actuators), 0.5))
    first = sim.sample()
    blocks = []
    for rows in BLOCKS:
        block = SampleBlock(scene.model, 50)
        sim.advance_block(block, rows)
        blocks.append(block)
    return scene, sim, first, blocks


def write_both(make, first, blocks, reset_after: int = 2):
    """Write the ticks sample by sample into ``make("samples")`` and block by block into
    ``make("blocks")``, with a reset after block ``reset_after``."""
    with make("samples") as rec:
        rec.write(first)
        for b, block in enumerate(blocks):
            for i in range(len(block)):
                rec.write(block.sample(i))
            if b == reset_after:
                rec.note_reset(float(block.t[len(block) - 1]))
    with make("blocks") as rec:
        rec.write(first)
        for b, block in enumerate(blocks):
            rec.write_block(block)
            if b == reset_after:
                rec.note_reset(float(block.t[len(block) - 1]))


# ---------------------------------------------------------------- MCAP
@pytest.mark.parametrize("marker_every", [10, 7, 0])
def test_mcap_blocks_write_the_same_file(run, tmp_path, monkeypatch, marker_every):
    """The whole file, byte for byte: every message's payload, time, sequence and order, the
    chunks (closed after the same ticks), message indexes, statistics and bag metadata.

    The recorder's clocks are frozen (the attachment's creation time and the wall-time condition
    of a chunk are the only things that depend on them); chunks of 30 ms put several chunk ends
    inside each block.
    """
    scene, sim, first, blocks = run
    monkeypatch.setattr(mcap_recorder, "time",
                        types.SimpleNamespace(monotonic=lambda: 0.0, time_ns=lambda: 7))

    def make(name):
        (tmp_path / name).mkdir()
        return McapRecorder(tmp_path / name / "run.mcap", scene.model, sim.describe(),
                            scene.text, marker_every=marker_every, chunk_seconds=0.03)

    write_both(make, first, blocks)
    by_samples = (tmp_path / "samples" / "run.mcap").read_bytes()
    assert (tmp_path / "blocks" / "run.mcap").read_bytes() == by_samples


def test_after_reserve_mcap_blocks_write_into_the_same_memory(run, tmp_path):
    """``reserve`` sizes the encoder's and the chunk's buffers for the run's blocks (markers
    included, laid out from the first sample): writing the blocks then replaces none of them,
    so no memory is mapped and cleared mid-run. Without ``reserve`` the first block does."""
    scene, sim, first, blocks = run

    def buffers(rec) -> list:
        return [rec._block_encoder._table, rec._block_encoder._out, rec._writer._builder.buffer]

    for reserved in (True, False):
        with McapRecorder(tmp_path / f"{reserved}.mcap", scene.model, sim.describe(),
                          scene.text, chunk_seconds=1.0) as rec:
            rec.write(first)
            if reserved:
                rec.reserve(max(BLOCKS))
            held = buffers(rec)
            for block in blocks:
                rec.write_block(block)
            kept = [now is before for now, before in zip(buffers(rec), held, strict=True)]
        assert kept == [reserved] * 3



def test_mcap_block_records_are_rosbags_serialization(run, tmp_path):
    """Every per-tick message (and every markers message) of a log written block by block is
    what rosbags' serializer writes for that tick's message, byte for byte, at the tick's log
    time. Oracle: rosbags (a third-party serializer, fed by the message dicts of
    :mod:`vjm_ros.logs.messages`)."""
    from mcap.reader import make_reader
    from rosbags_cdr import serialize

    from vjm_ros.logs import messages

    scene, sim, first, blocks = run
    model, path = scene.model, tmp_path / "run.mcap"
    samples = [first] + [block.sample(i) for block in blocks for i in range(len(block))]
    with McapRecorder(path, model, sim.describe(), scene.text, marker_every=7,
                      chunk_seconds=0.03) as rec:
        rec.write(first)
        for block in blocks:
            rec.write_block(block)
    topics = messages.Topics()
    expected = {
        topics.joint_states: lambda s, ns: (
            messages.JOINT_STATE, messages.joint_state(model.joint_names, s, ns)),
        topics.constraint_forces: lambda s, ns: (
            messages.FLOAT64_MULTI_ARRAY, messages.constraint_forces(model.force_names, s)),
        topics.energy: lambda s, ns: (messages.FLOAT64_MULTI_ARRAY, messages.energy(s)),
        topics.clock: lambda s, ns: (messages.CLOCK, messages.clock(ns)),
        topics.markers: lambda s, ns: (messages.MARKER_ARRAY, messages.markers(s, ns)),
    }
    for i, name in enumerate(model.force_names):
        expected[topics.wrench(name)] = lambda s, ns, i=i: (
            messages.WRENCH_STAMPED, messages.wrench(s, i, ns))
    seen: dict[str, int] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if channel.topic not in expected:
                continue  # the events
            k = seen.get(channel.topic, 0)
            seen[channel.topic] = k + 1
            step = 7 if channel.topic == topics.markers else 1
            type_name, value = expected[channel.topic](samples[k * step], message.log_time)
            assert message.data == serialize(type_name, value), (channel.topic, k)
    assert seen[topics.joint_states] == len(samples)
    assert seen[topics.markers] == -(-len(samples) // 7)

# ---------------------------------------------------------------- rerun
def rrd_chunks(path: Path) -> list[tuple]:
    """Every temporal chunk of a recording as (entity, times, {component: values}), in order."""
    out = []
    for chunk in RrdReader(path).store().stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        times = batch.column("sim_time").cast(pa.int64()).to_pylist()
        values = {name: batch.column(name).to_pylist() for name in batch.schema.names
                  if ":" in name}
        out.append((str(chunk.entity_path), times, values))
    return out


def test_rerun_blocks_equal_samples(run, tmp_path):
    scene, sim, first, blocks = run

    def make(name):
        return RerunRecorder(tmp_path / f"{name}.rrd", scene.model, sim.describe(), batch=64,
                             batch_seconds=1e9, recording_id="same")

    write_both(make, first, blocks)
    by_samples, by_blocks = rrd_chunks(tmp_path / "samples.rrd"), rrd_chunks(tmp_path / "blocks.rrd")
    assert len(by_samples) > 10  # several batches of series and of geometry
    assert {c[0] for c in by_samples} >= {"/series/joints/position", "/mechanism/links"}
    assert by_blocks == by_samples
