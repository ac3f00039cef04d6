"""The floor of the node's publishing cost: the same messages, published by bare rclpy.

``python -m benchmarks.bare_publish --scene five_bar --ticks 5000`` publishes, per tick, what
``vjm_sim_node`` publishes every tick (``/clock``, ``joint_states``, ``~/constraint_forces``, one
``~/closures/<name>/wrench`` per closure, ``~/energy``) with the node's names and types, from
messages built once from a real sample and only re-stamped, as fast as it can. It prints
``bare {"ticks": N, "cpu_time": s, "wall_time": s}`` (process CPU time over the publishing loop,
DDS threads included, as the node's own summary counts it). :mod:`benchmarks.node_cost`
compares the node against it.
"""

from __future__ import annotations

import argparse
import json
import time

import rclpy
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from benchmarks import ros_messages as conv
from vjm_ros.ros.conversions import stamp, wrench_topic
from vjm_ros.ros.node import NODE_NAME
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bare_publish",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--scene", default="five_bar")
    parser.add_argument("--ticks", type=int, default=5000)
    parser.add_argument("--wait", type=float, default=10.0,
                        help="seconds to wait for a subscriber on every topic before publishing")
    args = parser.parse_args(argv)
    scene = load_scene(args.scene)
    sim = Simulator(scene.model, SimulationSettings(), scene.gains)
    sim.advance()
    sample = sim.sample()
    model = scene.model
    ctx = rclpy.Context()
    rclpy.init(context=ctx, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = rclpy.create_node(NODE_NAME, context=ctx)
        pubs = [
            (node.create_publisher(Clock, "/clock", 10), conv.clock(sample.t)),
            (node.create_publisher(JointState, "joint_states", 10),
             conv.joint_state(model.joint_names, sample.t, sample.q, sample.qd, sample.effort)),
            (node.create_publisher(Float64MultiArray, "~/constraint_forces", 10),
             conv.constraint_forces(conv.labelled_layout(
                 [c.name for c in model.closures], len(conv.FORCE_COMPONENTS)),
                 sample.closure_force)),
            (node.create_publisher(Float64MultiArray, "~/energy", 10),
             conv.energy(conv.labelled_layout(conv.ENERGY_LABELS, 1), sample.energy)),
        ]
        for closure, force in zip(model.closures, sample.closure_force, strict=True):
            pubs.append((node.create_publisher(
                type(conv.wrench(force, sample.t)), wrench_topic(closure.name), 10),
                conv.wrench(force, sample.t)))
        deadline = time.monotonic() + args.wait
        while time.monotonic() < deadline and not all(
                p.get_subscription_count() > 0 for p, _ in pubs):
            time.sleep(0.05)
        stamps = [(msg, msg.clock if isinstance(msg, Clock) else getattr(msg, "header", None))
                  for _, msg in pubs]
        wall0, cpu0 = time.perf_counter(), time.process_time()
        for tick in range(args.ticks):
            t = stamp(tick * sim.dt)
            for (pub, msg), (_, header) in zip(pubs, stamps, strict=True):
                if isinstance(msg, Clock):
                    msg.clock = t
                elif header is not None:
                    header.stamp = t
                pub.publish(msg)
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        print("bare " + json.dumps({"ticks": args.ticks, "cpu_time": cpu, "wall_time": wall,
                                    "topics": len(pubs)}), flush=True)
    finally:
        rclpy.shutdown(context=ctx)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
