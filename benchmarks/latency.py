"""Timing of ``vjm_sim_node`` on this machine; re-run with ``python -m benchmarks.latency``.

For each scene, with the node as a separate process (as users run it):

1. **realtime**: ``seconds`` of realtime running at ``rate`` Hz. The node's exit summary gives the
   late and missed ticks (see :mod:`vjm_ros.realtime.pacing`). Meanwhile a probe node in this process
   publishes effort commands at random moments (every 20-60 ms, distinct small values) and times
   each from its publication to the first ``/joint_states`` whose effort equals it: the
   command-to-state latency (transport, the wait for the next tick, the tick, transport back).
2. **fast**: ``fast_seconds`` of simulated time in fast mode; the node's realtime factor.

Prints one line per scene, and with ``--json`` one JSON object on the last line. Numbers depend on
what else runs on the machine: the 1-minute load average is printed with them.

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python -m benchmarks.latency [--scenes four_bar five_bar]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import subprocess
import sys
import threading
import time

import numpy as np

from benchmarks.probes import GraphProbe
from vjm_ros.scene.loader import builtin_scenes, load_scene


def node_command(scene: str, rate: float, duration: float, realtime: bool, extra: list[str]) -> list[str]:
    """Command line of the simulator node for one measurement."""
    params = [f"scene:={scene}", f"rate_hz:={rate}", f"duration:={duration}",
              f"realtime:={'true' if realtime else 'false'}", "command_timeout:=0.0", *extra]
    cmd = [sys.executable, "-m", "vjm_ros.ros.node", "--ros-args"]
    for p in params:
        cmd += ["-p", p]
    return cmd


def run_node(cmd: list[str], during=None, timeout: float = 600.0) -> dict:
    """Run the node to its end (``during(proc)`` runs meanwhile); return its exit summary."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        if during is not None:
            during(proc)
        out, _ = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            out, _ = proc.communicate()
    return node_summary(proc.returncode, out)


def node_summary(returncode: int, output: str) -> dict:
    """The exit summary the node prints (``summary {...}``); RuntimeError if it failed."""
    match = re.search(r"summary (\{.*\})", output)
    if returncode != 0 or not match:
        raise RuntimeError(f"the node failed (exit code {returncode}):\n{output}")
    return json.loads(match.group(1))


def take_applied(tracker, msg):
    """Count a joint state and pop what ``tracker.pending`` holds for the effort it shows
    applied on ``tracker.joint`` (None: no pending command has that value). Call under
    ``tracker.lock``."""
    if tracker.index is None:
        tracker.index = list(msg.name).index(tracker.joint)
    tracker.states += 1
    return tracker.pending.pop(msg.effort[tracker.index], None)


class Probe:
    """Publishes effort commands and times their first appearance in ``/joint_states``.

    Parameters
    ----------
    joint : str
        Name of the actuated joint commanded (the first actuator).
    count : int
        Number of actuators (length of a command).
    magnitude : float
        Scale of the commanded values, N m or N.
    """

    def __init__(self, joint: str, count: int, magnitude: float):
        self.joint, self.count, self.magnitude = joint, count, magnitude
        self.pending: dict[float, float] = {}
        self.latencies: list[float] = []
        self.states = 0
        self.lock = threading.Lock()
        self.index = None
        self.graph = GraphProbe("vjm_latency_probe", on_state=self._on_state, depth=100,
                                commands=True)

    def _on_state(self, msg) -> None:
        now = time.monotonic()
        with self.lock:
            sent = take_applied(self, msg)
            if sent is not None:
                self.latencies.append(now - sent)

    def drive(self, proc: subprocess.Popen, seconds: float) -> None:
        """Send commands for ``seconds`` once the node publishes, until it ends."""
        start = time.monotonic()
        while self.states == 0 or not self.graph.commands_matched():
            if proc.poll() is not None or time.monotonic() - start > 60.0:
                return
            time.sleep(0.01)
        end = time.monotonic() + seconds
        k = 0
        while time.monotonic() < end and proc.poll() is None:
            k += 1
            value = self.magnitude * (0.1 + 1e-4 * k) * (-1) ** k
            data = [value] + [0.0] * (self.count - 1)
            with self.lock:
                self.pending[value] = time.monotonic()
            self.graph.publish_efforts(data)
            time.sleep(random.uniform(0.02, 0.06))

    def close(self) -> tuple[np.ndarray, int]:
        """Latencies measured (s) and commands never seen."""
        self.graph.close()
        return np.array(self.latencies), len(self.pending)


def measure(scene: str, rate: float, seconds: float, fast_seconds: float, extra: list[str]) -> dict:
    """Realtime ticks, latency and fast-mode speed of one scene."""
    model = load_scene(scene).model
    row: dict = {"scene": scene, "rate_hz": rate, "load_1min": os.getloadavg()[0]}
    probe = None
    if model.actuators:
        act = model.actuators[0]
        probe = Probe(model.joints[act.joint].name, len(model.actuators), min(act.limit, 1.0))
    try:
        during = (lambda proc: probe.drive(proc, seconds)) if probe else None
        realtime = run_node(node_command(scene, rate, seconds, True, extra), during)
    finally:
        latencies, lost = probe.close() if probe else (np.zeros(0), 0)
    row.update({
        "ticks": realtime["ticks"],
        "late_ticks": realtime["late_ticks"],
        "missed_ticks": realtime["missed_ticks"],
        "resyncs": realtime["resyncs"],
        "max_lateness_ms": 1e3 * realtime["max_lateness"],
        "realtime_run_factor": realtime["realtime_factor"],
        "commands": int(latencies.size + lost),
        "commands_unseen": lost,
    })
    if latencies.size:
        p50, p99 = np.percentile(latencies, [50, 99]) * 1e3
        row.update({"latency_p50_ms": p50, "latency_p99_ms": p99,
                    "latency_max_ms": 1e3 * latencies.max()})
    fast = run_node(node_command(scene, rate, fast_seconds, False, extra))
    row["fast_realtime_factor"] = fast["realtime_factor"]
    row["fast_cpu_per_tick_us"] = 1e6 * fast["cpu_time"] / max(fast["ticks"], 1)
    row["load_1min_end"] = os.getloadavg()[0]
    return row


def _format(row: dict) -> str:
    lat = (f"latency p50 {row['latency_p50_ms']:.2f} ms, p99 {row['latency_p99_ms']:.2f} ms "
           f"({row['commands']} commands, {row['commands_unseen']} unseen)"
           if "latency_p50_ms" in row else "no actuator: no latency")
    return (f"{row['scene']:>14}: {row['missed_ticks']} missed / {row['late_ticks']} late of "
            f"{row['ticks']} ticks (max lateness {row['max_lateness_ms']:.1f} ms, resyncs "
            f"{row['resyncs']}); fast mode {row['fast_realtime_factor']:.2f}x realtime "
            f"({row['fast_cpu_per_tick_us']:.0f} us CPU per tick); {lat}; "
            f"load {row['load_1min']:.2f}-{row['load_1min_end']:.2f}")


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module documentation."""
    from vjm_ros.jit import tiers

    tiers.compile_first()  # times compiled code, never the plain-Python tier
    parser = argparse.ArgumentParser(prog="python -m benchmarks.latency", description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", nargs="*", default=builtin_scenes(), help="built-in names or YAML paths")
    parser.add_argument("--rate", type=float, default=1000.0, help="tick rate, Hz (1000)")
    parser.add_argument("--seconds", type=float, default=10.0, help="realtime run, s (10)")
    parser.add_argument("--fast-seconds", type=float, default=5.0, help="fast-mode run, simulated s (5)")
    parser.add_argument("-p", "--param", action="append", default=[],
                        help="extra node parameter name:=value (repeatable)")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON on the last line")
    args = parser.parse_args(argv)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    rows = []
    for scene in args.scenes:
        try:
            rows.append(measure(scene, args.rate, args.seconds, args.fast_seconds, args.param))
            print(_format(rows[-1]), flush=True)
        except RuntimeError as exc:
            print(f"{scene:>14}: {exc}", flush=True)
    if args.json:
        print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
