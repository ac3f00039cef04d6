"""Joint sensors (``sensors.joint_states``): noise statistics, bias, quantization, delay, seeds.

Oracles: the exact state the simulator reports beside each measurement; the sample mean and
standard deviation of the noise against the scene's sigma over 1e5 ticks; quantization against
``r * floor(x / r + 1/2)`` written here per value; the delay against the exact state of earlier
ticks. No ROS here (the node's topics: ``test_ros_sensors.py``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from vjm_ros.core.errors import ConfigurationError, SceneError
from vjm_ros.scene.loader import parse_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator

DEG = math.pi / 180.0


def scene_text(sensors: str, rate: float = 1000.0) -> str:
    """A two-link open chain (revolute, then prismatic) swinging under gravity, with the given
    ``sensors.joint_states`` entries (angles in degrees)."""
    return f"""\
name: sensed
units: {{angle: degrees}}
chains:
  - name: arm
    links:
      - {{name: upper, length: 0.6, mass: 1.0, inertia: 0.03, com: [0.3, 0.0],
         joint: {{name: shoulder, type: revolute, angle: -40.0}}}}
      - {{name: slider, length: 0.3, mass: 0.5, inertia: 0.004, com: [0.15, 0.0],
         joint: {{name: extension, type: prismatic, slide: 0.05, velocity: 0.2}}}}
actuators:
  - {{joint: shoulder, limit: 20.0}}
  - {{joint: extension, limit: 50.0}}
sensors:
  joint_states:
{sensors}
defaults: {{integrator: rk4, rate: {rate:g}, duration: 1}}
"""


def simulate(text: str, ticks: int, block: int = 1000, efforts=(0.5, -1.0)):
    """Measured and exact states of ``ticks`` ticks in blocks of ``block`` (start row included).

    Returns
    -------
    measured, exact : ndarray, shape (ticks + 1, 3, n)
    """
    scene = parse_scene(text)
    sim = Simulator(scene.model, SimulationSettings(), scene.gains, scene.plant)
    first = sim.sample()  # measured at the start, before any command
    sim.set_efforts(list(efforts))
    measured, exact = [first.measured[None]], [np.stack((first.q, first.qd, first.effort))[None]]
    rows = SampleBlock(sim.model, block)
    while sim.ticks < ticks:
        sim.advance_block(rows, min(block, ticks - sim.ticks))
        k = rows.rows
        effort = np.broadcast_to(rows.effort, (k, sim.model.n))
        measured.append(rows.measured[:k].copy())
        exact.append(np.stack((rows.q[:k], rows.qd[:k], effort), axis=1))
    return np.concatenate(measured), np.concatenate(exact)


def test_noise_and_bias_statistics_over_1e5_ticks():
    """Per field and joint, ``measured - exact - bias`` has mean 0 and standard deviation sigma
    within 3 % of sigma over 1e5 ticks. The estimates' own spread is sigma / sqrt(N) = 0.3 % of
    sigma for the mean and sigma / sqrt(2 N) = 0.22 % for the deviation, so 3 % is a 10-sigma
    bound: a wrong unit (degrees as radians: x57), a missing noise term or a sigma applied
    twice fails it, chance does not."""
    text = scene_text("""\
    position: {noise: 0.2, bias: 1.5}
    velocity: {noise: 3.0, bias: -0.5}
    effort: {noise: 0.25, bias: 0.1}
    seed: 11""")
    measured, exact = simulate(text, 100_000)
    sigma = np.array([[0.2 * DEG, 0.2], [3.0 * DEG, 3.0], [0.25, 0.25]])
    bias = np.array([[1.5 * DEG, 1.5], [-0.5 * DEG, -0.5], [0.1, 0.1]])
    residual = measured - exact - bias
    assert len(residual) == 100_001
    assert np.all(np.abs(residual.mean(axis=0)) < 0.03 * sigma)
    assert np.all(np.abs(residual.std(axis=0) / sigma - 1.0) < 0.03)
    # independent draws: neighbouring ticks and neighbouring channels are uncorrelated
    flat = (residual / sigma).reshape(len(residual), -1)
    lag1 = np.mean(flat[1:] * flat[:-1], axis=0)
    assert np.all(np.abs(lag1) < 0.03)
    assert np.all(np.abs(np.corrcoef(flat.T) - np.eye(6)) < 0.03)


def test_quantization_is_exact():
    """Noise-free measurements are the exact values rounded to the nearest multiple of the
    resolution (``r * floor(x / r + 1/2)``, computed here value by value), never more than half
    a step away, along a swinging motion."""
    text = scene_text("""\
    position: {resolution: 0.05}
    velocity: {resolution: 0.5, bias: 0.2}
    effort: {resolution: 0.01}""")
    measured, exact = simulate(text, 2000, efforts=(0.123456, -0.987654))
    step = np.array([[0.05 * DEG, 0.05], [0.5 * DEG, 0.5], [0.01, 0.01]])
    shift = np.array([[0.0, 0.0], [0.2 * DEG, 0.2], [0.0, 0.0]])
    x = exact + shift
    oracle = np.vectorize(lambda v, r: r * math.floor(v / r + 0.5))(x, step)
    assert np.array_equal(measured, oracle)
    assert np.all(np.abs(measured - x) <= step / 2 * (1 + 1e-12))
    assert len(np.unique(measured[:, 0, 0])) > 20  # the motion crosses many steps


def test_delay_shows_the_state_of_whole_ticks_before():
    text = scene_text("    delay: 0.004")
    measured, exact = simulate(text, 500)
    assert np.array_equal(measured[4:], exact[:-4])
    assert np.array_equal(measured[:4], np.repeat(exact[:1], 4, axis=0))  # the start state


def test_the_same_seed_gives_the_same_stream_ticked_or_in_blocks():
    """The stream depends on the seed only: tick by tick (the node) and in blocks (``vjm
    run``) alike, and again after a reset; another seed gives another stream."""
    noisy = """\
    position: {noise: 0.1, resolution: 0.01}
    velocity: {noise: 1.0}
    effort: {noise: 0.2}
    delay: 0.002
    seed: 2024"""
    by_block, exact = simulate(scene_text(noisy), 600, block=250)
    by_tick, exact_tick = simulate(scene_text(noisy), 600, block=1)
    assert np.array_equal(by_block, by_tick) and np.array_equal(exact, exact_tick)
    other, _ = simulate(scene_text(noisy.replace("2024", "2025")), 600)
    assert not np.any(other[1:, 1] == by_block[1:, 1])

    scene = parse_scene(scene_text(noisy))
    sim = Simulator(scene.model, SimulationSettings(), scene.gains, scene.plant)
    sim.set_efforts([0.5, -1.0])
    start = sim.measured.copy()
    first = [sim.advance() or sim.measured.copy() for _ in range(50)]
    sim.reset()
    sim.set_efforts([0.5, -1.0])
    assert np.array_equal(sim.measured, start)
    again = [sim.advance() or sim.measured.copy() for _ in range(50)]
    assert np.array_equal(first, again)
    assert np.array_equal(np.array(first), by_block[1:51])


def test_a_scene_without_sensors_measures_nothing():
    scene = parse_scene(scene_text("    seed: 1").replace(
        "sensors:\n  joint_states:\n    seed: 1\n", ""))
    sim = Simulator(scene.model, SimulationSettings(), scene.gains, scene.plant)
    sim.advance()
    block = SampleBlock(sim.model, 10)
    sim.advance_block(block, 10)
    assert sim.sensors is None and sim.measured is None and block.measured is None
    assert sim.sample().measured is None


@pytest.mark.parametrize("sensors, key, expected", [
    ("    position: {noise: -0.1}", "sensors.joint_states.position.noise", "a number >= 0"),
    ("    effort: {resolution: -1.0}", "sensors.joint_states.effort.resolution",
     "a number >= 0"),
    ("    velocity: {bias: fast}", "sensors.joint_states.velocity.bias", "a number"),
    ("    position: {sigma: 0.1}", "sensors.joint_states.position.sigma", "one of the keys"),
    ("    acceleration: {noise: 0.1}", "sensors.joint_states.acceleration", "one of the keys"),
    ("    seed: -1", "sensors.joint_states.seed", "a whole number from 0"),
    ("    seed: 1.5", "sensors.joint_states.seed", "a whole number from 0"),
    ("    delay: -0.001", "sensors.joint_states.delay", "a number >= 0"),
    ("    delay: 0.0025", "sensors.joint_states.delay", "a whole number of ticks"),
    ("    position: [0.1]", "sensors.joint_states.position", "a mapping"),
])
def test_bad_sensor_keys_are_refused_naming_the_key(sensors, key, expected):
    with pytest.raises(SceneError) as err:
        parse_scene(scene_text(sensors), source="sensed.yaml")
    assert err.value.key == key
    assert expected in str(err.value) and str(err.value).startswith("sensed.yaml: ")


def test_other_sensor_sections_are_refused():
    text = scene_text("    seed: 1").replace("  joint_states:\n    seed: 1", "  imu: {}")
    with pytest.raises(SceneError) as err:
        parse_scene(text, source="sensed.yaml")
    assert err.value.key == "sensors.imu"


def test_a_sensor_delay_that_is_not_whole_ticks_at_the_run_rate_is_refused():
    scene = parse_scene(scene_text("    delay: 0.003"), source="sensed.yaml")
    with pytest.raises(ConfigurationError, match=r"sensed\.yaml: sensors\.joint_states\.delay: "
                       r"expected a whole number of ticks of 0\.002 s"):
        Simulator(scene.model, SimulationSettings(rate=500.0), scene.gains, scene.plant)


def test_vjm_run_writes_the_measured_columns_beside_the_exact_ones(tmp_path):
    """``trajectory.csv`` of a scene with sensors: the exact state under the usual names and
    the stream of the sensors as ``measured.q|qd|effort.<joint>``, equal to the simulator's."""
    from vjm_ros.app import cli

    text = scene_text("""\
    position: {noise: 0.1, resolution: 0.01}
    velocity: {noise: 1.0, bias: 0.3}
    effort: {noise: 0.2}
    delay: 0.003
    seed: 5""")
    path = tmp_path / "sensed.yaml"
    path.write_text(text)
    assert cli.main(["run", str(path), "--duration", "0.3", "--effort", "0.5", "-1.0",
                     "--out", str(tmp_path / "out")]) == 0
    with open(tmp_path / "out" / "trajectory.csv") as fh:
        header = fh.readline().strip().split(",")
    table = np.loadtxt(tmp_path / "out" / "trajectory.csv", delimiter=",", skiprows=1)
    names = ("shoulder", "extension")
    assert header[-6:] == [f"measured.{f}.{j}" for j in names for f in ("q", "qd", "effort")]
    assert header[:5] == ["t", "q.shoulder", "qd.shoulder", "qdd.shoulder", "effort.shoulder"]
    measured, exact = simulate(text, 300)
    column = {name: table[:, k] for k, name in enumerate(header)}
    for j, name in enumerate(names):
        # the CSV holds each value's shortest repr: the same doubles
        assert np.array_equal(column[f"q.{name}"], exact[:, 0, j])
        for f, field in enumerate(("q", "qd", "effort")):
            assert np.array_equal(column[f"measured.{field}.{name}"], measured[:, f, j])


def test_the_logs_keep_the_measured_and_the_exact_joint_states(tmp_path, monkeypatch):
    """MCAP of a scene with sensors (and a lagged actuator, so efforts change per row): written
    block by block (``vjm run``) it is the file written sample by sample (the node's rows),
    byte for byte; rosbags reads the measured state on ``/joint_states`` and the exact one on
    ``/vjm_sim_node/ground_truth/joint_states``; replay draws the exact poses."""
    import types

    from rosbags.highlevel import AnyReader

    from vjm_ros.logs import mcap_recorder
    from vjm_ros.logs.mcap_recorder import McapRecorder
    from vjm_ros.logs.replay import replay

    text = scene_text("""\
    position: {noise: 0.1, resolution: 0.01}
    velocity: {noise: 1.0}
    effort: {noise: 0.2}
    delay: 0.002
    seed: 9""").replace("{joint: shoulder, limit: 20.0}",
                        "{joint: shoulder, limit: 20.0, time_constant: 0.01}")
    scene = parse_scene(text)
    sim = Simulator(scene.model, SimulationSettings(), scene.gains, scene.plant)
    first = sim.sample()
    sim.set_efforts([0.5, -1.0])
    blocks = []
    for rows in (50, 37, 50):
        block = SampleBlock(scene.model, 50)
        sim.advance_block(block, rows)
        blocks.append(block)
    assert blocks[0].effort.ndim == 2  # one applied effort per row
    monkeypatch.setattr(mcap_recorder, "time",
                        types.SimpleNamespace(monotonic=lambda: 0.0, time_ns=lambda: 7))
    paths = {}
    for how in ("samples", "blocks"):
        (tmp_path / how).mkdir()
        paths[how] = tmp_path / how / "run.mcap"  # one name: the bag metadata holds it
        with McapRecorder(paths[how], scene.model, sim.describe(), scene.text,
                          chunk_seconds=0.03) as rec:
            rec.write(first)
            for block in blocks:
                if how == "blocks":
                    rec.write_block(block)
                else:
                    for i in range(len(block)):
                        rec.write(block.sample(i))
    assert paths["blocks"].read_bytes() == paths["samples"].read_bytes()

    rows = [first] + [b.sample(i) for b in blocks for i in range(len(b))]
    got: dict[str, list] = {}
    with AnyReader([paths["blocks"]]) as reader:
        for conn, _, raw in reader.messages():
            if conn.msgtype == "sensor_msgs/msg/JointState":
                msg = reader.deserialize(raw, conn.msgtype)
                got.setdefault(conn.topic, []).append(
                    np.stack((msg.position, msg.velocity, msg.effort)))
    assert np.array_equal(got["/joint_states"], [s.measured for s in rows])
    assert np.array_equal(got["/vjm_sim_node/ground_truth/joint_states"],
                          [np.stack((s.q, s.qd, s.effort)) for s in rows])

    from rerun.chunk import RrdReader

    from vjm_ros.logs.rerun_recorder import RerunRecorder

    def series(path, entity):
        values = []
        for chunk in RrdReader(path).store().stream():
            if str(chunk.entity_path) == entity and not chunk.is_static:
                batch = chunk.to_record_batch()
                column = next(n for n in batch.schema.names if n.endswith("Scalars:scalars"))
                values += batch.column(column).to_pylist()
        return values

    with RerunRecorder(tmp_path / "run.rrd", scene.model, sim.describe(), batch=64) as rec:
        rec.write(first)
        for block in blocks:
            rec.write_block(block)
    for f, field in enumerate(("position", "velocity", "effort")):
        assert np.array_equal(series(tmp_path / "run.rrd", f"/series/measured/{field}"),
                              [s.measured[f] for s in rows])
    assert np.array_equal(series(tmp_path / "run.rrd", "/series/joints/position"),
                          [s.q for s in rows])

    done = replay(paths["blocks"], tmp_path / "replay.rrd")
    assert done["samples"] == len(rows)
    # the exact poses, not the measured ones
    assert np.array_equal(series(tmp_path / "replay.rrd", "/series/joints/position"),
                          [s.q for s in rows])
