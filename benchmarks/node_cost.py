"""What the node costs per tick against its floor: the physics plus bare rclpy publishing.

``python -m benchmarks.node_cost [--scenes ...] [--seconds 5]`` measures, per scene, in one
run and with one subscriber process on every topic the node publishes (this process):

1. **node**: ``vjm_sim_node`` in fast mode (``realtime:=false``) for ``seconds`` simulated
   seconds at 1 kHz; process CPU time per tick from its exit summary (tick loop, executor and DDS
   threads), counted from the first tick. The node holds its start state
   (``wait_for_command:=true``) until this process has heard it on every per-tick topic and sent
   it one command (the scene's default efforts): a node that published before its subscriber was
   matched would look cheaper than it is;
2. **bare publish**: :mod:`benchmarks.bare_publish`, the same messages on the same topics per
   tick from prebuilt messages, as fast as it can; process CPU time per tick;
3. **physics**: the node's physics (one compiled call per tick for the step, the guard and
   every observable, ``Simulator.advance_block`` of one tick) in this process, CPU time per
   tick.

The node and the bare publishing run ``--repeats`` times each, alternately; the ratio
``node / (physics + bare publish)`` of their medians is the node's overhead over its floor (issue
target: at most 1.3). CPU times on a shared 2-core machine vary from run to run: compare the
figures of one run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

from benchmarks import ROOT
from benchmarks.latency import node_command, run_node
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator

RATE = 1000.0


def physics_per_tick(scene: str, ticks: int = 3000) -> float:
    """CPU seconds per tick of the node's physics: one compiled call for the step, the guard and
    every observable (``advance_block`` of one tick), as the tick loop makes it."""
    sc = load_scene(scene)
    sim = Simulator(sc.model, SimulationSettings(rate=RATE), sc.gains)
    if sc.model.actuators:
        sim.set_efforts([a.effort for a in sc.model.actuators])
    sim.blocks_compiled()
    block = SampleBlock(sc.model, 1)
    sim.advance_block(block, 1)
    c0 = time.process_time()
    for _ in range(ticks):
        sim.advance_block(block, 1)
    return (time.process_time() - c0) / ticks


def bare_publish_per_tick(scene: str, ticks: int) -> tuple[float, int]:
    """CPU seconds per tick of :mod:`benchmarks.bare_publish`, and its number of topics."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.bare_publish", "--scene", scene, "--ticks", str(ticks)],
        env=env, cwd=ROOT, capture_output=True, text=True, timeout=600)
    line = next((x for x in out.stdout.splitlines() if x.startswith("bare ")), None)
    if out.returncode != 0 or line is None:
        raise RuntimeError(f"bare_publish failed ({out.returncode}):\n{out.stdout}{out.stderr}")
    figures = json.loads(line[len("bare "):])
    return figures["cpu_time"] / figures["ticks"], figures["topics"]


PER_TICK = ("/clock", "/joint_states", "/vjm_sim_node/constraint_forces", "/vjm_sim_node/energy")
"""Topics the node publishes every tick besides the wrenches (names as the sink sees them)."""
MATCH_TIMEOUT = 60.0
"""Longest wait for the node to be heard on every per-tick topic, wall s (then it starts anyway)."""


def start_when_heard(sink, efforts: list[float], proc) -> None:
    """Send the node its first command once ``sink`` hears it on ``/joint_states`` (republished
    while it holds) and knows a publisher on every per-tick topic; a node that exits first or
    is not heard within :data:`MATCH_TIMEOUT` is started all the same."""
    topics = [t for t in sink.counts if t in PER_TICK or t.endswith("/wrench")]
    deadline = time.monotonic() + MATCH_TIMEOUT
    while time.monotonic() < deadline and proc.poll() is None:
        if (sink.counts["/joint_states"] > 0 and sink.commands_matched()
                and all(sink.node.count_publishers(t) > 0 for t in topics)):
            break
        time.sleep(0.01)
    sink.publish_efforts(efforts)


def measure(scene: str, seconds: float, repeats: int = 3) -> dict:
    """The three costs of one scene (µs per tick) and the ratio.

    The node and the bare publishing run ``repeats`` times each, alternately (each with a fresh
    subscriber); the ratio is that of their medians. Single runs of either varied by a third
    from one to the next on a shared machine.
    """
    from benchmarks.probes import TopicSink

    model = load_scene(scene).model
    efforts = [float(a.effort) for a in model.actuators]
    ticks = int(round(seconds * RATE))
    node_ticks, bares, received = [], [], []
    for _ in range(max(int(repeats), 1)):
        with TopicSink("vjm_cost_sink", model.closure_names, commands=True) as sink:
            node = run_node(node_command(scene, RATE, seconds, False,
                                         ["marker_rate_hz:=10.0", "wait_for_command:=true"]),
                            during=lambda proc, sink=sink: start_when_heard(sink, efforts, proc))
            received.append(dict(sink.counts))
            bare, topics = bare_publish_per_tick(scene, ticks)
        node_ticks.append(node["ticking_cpu_time"] / max(node["ticks"], 1))
        bares.append(bare)
    physics = physics_per_tick(scene)
    node_tick, bare = float(np.median(node_ticks)), float(np.median(bares))
    return {
        "scene": scene,
        "ticks": node["ticks"],
        "repeats": len(node_ticks),
        "topics_per_tick": topics,
        "node_us": 1e6 * node_tick,
        "node_us_range": [1e6 * min(node_ticks), 1e6 * max(node_ticks)],
        "physics_us": 1e6 * physics,
        "bare_publish_us": 1e6 * bare,
        "bare_publish_us_range": [1e6 * min(bares), 1e6 * max(bares)],
        "ratio": node_tick / (physics + bare),
        "joint_states_received": min(r.get("/joint_states", 0) for r in received),
        "received": received[-1],
        "load_1min": os.getloadavg()[0],
    }


def main(argv: list[str] | None = None) -> int:
    from vjm_ros.jit import tiers

    tiers.compile_first()  # times compiled code, never the plain-Python tier
    parser = argparse.ArgumentParser(prog="python -m benchmarks.node_cost",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", nargs="*", default=["four_bar", "five_bar", "three_chain"])
    parser.add_argument("--seconds", type=float, default=5.0, help="simulated s per node run")
    parser.add_argument("--repeats", type=int, default=3,
                        help="alternate runs of the node and of the bare publishing (medians)")
    parser.add_argument("--json", action="store_true", help="rows as JSON on the last line")
    args = parser.parse_args(argv)
    rows = []
    for scene in args.scenes:
        row = measure(scene, args.seconds, args.repeats)
        rows.append(row)
        lo, hi = row["node_us_range"]
        blo, bhi = row["bare_publish_us_range"]
        print(f"{scene:>14}: node {row['node_us']:.0f} us CPU per tick ({lo:.0f}-{hi:.0f}); "
              f"physics {row['physics_us']:.0f} us + bare publish of {row['topics_per_tick']} "
              f"messages {row['bare_publish_us']:.0f} us ({blo:.0f}-{bhi:.0f}); ratio "
              f"{row['ratio']:.2f} (target <= 1.3); medians of {row['repeats']} runs; at least "
              f"{row['joint_states_received']} joint states received of {row['ticks'] + 1}; "
              f"load {row['load_1min']:.2f}", flush=True)
    if args.json:
        print(json.dumps(rows, default=float))
    return 0 if all(np.isfinite(r["ratio"]) for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
