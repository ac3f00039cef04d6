"""The node live at 1 kHz with a 1 kHz controller in the loop: missed ticks, command lag, commands
applied.

``python -m benchmarks.live_loop [--scenes ...] [--seconds 10]`` runs ``vjm_sim_node`` in
realtime at normal priority and, in this process, a controller that subscribes to every topic the
node publishes and answers each ``/joint_states`` with an effort command. Each command carries a
value of its own (on the first actuator, well inside its limit), so the first joint state whose
applied effort equals it tells when the command took effect:

* **missed ticks**: the node's own count over the run (issue target: at most 0.1 %);
* **command lag**: ticks from the joint state a command answers to the first joint state that
  shows it applied (target: median at most 2 ticks; a command received during tick k applies
  from tick k + 1, so 2 is the least a state -> command -> state loop can show);
* **commands applied**: share of the commands sent that ever showed in a joint state (target:
  at least 95 %; a command overtaken by the next one before a tick latches it never shows).

Right before each scene, the study runs the node's pacer with an empty tick for as long
(:mod:`benchmarks.pacing_floor`, ``--floor-seconds``; 0 skips it): the ticks *it* misses
are the machine's, and no node can miss fewer on that machine at that time. Each row carries
that floor (``floor_missed_share``, ``floor_max_lateness_ms``). The figures depend on the
machine's load: compare within one run.
"""

from __future__ import annotations

import argparse
import json
import os
import threading

import numpy as np

from benchmarks import pacing_floor
from benchmarks.latency import node_command, run_node, take_applied
from vjm_ros.scene.loader import builtin_scenes, load_scene

RATE = 1000.0


class LoopController:
    """Answers each joint state with a command whose value identifies the state's tick.

    Parameters
    ----------
    scene : str
        The scene the node runs (names, actuators, closures).
    """

    def __init__(self, scene: str):
        from benchmarks.probes import TopicSink

        model = load_scene(scene).model
        act = model.actuators[0]
        self.joint = model.joints[act.joint].name
        self.count = len(model.actuators)
        self.magnitude = 0.5 * min(act.limit, 1.0)
        self.pending: dict[float, int] = {}
        self.lags: list[int] = []
        self.states = 0
        self.index: int | None = None
        self.lock = threading.Lock()
        self.sink = TopicSink("vjm_loop_controller", model.closure_names,
                              on_state=self._on_state, commands=True)

    def _value(self, tick: int) -> float:
        # distinct for ticks less than 10 000 apart; well inside the actuator's limit
        return self.magnitude * (0.1 + 0.9 * (tick % 10_000) / 10_000)

    def _on_state(self, msg) -> None:
        tick = int(round((msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec) * RATE))
        value = self._value(tick)
        with self.lock:
            answered = take_applied(self, msg)
            if answered is not None:
                self.lags.append(tick - answered)
            self.pending[value] = tick
        if self.sink.commands_matched():
            self.sink.publish_efforts([value] + [0.0] * (self.count - 1))

    def close(self) -> dict:
        """Lags (ticks) and counts; stops the controller."""
        self.sink.close()
        lags = np.array(self.lags, dtype=float)
        return {"commands": int(lags.size + len(self.pending)), "applied": int(lags.size),
                "lags": lags, "received": dict(self.sink.counts)}


def measure(scene: str, seconds: float, extra: list[str]) -> dict:
    """One live run of ``seconds`` with the controller in the loop."""
    ctrl = LoopController(scene)
    try:
        # the node holds its start state until the controller's first command: the run starts
        # once the two have found each other, however long discovery takes on a loaded machine
        summary = run_node(node_command(scene, RATE, seconds, True,
                                        ["wait_for_command:=true", *extra]))
    finally:
        got = ctrl.close()
    lags = got["lags"]
    ticks = max(summary["ticks"], 1)
    return {
        "scene": scene,
        "ticks": summary["ticks"],
        "missed_ticks": summary["missed_ticks"],
        "missed_share": summary["missed_ticks"] / ticks,
        "late_ticks": summary["late_ticks"],
        "commands": got["commands"],
        "applied_share": got["applied"] / max(got["commands"], 1),
        "lag_median_ticks": float(np.median(lags)) if lags.size else float("nan"),
        "lag_p99_ticks": float(np.percentile(lags, 99)) if lags.size else float("nan"),
        "topics_received": sum(1 for v in got["received"].values() if v > 0),
        "load_1min": os.getloadavg()[0],
    }


def main(argv: list[str] | None = None) -> int:
    from vjm_ros.jit import tiers

    tiers.compile_first()  # times compiled code, never the plain-Python tier
    parser = argparse.ArgumentParser(prog="python -m benchmarks.live_loop",
                                     description=__doc__.split("\n")[0])
    actuated = [s for s in builtin_scenes() if load_scene(s).model.actuators]
    parser.add_argument("--scenes", nargs="*", default=actuated)
    parser.add_argument("--seconds", type=float, default=10.0, help="realtime run, s (10)")
    parser.add_argument("-p", "--param", action="append", default=[],
                        help="extra node parameter name:=value (repeatable)")
    parser.add_argument("--floor-seconds", type=float, default=None,
                        help="the pacer with an empty tick before each scene, s (as --seconds; "
                             "0: not run)")
    parser.add_argument("--json", action="store_true", help="rows as JSON on the last line")
    args = parser.parse_args(argv)
    floor_seconds = args.seconds if args.floor_seconds is None else args.floor_seconds
    rows = []
    for scene in args.scenes:
        floor = pacing_floor.measure(floor_seconds, RATE) if floor_seconds > 0 else None
        row = measure(scene, args.seconds, args.param)
        if floor is not None:
            row["floor_missed_share"] = floor["missed_share"]
            row["floor_max_lateness_ms"] = floor["max_lateness_ms"]
            print(f"{'':>14}  {pacing_floor.describe(floor)}", flush=True)
        rows.append(row)
        print(f"{scene:>14}: missed {row['missed_ticks']} of {row['ticks']} ticks "
              f"({100 * row['missed_share']:.2f} %, target <= 0.1 %); command lag median "
              f"{row['lag_median_ticks']:.0f} ticks (target <= 2), p99 "
              f"{row['lag_p99_ticks']:.0f}; applied {100 * row['applied_share']:.1f} % of "
              f"{row['commands']} commands (target >= 95 %); load {row['load_1min']:.2f}",
              flush=True)
    if args.json:
        print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
