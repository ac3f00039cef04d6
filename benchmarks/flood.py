"""Command fuzzing and floods against a live ``vjm_sim_node``; re-run with ``python -m benchmarks.flood``.

Three processes, as in a real ROS graph:

1. the simulator node (realtime, ``rate`` Hz, ``command_timeout`` 0.5 s);
2. a flooder (``python -m benchmarks.flood --publish ...``) that publishes ``flood_hz`` commands per
   second for ``seconds`` on both command topics (:class:`FuzzCommands`): valid efforts (some beyond
   the limits), NaN, Inf, wrong-length and oversized arrays, unknown, duplicate and non-actuated
   names. It then sends one last valid command, the *sentinel* (repeated for
   :data:`SENTINEL_SECONDS`, and waited on until the node has acknowledged it), and writes what it
   sent to JSON;
3. this process: a probe that reads ``/joint_states``, samples the node's resident memory, and
   counts the node's warnings.

The verdict (:func:`measure`): ticks kept (the node's late/missed counts), every effort the node
applied is a value of a valid command (clamped to the limits) or zero, the sentinel is applied,
warnings stay throttled (one per kind and second), and memory growth over the flood.

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python -m benchmarks.flood [--scene five_bar] [--json]
"""

from __future__ import annotations

import argparse
import array
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from benchmarks import ROOT
from vjm_ros.scene.loader import load_scene

VALID_ARRAY = "valid_array"
CLAMPED_ARRAY = "clamped_array"
VALID_NAMED = "valid_named"
PARTIAL_NAMED = "partial_named"
NAN_ARRAY = "nan_array"
INF_ARRAY = "inf_array"
SHORT_OR_LONG = "wrong_length"
OVERSIZED = "oversized"
UNKNOWN_NAMES = "unknown_names"
PASSIVE_NAMES = "passive_names"
DUPLICATE_NAMES = "duplicate_names"
NAN_NAMED = "nan_named"
EMPTY_NAMED = "empty_named"
MIX: dict[str, float] = {
    VALID_ARRAY: 0.35, CLAMPED_ARRAY: 0.05, VALID_NAMED: 0.08, PARTIAL_NAMED: 0.04,
    NAN_ARRAY: 0.08, INF_ARRAY: 0.07, SHORT_OR_LONG: 0.1, OVERSIZED: 0.003,
    UNKNOWN_NAMES: 0.07, PASSIVE_NAMES: 0.05, DUPLICATE_NAMES: 0.04, NAN_NAMED: 0.04,
    EMPTY_NAMED: 0.027,
}
"""Share of each class of command in a flood (sums to 1)."""
OVERSIZED_LENGTHS = (1_000, 10_000, 100_000)
"""Lengths of the oversized arrays (8 kB to 800 kB each). A few fixed sizes: the transport's
buffers reach their largest size within the first second, so that any later growth of the
node's memory is a leak, not a new record size."""
SENTINEL_FRACTION = 0.123456789
"""The last command: this fraction of each actuator's limit (a value no other command uses)."""


class FuzzCommands:
    """Random commands for a scene's actuators, remembering the values a node may apply.

    Parameters
    ----------
    actuator_names : sequence of str
        Actuated joints, scene actuator order.
    joint_names : sequence of str
        Every joint of the scene.
    limits : array_like, shape (n_actuators,)
        Effort limits, N m or N.
    seed : int
    """

    def __init__(self, actuator_names: Sequence[str], joint_names: Sequence[str],
                 limits: Sequence[float], seed: int = 0):
        self.actuators = list(actuator_names)
        self.passive = [j for j in joint_names if j not in set(self.actuators)]
        self.limits = np.asarray(limits, dtype=float)
        self.rng = np.random.default_rng(seed)
        self.kinds = list(MIX)
        self.weights = np.array([MIX[k] for k in self.kinds]) / sum(MIX.values())
        self._cumulative = np.cumsum(self.weights)
        self.applicable: list[set[float]] = [set() for _ in self.actuators]
        self.sent: Counter = Counter()

    def _values(self, scale: float = 0.5) -> np.ndarray:
        return self.rng.uniform(-scale, scale, len(self.actuators)) * self.limits

    def _valid(self, values: np.ndarray, which: Sequence[int]) -> None:
        clipped = np.clip(values, -self.limits, self.limits)
        for i, j in enumerate(which):
            self.applicable[j].add(float(clipped[i]))

    def next(self) -> tuple[str, str, list[str], np.ndarray]:
        """One command.

        Returns
        -------
        kind : str
            Its class (a key of :data:`MIX`).
        topic : str
            ``"effort_commands"`` (a ``Float64MultiArray``) or ``"joint_commands"``
            (a ``JointState``).
        names : list of str
            Joint names (``joint_commands`` only).
        values : ndarray
            Efforts, N m or N.
        """
        kind = self.kinds[min(int(np.searchsorted(self._cumulative, self.rng.random(), "right")),
                              len(self.kinds) - 1)]
        self.sent[kind] += 1
        n, rng = len(self.actuators), self.rng
        every = list(range(n))
        if kind in (VALID_ARRAY, CLAMPED_ARRAY):
            v = self._values(0.5 if kind == VALID_ARRAY else 4.0)
            self._valid(v, every)
            return kind, "effort_commands", [], v
        if kind in (NAN_ARRAY, INF_ARRAY):
            v = self._values()
            v[rng.integers(n)] = math.nan if kind == NAN_ARRAY else rng.choice([math.inf, -math.inf])
            return kind, "effort_commands", [], v
        if kind == SHORT_OR_LONG:
            length = int(rng.integers(0, n + 6))
            length += length == n
            return kind, "effort_commands", [], rng.uniform(-1, 1, length)
        if kind == OVERSIZED:
            length = OVERSIZED_LENGTHS[int(rng.integers(len(OVERSIZED_LENGTHS)))]
            return kind, "effort_commands", [], rng.uniform(-1, 1, length)
        if kind == VALID_NAMED:
            order = rng.permutation(n)
            v = self._values()[order]
            self._valid(v, order)
            return kind, "joint_commands", [self.actuators[j] for j in order], v
        if kind == PARTIAL_NAMED:
            j = int(rng.integers(n))
            v = self._values()[[j]]
            self._valid(v, [j])
            return kind, "joint_commands", [self.actuators[j]], v
        if kind == UNKNOWN_NAMES:
            names = [*self.actuators, f"no_such_joint_{rng.integers(1 << 30)}"]
            return kind, "joint_commands", names, rng.uniform(-1, 1, len(names))
        if kind == PASSIVE_NAMES and self.passive:
            names = [*self.actuators, self.passive[int(rng.integers(len(self.passive)))]]
            return kind, "joint_commands", names, rng.uniform(-1, 1, len(names))
        if kind in (DUPLICATE_NAMES, PASSIVE_NAMES):
            names = [*self.actuators, self.actuators[0]]
            return kind, "joint_commands", names, rng.uniform(-1, 1, len(names))
        if kind == NAN_NAMED:
            v = self._values()
            v[rng.integers(n)] = math.nan
            return kind, "joint_commands", list(self.actuators), v
        return kind, "joint_commands", [], np.zeros(0)  # EMPTY_NAMED

    def sentinel(self) -> list[float]:
        """The last command's efforts (recorded as applicable), N m or N."""
        v = SENTINEL_FRACTION * self.limits
        self._valid(v, range(len(self.actuators)))
        return v.tolist()


# ---------------------------------------------------------------- the flooder process
def publish(scene: str, node_name: str, rate: float, seconds: float, out: Path, seed: int) -> int:
    """Flood the node's command topics; write what was sent to ``out`` (JSON). Returns 0."""
    from benchmarks.probes import GraphProbe

    model = load_scene(scene).model
    fuzz = FuzzCommands(model.actuator_names, model.joint_names,
                        [a.limit for a in model.actuators], seed)
    with GraphProbe("vjm_flooder", commands=True, sim_node=node_name) as probe:
        start = time.monotonic()
        while not probe.commands_matched():
            if time.monotonic() - start > 60.0:  # a hang guard
                print("vjm_flooder: the simulator's command topics never matched", file=sys.stderr)
                return 1
            time.sleep(0.01)
        result = _flood(probe, fuzz, rate, seconds)
    out.write_text(json.dumps(result))
    return 0


SENTINEL_SECONDS = 1.0
"""How long the flooder repeats the sentinel after the flood, s (twice the node's command timeout
of :func:`measure`)."""


def _flood(probe, fuzz: FuzzCommands, rate: float, seconds: float) -> dict:
    """Publish ``rate`` fuzzed commands per second for ``seconds``, then the sentinel."""
    period = 1.0 / rate
    published = 0
    t0 = time.monotonic()
    end = t0 + seconds
    while (now := time.monotonic()) < end:
        due = int((now - t0) / period) + 1 - published  # catch up on the schedule
        if due <= 0:
            time.sleep(min(period * 4, end - now))
            continue
        for _ in range(min(due, 100)):
            kind, topic, names, values = fuzz.next()
            data = array.array("d", values.tobytes())
            if topic == "effort_commands":
                probe.publish_efforts(data)
            else:
                probe.publish_named(names, data)
            published += 1
    wall = time.monotonic() - t0
    sentinel = fuzz.sentinel()
    # The sentinel again every 20 ms for SENTINEL_SECONDS, twice the node's command timeout: it
    # stays applied that long, so a watcher that loses a burst of states on a loaded machine
    # still sees it (sent for 0.1 s, it was missed in 1 run of 4 with another process busy).
    for _ in range(round(SENTINEL_SECONDS / 0.02)):
        probe.publish_efforts(sentinel)
        time.sleep(0.02)
    # Exit only once the node has the commands (reliable QoS): the flood can leave a backlog
    # in the writer, which an exiting process would take with it.
    delivered = probe.wait_for_commands_delivered(10.0)
    return {
        "published": published,
        "wall": wall,
        "rate": published / wall,
        "sent": dict(fuzz.sent),
        "applicable": [sorted(s) for s in fuzz.applicable],
        "sentinel": sentinel,
        "delivered": delivered,
    }


# ---------------------------------------------------------------- the measurement
def rss_mb(pid: int) -> float:
    """Resident memory of a process, MB (nan when it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return math.nan


WARNING = re.compile(r"\[WARN\].*?: (~/\w+): (?:command refused|effort)")


def measure(scene: str = "five_bar", seconds: float = 10.0, flood_hz: float = 10_000.0,
            rate: float = 1000.0, seed: int = 0,
            extra: Sequence[str] = ("realtime_priority:=50",)) -> dict:
    """Run a node, flood it, and judge what it did.

    Parameters
    ----------
    scene : str
        A scene with actuators.
    seconds : float
        Length of the flood, s.
    flood_hz : float
        Commands per second.
    rate : float
        Tick rate of the node, Hz.
    seed : int
    extra : sequence of str
        More node parameters ``name:=value``. By default the tick loop asks for SCHED_FIFO
        priority 50: at normal priority on a two-core machine, a flooder that takes a core
        leaves the tick to the kernel's fair scheduler, which delays it by milliseconds.

    Returns
    -------
    dict
        The figures and checks (see :func:`_format`).
    """
    from benchmarks.latency import node_command, node_summary
    from benchmarks.probes import GraphProbe

    model = load_scene(scene).model
    actuated = [model.joint_names.index(a) for a in model.actuator_names]
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    duration = seconds + 4.0
    cmd = node_command(scene, rate, duration, True, ["command_timeout:=0.5", *extra])
    applied: set[tuple[float, ...]] = set()
    states = [0]
    lock = threading.Lock()

    def on_state(msg):
        e = tuple(msg.effort[i] for i in actuated)
        with lock:
            states[0] += 1
            applied.add(e)

    probe = GraphProbe("vjm_flood_probe", on_state=on_state, depth=1000)
    node = flooder = reader = None
    row: dict = {"scene": scene, "seconds": seconds, "flood_hz": flood_hz, "rate_hz": rate,
                 "load_1min": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory() as tmp:
        sent_file = Path(tmp) / "sent.json"
        try:
            node = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, text=True)
            output: list[str] = []
            reader = threading.Thread(target=lambda: output.extend(node.stdout), daemon=True)
            reader.start()
            # The flooder starts beside the node, not after its first state: it floods once the
            # node's command topics match, and its own start-up (seconds on a loaded machine)
            # then overlaps the node's instead of eating into the 4 s of the node's run that
            # follow the flood and its sentinel (started after the first state, the sentinel
            # sometimes came after the node had stopped).
            flooder = subprocess.Popen(
                [sys.executable, "-m", "benchmarks.flood", "--publish", "--scene", scene,
                 "--flood-hz", str(flood_hz), "--seconds", str(seconds), "--seed", str(seed),
                 "--out", str(sent_file)],
                env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            _wait_for_first_state(node, states, output)
            memory = _sample_memory(node, flooder)
            flood_out = flooder.communicate(timeout=60.0)[0]
            if flooder.returncode != 0:
                raise RuntimeError(f"the flooder failed ({flooder.returncode}):\n{flood_out}")
            node.wait(timeout=duration + 60.0)
        finally:
            _reap((flooder, node), reader)
            probe.close()
        text = "".join(output)
        summary = node_summary(node.returncode, text)
        sent = json.loads(sent_file.read_text())
    row.update(_figures(sent, summary, applied, text, memory, duration * rate))
    row["states_seen"] = states[0]
    row["load_1min_end"] = os.getloadavg()[0]
    return row


def _wait_for_first_state(node: subprocess.Popen, states: list, output: list[str]) -> None:
    """Return once the probe has counted a state; raise with the node's output if it died or
    stayed silent for 60 s."""
    start = time.monotonic()
    while states[0] == 0:
        if node.poll() is not None or time.monotonic() - start > 60.0:
            raise RuntimeError("the node did not start:\n" + "".join(output))
        time.sleep(0.01)


def _sample_memory(node: subprocess.Popen, flooder: subprocess.Popen) -> list:
    """``(monotonic s, node RSS MB)`` every 0.25 s while both processes run."""
    memory = []
    while flooder.poll() is None and node.poll() is None:
        memory.append((time.monotonic(), rss_mb(node.pid)))
        time.sleep(0.25)
    memory.append((time.monotonic(), rss_mb(node.pid)))
    return memory


def _reap(procs, reader: threading.Thread | None) -> None:
    """Kill what still runs, then close the pipes once their reader is done."""
    for proc in procs:
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()
    if reader is not None:
        reader.join(10.0)
    for proc in procs:
        if proc is not None and proc.stdout is not None:
            proc.stdout.close()


def _figures(sent: dict, summary: dict, applied: set, text: str, memory: list,
             expected_ticks: float) -> dict:
    """The verdict of one flood from what was sent, the node's summary and log, and memory."""
    allowed = [set(v) | {0.0} for v in sent["applicable"]]
    foreign = sorted(e for e in applied
                     if any(x not in ok for x, ok in zip(e, allowed, strict=True)))
    warnings = Counter(m.group(1) for m in WARNING.finditer(text))
    mb = np.array([m for _, m in memory if not math.isnan(m)])
    return {
        "published": sent["published"],
        "flood_rate": sent["rate"],
        "sent": sent["sent"],
        "ticks": summary["ticks"],
        "expected_ticks": round(expected_ticks),
        "late_ticks": summary["late_ticks"],
        "missed_ticks": summary["missed_ticks"],
        "resyncs": summary["resyncs"],
        "max_lateness_ms": 1e3 * summary["max_lateness"],
        "kept": 1.0 - summary["missed_ticks"] / max(summary["ticks"], 1),
        "commands_accepted": summary["commands_accepted"],
        "commands_rejected": summary["commands_rejected"],
        "distinct_efforts": len(applied),
        "foreign_efforts": [list(e) for e in foreign[:5]],
        "n_foreign": len(foreign),
        "sentinel_applied": tuple(sent["sentinel"]) in applied,
        "sentinel_delivered": sent.get("delivered"),
        "warnings": dict(warnings),
        "warning_lines": sum(warnings.values()),
        "rss_start_mb": float(mb[0]) if mb.size else math.nan,
        "rss_max_mb": float(mb.max()) if mb.size else math.nan,
        "rss_end_mb": float(mb[-1]) if mb.size else math.nan,
        "rss_series_mb": [round(float(m), 2) for m in mb],
        "realtime_priority_granted": "tick loop at SCHED_FIFO priority" in text,
    }


def _format(row: dict) -> str:
    return (
        f"{row['scene']}: {row['published']} commands in {row['seconds']:g} s "
        f"({row['flood_rate']:.0f}/s; accepted {row['commands_accepted']}, refused "
        f"{row['commands_rejected']}); ticks {row['ticks']} of {row['expected_ticks']}, missed "
        f"{row['missed_ticks']} ({100 * row['kept']:.2f} % kept), late {row['late_ticks']}, "
        f"max lateness {row['max_lateness_ms']:.1f} ms; {row['n_foreign']} foreign efforts among "
        f"{row['distinct_efforts']} applied, sentinel applied: {row['sentinel_applied']}; "
        f"{row['warning_lines']} warning lines {row['warnings']}; RSS {row['rss_start_mb']:.1f} -> "
        f"{row['rss_end_mb']:.1f} MB (max {row['rss_max_mb']:.1f}); SCHED_FIFO "
        f"{'granted' if row['realtime_priority_granted'] else 'not granted'}; load "
        f"{row['load_1min']:.2f}-{row['load_1min_end']:.2f}"
    )


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module documentation."""
    from vjm_ros.jit import tiers

    tiers.compile_first()  # times compiled code, never the plain-Python tier
    parser = argparse.ArgumentParser(prog="python -m benchmarks.flood",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--scene", default="five_bar", help="scene with actuators (five_bar)")
    parser.add_argument("--seconds", type=float, default=10.0, help="length of the flood, s (10)")
    parser.add_argument("--flood-hz", type=float, default=10_000.0, help="commands per second (10000)")
    parser.add_argument("--rate", type=float, default=1000.0, help="node tick rate, Hz (1000)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("-p", "--param", action="append", default=None,
                        help="node parameter name:=value (repeatable; default: "
                             "realtime_priority:=50)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON on the last line")
    parser.add_argument("--publish", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--node-name", default="vjm_sim_node", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    if args.publish:
        return publish(args.scene, args.node_name, args.flood_hz, args.seconds, args.out, args.seed)
    extra = ["realtime_priority:=50"] if args.param is None else args.param
    row = measure(args.scene, args.seconds, args.flood_hz, args.rate, args.seed, extra)
    print(_format(row), flush=True)
    if args.json:
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
