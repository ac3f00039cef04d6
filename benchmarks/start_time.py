"""Start time of ``vjm run``, warm (numba's cache filled) and cold (empty cache), with a breakdown.

``python -m benchmarks.start_time [--scene four_bar] [--repeats 5] [--json]
[--docs docs/accuracy.md]`` measures in one run:

1. **floor**: ``python -c pass``, the interpreter alone (median of ``repeats`` processes);
2. **warm**: the whole process ``vjm run SCENE --duration 0.001`` (one control tick, the summary
   printed, no files written) with numba's cache filled by a run before, median of ``repeats``;
3. **cold**: the same process with ``NUMBA_CACHE_DIR`` set to a new, empty temporary directory:
   the kernels run as plain Python while a child process compiles them
   (:mod:`vjm_ros.jit.tiers`), median of ``cold_repeats``; and **cold, compiled first**: the
   same with ``VJM_TIERED=0``, every compiled entry point compiled before the first tick (one
   run);
4. with ``--node``, **node warm**: the whole process of ``vjm_sim_node`` in fast mode for one
   tick (``duration:=0.001``), rclpy start and shutdown included, median of ``repeats``;
5. **breakdown**, warm and cold: in a fresh process, the wall time of each start stage
   (:func:`stages`: imports, the first tick, numba's import, and the time until the ticks run
   compiled: the pipeline loaded from the cache warm, compiled in the background cold), and
   from ``python -X importtime`` the import time of each top-level package (self times summed;
   ``-X importtime`` itself slows imports a little).

Where numba's cache holds the kernels, the first ticks of a run are plain Python all the same
(:data:`vjm_ros.core.mechanism.PIPELINE_PLAIN_CALLS`), and numba is imported after them: a
one-tick run never imports it, and a longer run's first tick comes as soon.

With ``--docs`` it writes the figures as the page's start-time section (:data:`HEADING`; the bench
keeps that section when it rewrites the page). Issue targets: warm at most 0.5 s, cold at most
3 s. Times on a shared 2-core machine vary 2-4x
with load (the 1-minute load average is printed with them): compare figures of one run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from benchmarks import ROOT
from vjm_ros.studies.pages import with_section

HEADING = "## Start time"
"""Heading of the section of ``docs/accuracy.md`` this study writes."""

TIMEOUT = 600.0
"""Hang guard for each measured process, s (a cold start takes seconds)."""

_IMPORT_LINE = re.compile(r"^import time:\s+(\d+) \|\s+(\d+) \| (\s*)(\S+)")


def run_command(scene: str) -> list[str]:
    """Command line of one measured ``vjm run``: one tick of ``scene``."""
    script = Path(sys.executable).with_name("vjm")
    head = [str(script)] if script.exists() else [sys.executable, "-m", "vjm_ros.app.cli"]
    return [*head, "run", scene, "--duration", "0.001"]


def node_command(scene: str) -> list[str]:
    """Command line of one measured node: one tick of ``scene`` in fast mode."""
    cmd = [sys.executable, "-m", "vjm_ros.ros.node", "--ros-args"]
    for param in (f"scene:={scene}", "duration:=0.001", "realtime:=false", "command_timeout:=0.0"):
        cmd += ["-p", param]
    return cmd


def _env(cache: str | None) -> dict[str, str]:
    """The environment of a measured process: numba's cache in ``cache`` (None: the default)."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("NUMBA_CACHE_DIR", None)
    env.pop("VJM_TIERED", None)  # the default: tiered where the cache lacks the kernels
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = cache
    return env


def wall_time(cmd: list[str], env: dict[str, str]) -> tuple[float, float]:
    """Wall time of one process from start to exit, and the CPU time it used (user and system),
    s (raises when it fails). Under load the CPU time grows less than the wall time."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=TIMEOUT)
    elapsed = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with {done.returncode}: {done.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return elapsed, cpu


def import_times(stderr: str) -> dict[str, float]:
    """Import time per top-level package from ``python -X importtime`` output, s.

    Parameters
    ----------
    stderr : str
        The process's standard error.

    Returns
    -------
    dict
        Package name to the sum of the self times of its modules, s, largest first.
    """
    totals: dict[str, float] = defaultdict(float)
    for line in stderr.splitlines():
        match = _IMPORT_LINE.match(line)
        if match:
            totals[match.group(4).split(".")[0]] += int(match.group(1)) * 1e-6
    return dict(sorted(totals.items(), key=lambda kv: -kv[1]))


def warm_imports(scene: str) -> dict[str, float]:
    """Import time per top-level package of a warm ``vjm run`` of one tick, s."""
    cmd = run_command(scene)
    if cmd[0] != sys.executable:
        cmd = [sys.executable, "-m", "vjm_ros.app.cli", *cmd[1:]]
    done = subprocess.run([cmd[0], "-X", "importtime", *cmd[1:]], env=_env(None),
                          capture_output=True, text=True, timeout=TIMEOUT)
    return import_times(done.stderr)


def stages(scene: str) -> tuple[dict[str, float], int]:
    """Wall time of each stage of a start in this process, in order, s, and the ticks run as
    plain Python after the first one until the ticks ran compiled (0 when the compiled code was
    loaded at the first call after the first tick).

    Stages, as ``vjm run`` goes: ``import`` (what it imports before it builds the simulator,
    :mod:`vjm_ros.app.cli` itself aside),
    ``scene`` (the scene file to a model and settings), ``kernel`` (the compiled
    entry point :func:`vjm_ros.core.kernels.step` loaded from numba's cache or compiled, while the
    simulator is built; 0 where entry points start as plain Python: the kernel is then left to
    its first calls, :data:`~vjm_ros.core.mechanism.STEP_PLAIN_CALLS`), ``simulator`` (the rest of
    building it), ``first_tick`` (one tick advanced and sampled: as plain Python where entry points
    start so, :data:`~vjm_ros.core.mechanism.PIPELINE_PLAIN_CALLS`), ``numba`` (numba imported and
    the compiled functions made, :func:`vjm_ros.jit.deferred.activate`, which the next call of the
    pipeline would do), ``compiled`` (from there until the ticks run compiled: the pipeline
    :func:`vjm_ros.core.pipeline.advance_ticks` loaded from numba's cache, or, cold, compiled in
    the background while ticks advance as plain Python, in calls of
    :data:`~vjm_ros.core.mechanism.PLAIN_PART_TICKS`).

    Run it in a fresh process: modules imported and functions loaded before are not counted.
    """
    times: dict[str, float] = {}

    def lap(name: str, start: float) -> float:
        now = time.perf_counter()
        times[name] = now - start
        return now

    t = time.perf_counter()
    import numpy  # noqa: F401

    import vjm_ros.logs.signals  # noqa: F401
    import vjm_ros.logs.storage  # noqa: F401
    from vjm_ros.jit import deferred
    from vjm_ros.scene.loader import load_scene
    from vjm_ros.sim.samples import SampleBlock
    from vjm_ros.sim.settings import resolve_settings
    from vjm_ros.sim.simulator import Simulator
    from vjm_ros.sim.trajectory import Trajectory

    t = lap("import", t)
    sc = load_scene(scene)
    settings = resolve_settings(sc.defaults, sc.gains)
    t = lap("scene", t)
    sim = Simulator(sc.model, settings, sc.gains)
    now = time.perf_counter()
    warm_up = getattr(sim.mechanism, "warm_up_time", math.nan)
    times["kernel"] = 0.0 if math.isnan(warm_up) else warm_up  # nan: left to its first calls
    times["simulator"] = now - t - times["kernel"]
    t = now
    traj = Trajectory(sc.model, capacity=3)
    block = SampleBlock(sc.model, 1)
    sim.advance_block(block, 1)
    traj.extend(block)
    t = lap("first_tick", t)
    deferred.activate()
    t = lap("numba", t)
    deadline = t + TIMEOUT
    calls = 0
    while sim.mechanism.tier != "compiled" and time.perf_counter() < deadline:
        sim.advance_block(block, 1)
        calls += 1
    lap("compiled", t)
    return times, max(calls - 1, 0)  # the last call ran compiled


def stages_in_process(scene: str, cache: str | None) -> tuple[dict[str, float], int]:
    """:func:`stages` in a fresh process with numba's cache in ``cache`` (None: the default)."""
    done = subprocess.run([sys.executable, "-m", "benchmarks.start_time", "--stages", scene],
                          env=_env(cache), cwd=ROOT, capture_output=True, text=True,
                          timeout=TIMEOUT)
    if done.returncode != 0:
        raise RuntimeError(f"stages of {scene} failed: {done.stderr[-2000:]}")
    times, plain_ticks = json.loads(done.stdout.strip().splitlines()[-1])
    return times, int(plain_ticks)


def measure(scene: str, repeats: int, cold_repeats: int) -> dict:
    """Every figure of the module docstring for ``scene``.

    Returns
    -------
    dict
        ``floor_s``, ``warm_s``, ``cold_s`` (median wall times, s), ``warm_cpu_s``,
        ``cold_cpu_s`` (median CPU times of the same processes, s), ``cold_compiled_first_s``,
        ``cold_compiled_first_cpu_s`` (one cold run with ``VJM_TIERED=0``), ``warm_runs_s``,
        ``cold_runs_s`` (each run's wall time, s), ``warm_stages_s``, ``cold_stages_s``,
        ``warm_plain_ticks``, ``cold_plain_ticks`` (:func:`stages`), ``warm_imports_s`` (:func:`import_times`, the ten largest),
        ``load_1min``.
    """
    cmd = run_command(scene)
    wall_time(cmd, _env(None))  # fills numba's cache if it is empty
    floor = [wall_time([sys.executable, "-c", "pass"], _env(None)) for _ in range(repeats)]
    warm = [wall_time(cmd, _env(None)) for _ in range(repeats)]
    cold = []
    for _ in range(cold_repeats):
        with tempfile.TemporaryDirectory() as cache:
            cold.append(wall_time(cmd, _env(cache)))
    with tempfile.TemporaryDirectory() as cache:
        compiled_first = wall_time(cmd, dict(_env(cache), VJM_TIERED="0"))
    with tempfile.TemporaryDirectory() as cache:
        cold_stages, cold_plain_ticks = stages_in_process(scene, cache)
    imports = warm_imports(scene)
    warm_stages, warm_plain_ticks = stages_in_process(scene, None)
    return {
        "scene": scene,
        "floor_s": statistics.median(w for w, _ in floor),
        "warm_s": statistics.median(w for w, _ in warm),
        "cold_s": statistics.median(w for w, _ in cold),
        "warm_cpu_s": statistics.median(c for _, c in warm),
        "cold_cpu_s": statistics.median(c for _, c in cold),
        "cold_compiled_first_s": compiled_first[0],
        "cold_compiled_first_cpu_s": compiled_first[1],
        "warm_runs_s": [w for w, _ in warm],
        "cold_runs_s": [w for w, _ in cold],
        "warm_stages_s": warm_stages,
        "cold_stages_s": cold_stages,
        "warm_plain_ticks": warm_plain_ticks,
        "cold_plain_ticks": cold_plain_ticks,
        "warm_imports_s": dict(list(imports.items())[:10]),
        "load_1min": os.getloadavg()[0],
    }


def _stage_line(times: dict[str, float]) -> str:
    return ", ".join(f"{k} {v:.2f}" for k, v in times.items())


def render_section(row: dict, when: str) -> str:
    """The start-time section of ``docs/accuracy.md`` from :func:`measure`'s figures."""
    warm, cold = row["warm_stages_s"], row["cold_stages_s"]
    lines = [
        HEADING,
        "",
        f"Written by `python -m benchmarks.start_time --docs docs/accuracy.md` ({when}; "
        f"1-minute load average {row['load_1min']:.1f} on this shared machine: the figures vary "
        "2-4x with load, compare those of one run). Whole process of "
        f"`vjm run {row['scene']} --duration 0.001` (one control tick), median of "
        f"{len(row['warm_runs_s'])} runs warm (numba's cache filled) and of "
        f"{len(row['cold_runs_s'])} cold (an empty `NUMBA_CACHE_DIR`: the kernels run as plain "
        "Python, and a run longer than its first ticks has a child process compile them, "
        "`vjm_ros.jit.tiers`; a one-tick run ends before that), and one cold with "
        "`VJM_TIERED=0` (every compiled entry point compiled before the first tick); "
        f"`python -c pass` takes {row['floor_s']:.2f} s.",
        "",
        "| start | whole process, wall s | its CPU time s | target s |",
        "|---|---|---|---|",
        f"| warm | {row['warm_s']:.2f} | {row['warm_cpu_s']:.2f} | 0.5 |",
        f"| cold | {row['cold_s']:.2f} | {row['cold_cpu_s']:.2f} | 3 |",
        *([f"| cold, compiled first (`VJM_TIERED=0`) | {row['cold_compiled_first_s']:.2f} | "
           f"{row['cold_compiled_first_cpu_s']:.2f} | – |"]
          if "cold_compiled_first_s" in row else []),
        *([f"| node warm (`vjm_sim_node`, one tick, rclpy included) | {row['node_warm_s']:.2f} | "
           f"{row['node_warm_cpu_s']:.2f} | – |"] if "node_warm_s" in row else []),
        "",
        "Stages in a fresh process (s; `first_tick`: as plain Python, before numba is imported; "
        "`numba`: numba imported and the compiled functions made; `compiled`: until the ticks "
        "run compiled, the block pipeline `pipeline.advance_ticks` loaded from numba's cache "
        "(warm) or compiled in the background while the ticks run as plain Python (cold); "
        "numba's own typing and lowering tables are loaded only when something is compiled). "
        "A run's first tick comes after the stages up to `first_tick`, whatever its length; "
        "a one-tick run ends there:",
        "",
        "| stage | " + " | ".join(warm) + " |",
        "|---|" + "---|" * len(warm),
        "| warm | " + " | ".join(f"{v:.2f}" for v in warm.values()) + " |",
        "| cold | " + " | ".join(f"{cold.get(k, float('nan')):.2f}" for k in warm) + " |",
        "",
        "Import time of a warm run per top-level package (`-X importtime`, self times summed, s): "
        + ", ".join(f"{k} {v:.3f}" for k, v in row["warm_imports_s"].items()) + ".",
        "",
    ]
    return "\n".join(lines)


def write_section(path: Path, section: str) -> None:
    """Put ``section`` in the page at ``path`` in place of its start-time section, or at its end."""
    text = path.read_text() if path.exists() else ""
    path.write_text(with_section(text, HEADING, section))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.start_time",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--scene", default="four_bar")
    parser.add_argument("--repeats", type=int, default=5, help="warm runs (median)")
    parser.add_argument("--cold-repeats", type=int, default=1, help="cold runs (median)")
    parser.add_argument("--json", action="store_true", help="figures as JSON on the last line")
    parser.add_argument("--node", action="store_true",
                        help="also the node's warm start to its first tick (needs ROS 2)")
    parser.add_argument("--docs", type=Path, metavar="PAGE",
                        help="write the figures as the page's start-time section")
    parser.add_argument("--stages", metavar="SCENE", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.stages:
        print(json.dumps(list(stages(args.stages))))
        return 0
    if args.repeats < 1 or args.cold_repeats < 1:
        parser.error("--repeats and --cold-repeats: expected at least 1")
    row = measure(args.scene, args.repeats, args.cold_repeats)
    if args.node:
        wall_time(node_command(args.scene), _env(None))  # not timed: loads what the node loads
        node = [wall_time(node_command(args.scene), _env(None)) for _ in range(args.repeats)]
        row["node_warm_s"] = statistics.median(w for w, _ in node)
        row["node_warm_cpu_s"] = statistics.median(c for _, c in node)
    print(f"vjm run {args.scene} --duration 0.001, whole process (python -c pass: "
          f"{row['floor_s']:.2f} s), load {row['load_1min']:.2f}")
    print(f"  warm {row['warm_s']:.2f} s, CPU {row['warm_cpu_s']:.2f} s (median of "
          f"{args.repeats}; target <= 0.5 s)")
    print(f"  cold {row['cold_s']:.2f} s, CPU {row['cold_cpu_s']:.2f} s (empty numba cache, median "
          f"of {args.cold_repeats}; target <= 3 s)")
    print(f"  cold, compiled first (VJM_TIERED=0) {row['cold_compiled_first_s']:.2f} s, CPU "
          f"{row['cold_compiled_first_cpu_s']:.2f} s")
    if args.node:
        print(f"  node warm {row['node_warm_s']:.2f} s, CPU {row['node_warm_cpu_s']:.2f} s "
              f"(vjm_sim_node, one tick in fast mode, rclpy included)")
    print(f"  warm stages, s: {_stage_line(row['warm_stages_s'])}")
    print(f"  cold stages, s: {_stage_line(row['cold_stages_s'])} ({row['cold_plain_ticks']} "
          "ticks as plain Python before the compiled ones)")
    print(f"  warm imports (-X importtime, self, s): {_stage_line(row['warm_imports_s'])}")
    if args.docs is not None:
        when = time.strftime("%Y-%m-%dT%H:%M:%S+00:00", time.gmtime())
        write_section(args.docs, render_section(row, when))
    if args.json:
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
