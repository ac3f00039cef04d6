"""What the logs of ``vjm run`` cost against the physics-only run of the same scene and settings.

``python -m benchmarks.log_cost [--scene four_bar] [--seconds 10] [--rounds 5]`` runs, as a
user runs it, a fresh ``vjm run`` process per run, interleaved round by round, of one scene with
rk4 at 1 kHz and exact closure, and reads two times of each: the ``wall_time`` of its summary (the
run, from its first tick to its last log finalized) and the process's elapsed time (what the user
waits for, start-up included). ``--in-process`` runs the parsed command in this process instead,
after a warm-up (the logs' steady cost, without imports). The configurations:

1. **physics**: no output;
2. **+csv**: ``--out`` (``trajectory.csv`` and ``summary.json``);
3. **+mcap**: ``--mcap``;
4. **+rrd**: ``--rrd`` to a file;
5. **all**: ``--out --mcap --rrd``.

It prints the best wall time of each (ms per simulated second) and its ratio to the physics-only
run (issue target for *all*: at most 1.5), and, for fresh processes, the ``cpu_time`` each
reports (its CPU time over the same span, every thread), the machine's floor (the physics-only
run with the second core kept busy by another process, which any log written beside the physics
costs on this machine: a shared virtual machine's core slows when its neighbour works) and the
two-core bound (the run with all logs ends no sooner than its CPU time spread over two cores).
A first round, not counted, loads the compiled code and the log libraries. Wall times on a
shared 2-core machine vary 2-4x from run to run: compare the ratios of one run. ``--json`` prints
the figures as one JSON object; ``--parts`` adds the parts of one profiled run with all logs
(physics, CSV, MCAP encoding, records and indexes, chunks and their compression, rerun), as
shares of that run. ``--repeats N`` measures the fresh processes N times over and ends with
how the figures spread from one measure to the next (:func:`spread`): on a shared machine one
measure of a few rounds can fall on either side of the target.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from vjm_ros.studies.pages import with_section

CONFIGS = ("physics", "+csv", "+mcap", "+rrd", "all")


def _options(config: str, folder: Path) -> list[str]:
    """The ``vjm run`` options of one configuration, writing into ``folder``."""
    out = ["--out", str(folder / "out")]
    mcap = ["--mcap", str(folder / "run.mcap")]
    rrd = ["--rrd", str(folder / "run.rrd")]
    return {"physics": [], "+csv": out, "+mcap": mcap, "+rrd": rrd,
            "all": out + mcap + rrd}[config]


def run_once(scene: str, seconds: float, config: str, folder: Path) -> float:
    """Wall seconds of one ``vjm run`` (rk4, 1 kHz, exact closure) with the logs of ``config``."""
    from vjm_ros.app import cli

    argv = ["run", scene, "--integrator", "rk4", "--rate", "1000", "--substeps", "1",
            "--closure", "exact", "--duration", str(seconds), "--json"]
    args = cli._parser().parse_args(argv + _options(config, folder))
    with contextlib.redirect_stdout(io.StringIO()):
        t0 = time.perf_counter()
        code = cli._cmd_run(args)
        wall = time.perf_counter() - t0
    if code != 0:
        raise RuntimeError(f"vjm run {' '.join(argv)} ({config}) ended with exit code {code}")
    return wall


def vjm_command() -> list[str]:
    """The ``vjm`` of this Python (its console script, or the module where none is installed)."""
    script = Path(sys.executable).with_name("vjm")
    if script.is_file():
        return [str(script)]
    return [sys.executable, "-c", "import sys; from vjm_ros.app.cli import main; sys.exit(main())"]


def run_fresh(scene: str, seconds: float, config: str,
              folder: Path) -> tuple[float, float, float, float]:
    """``(wall_time, elapsed, cpu_time, outputs_wait_time)`` in s of one fresh ``vjm run``
    process with the logs of ``config``.

    ``wall_time``, ``cpu_time`` (the process's CPU time over the same span, every thread) and
    ``outputs_wait_time`` (the part of ``wall_time`` after the last tick) are what the process
    reports in its summary; ``elapsed`` is measured around the process, from its start to its
    exit.
    """
    for path in ("out", "run.mcap", "run.rrd"):  # each run writes its outputs anew
        target = folder / path
        if target.is_dir():
            shutil.rmtree(target)
        elif target.exists():
            target.unlink()
    argv = ["run", scene, "--integrator", "rk4", "--rate", "1000", "--substeps", "1",
            "--closure", "exact", "--duration", str(seconds), "--json"]
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    t0 = time.perf_counter()
    done = subprocess.run(vjm_command() + argv + _options(config, folder), env=env,
                          capture_output=True, text=True, check=False)
    elapsed = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"vjm {' '.join(argv)} ({config}) ended with exit code "
                           f"{done.returncode}: {done.stderr.strip()[-500:]}")
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    return summary["wall_time"], elapsed, summary["cpu_time"], summary["outputs_wait_time"]


@contextlib.contextmanager
def busy_core():
    """A process that keeps one core busy (a Python loop doing nothing) at the scheduling
    priority of ``vjm run``'s log threads (:data:`vjm_ros.logs.background.NICENESS`), for as
    long as the context lasts."""
    from vjm_ros.logs.background import NICENESS

    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"],
                               preexec_fn=lambda: os.nice(NICENESS))
    try:
        yield spinner
    finally:
        spinner.kill()
        spinner.wait()


def measure_fresh(scene: str = "four_bar", seconds: float = 10.0, rounds: int = 5) -> dict:
    """Best ``wall_time`` and best elapsed time per configuration, fresh processes, and the
    machine's floor for any log written beside the physics.

    The floor is the physics-only run with the second core kept busy by another process
    (:func:`busy_core`), interleaved with the others: logs written while the physics runs
    occupy that core, and whatever the physics loses to a busy neighbour (shared caches and
    memory bandwidth, a virtual machine's scheduling) no logger avoids.

    Returns
    -------
    dict
        ``wall_ms`` and ``elapsed_ms`` per configuration of :data:`CONFIGS` (best over the
        rounds), ``wait_ms`` (the ``outputs_wait_time`` of the run with the best ``wall_ms``),
        ``ratio`` and ``elapsed_ratio`` (to the physics-only run), ``cpu_ms`` (the least
        ``cpu_time`` of each), ``two_cores`` (the least ratio the run with all logs can
        reach on two cores: its CPU time spread over both, to the physics-only run's wall time,
        at least 1), ``floor`` (the busy-core run: its best ``wall_ms``, its ``ratio`` to the
        physics-only run and the ratio of the run with all logs to it, ``all_ratio``), with the
        scene, the simulated seconds, the rounds and the machine's ``load`` average before and
        after.
    """
    wall = dict.fromkeys(CONFIGS, float("inf"))
    elapsed = dict.fromkeys(CONFIGS, float("inf"))
    cpu = dict.fromkeys(CONFIGS, float("inf"))
    wait = dict.fromkeys(CONFIGS, 0.0)
    busy = float("inf")
    load_before = _load_average()
    with tempfile.TemporaryDirectory(prefix="vjm_log_cost_") as tmp:
        for _ in range(rounds):
            for config in CONFIGS:
                w, e, c, after = run_fresh(scene, seconds, config, Path(tmp))
                if w < wall[config]:
                    wall[config], wait[config] = w, after
                elapsed[config] = min(elapsed[config], e)
                cpu[config] = min(cpu[config], c)
            with busy_core():
                busy = min(busy, run_fresh(scene, seconds, "physics", Path(tmp))[0])
    return {
        "floor": {"wall_ms": 1e3 * busy, "ratio": busy / wall["physics"],
                  "all_ratio": wall["all"] / busy},
        "cpu_ms": {c: 1e3 * cpu[c] for c in CONFIGS},
        "two_cores": max(1.0, cpu["all"] / 2 / wall["physics"]),
        "scene": scene, "seconds": seconds, "rounds": rounds, "fresh": True,
        "wall_ms": {c: 1e3 * wall[c] for c in CONFIGS},
        "wait_ms": {c: 1e3 * wait[c] for c in CONFIGS},
        "elapsed_ms": {c: 1e3 * elapsed[c] for c in CONFIGS},
        "ratio": {c: wall[c] / wall["physics"] for c in CONFIGS},
        "elapsed_ratio": {c: elapsed[c] / elapsed["physics"] for c in CONFIGS},
        "load": f"{load_before} before, {_load_average()} after",
    }


def measure(scene: str = "four_bar", seconds: float = 10.0, rounds: int = 5) -> dict:
    """Best wall time per configuration over ``rounds`` interleaved rounds.

    Returns
    -------
    dict
        ``ms_per_sim_s`` and ``ratio`` (to the physics-only run) per configuration of
        :data:`CONFIGS`, ``cpu_ms_per_sim_s`` (the least CPU time of the process, all its
        threads, over the rounds), with the scene, the simulated seconds, the rounds and the
        machine's ``load`` average before and after.
    """
    best = dict.fromkeys(CONFIGS, float("inf"))
    cpu = dict.fromkeys(CONFIGS, float("inf"))
    load_before = _load_average()
    with tempfile.TemporaryDirectory(prefix="vjm_log_cost_") as tmp:
        folder = Path(tmp)
        for config in CONFIGS:  # warm-up: compiled code, log libraries
            run_once(scene, min(seconds, 0.5), config, folder)
        for _ in range(rounds):
            for config in CONFIGS:
                cpu0 = time.process_time()
                best[config] = min(best[config], run_once(scene, seconds, config, folder))
                cpu[config] = min(cpu[config], time.process_time() - cpu0)
    physics = best["physics"]
    return {
        "scene": scene,
        "seconds": seconds,
        "rounds": rounds,
        "ms_per_sim_s": {c: 1e3 * best[c] / seconds for c in CONFIGS},
        "ratio": {c: best[c] / physics for c in CONFIGS},
        "cpu_ms_per_sim_s": {c: 1e3 * cpu[c] / seconds for c in CONFIGS},
        "load": f"{load_before} before, {_load_average()} after",
    }


def _load_average() -> str:
    """The machine's 1-minute load average (what else ran on it), or ``"unknown"``."""
    try:
        return f"{os.getloadavg()[0]:.2f}"
    except (AttributeError, OSError):
        return "unknown"


PARTS = (
    ("physics (advance_block)", "sim/simulator.py", "advance_block"),
    ("trajectory: extend", "sim/trajectory.py", "extend"),
    ("csv: trajectory.csv", "sim/trajectory.py", "catch_up"),
    ("mcap: open", "logs/mcap_recorder.py", "__init__"),
    ("mcap: encode blocks", "logs/mcap_block.py", "encode"),
    ("mcap: add records, index", "logs/mcap_block.py", "add_run"),
    ("mcap: close chunks", "logs/mcap_block.py", "_Writer__finalize_chunk"),
    ("mcap:   of which zstd", "~",
     "<method 'compress' of 'zstandard.backend_c.ZstdCompressor' objects>"),
    ("mcap: finalize file", "logs/mcap_recorder.py", "_finalize"),
    ("rrd: open", "logs/rerun_recorder.py", "__init__"),
    ("rrd: buffer blocks", "logs/rerun_recorder.py", "write_block"),
    ("rrd: send chunks (also at finalize)", "logs/rerun_recorder.py", "send"),
    ("rrd: finalize file", "logs/rerun_recorder.py", "_finalize"),
)
"""Parts of the *all* run: label, file (path suffix; ``~`` for a built-in) and function whose
cumulative time it is."""


def breakdown(scene: str = "four_bar", seconds: float = 10.0) -> dict[str, float]:
    """Seconds per part (:data:`PARTS`) of one *all* run, under :mod:`cProfile`, with the
    outputs written in the calling thread after each block
    (:data:`vjm_ros.logs.background.IN_CALLING_THREAD`).

    In ``vjm run`` the outputs work in threads of their own (the MCAP log in one, the CSV and
    the rerun log in another); run one after the other in one thread, a profile shows what each
    part costs without the waits of threads for the GIL or a core. ``"run"`` is that run's
    wall time: the sum of the physics and of every output. Profiling slows calls down, the more
    the smaller they are: read the parts as shares, not as absolute times.
    """
    import cProfile
    import pstats

    from vjm_ros.logs import background

    with tempfile.TemporaryDirectory(prefix="vjm_log_cost_") as tmp:
        background.IN_CALLING_THREAD = True
        try:
            run_once(scene, min(seconds, 0.5), "all", Path(tmp))
            profile = cProfile.Profile()
            profile.enable()
            total = run_once(scene, seconds, "all", Path(tmp))
            profile.disable()
        finally:
            background.IN_CALLING_THREAD = False
    stats = pstats.Stats(profile).stats  # (file, line, function) -> (cc, nc, tt, ct, callers)
    out = {"run": total}
    for label, suffix, function in PARTS:
        out[label] = sum(v[3] for (file, _, name), v in stats.items()
                         if name == function and file.replace("\\", "/").endswith(suffix))
    return out


LOG_COST_HEADING = "## Cost of the logs of `vjm run`"
"""Heading of the section of ``docs/accuracy.md`` written by ``--docs``."""


TARGET = 1.5
"""Issue target: a run with all three logs costs at most this many physics-only runs."""


def fresh_verdict(r: dict) -> str:
    """Whether the run with all logs is within :data:`TARGET` of the run without outputs
    (figures of :func:`measure_fresh`), counted against the faster of the two series without
    outputs: the free core's and the busy core's (the floor). A busy-core run faster than the
    free core's best shows that the machine slowed the free core's series; a ratio to that
    series alone would then favour the logs."""
    ratio = r["ratio"]["all"]
    if ratio > TARGET:
        return "not met"
    floor = r.get("floor")
    if floor is not None and floor["all_ratio"] > TARGET:
        return (f"not counted as met: the run without outputs beside a busy core was faster "
                f"({floor['wall_ms']:.0f} ms), and against it the logs take "
                f"{floor['all_ratio']:.2f}x")
    return "met"


def spread(results: list[dict]) -> dict:
    """How repeated measures of :func:`measure_fresh` (of the same code, one after the other)
    differ: the ratio of the run with all logs to the run without outputs, the two-core bound,
    the ratio to the machine's floor and the CPU time of the runs without and with all logs.

    Returns
    -------
    dict
        ``repeats``; ``met``: how many measures :func:`fresh_verdict` counts as met; ``ratio``,
        ``two_cores``, ``floor_ratio`` (ratios), ``cpu_physics_ms`` and ``cpu_all_ms`` (ms),
        each ``(least, median, largest)`` over the measures.
    """
    def triple(values: list[float]) -> tuple[float, float, float]:
        return min(values), statistics.median(values), max(values)

    return {
        "repeats": len(results),
        "met": sum(fresh_verdict(r) == "met" for r in results),
        "ratio": triple([r["ratio"]["all"] for r in results]),
        "two_cores": triple([r["two_cores"] for r in results]),
        "floor_ratio": triple([r["floor"]["all_ratio"] for r in results]),
        "cpu_physics_ms": triple([r["cpu_ms"]["physics"] for r in results]),
        "cpu_all_ms": triple([r["cpu_ms"]["all"] for r in results]),
    }


def render_spread(s: dict) -> list[str]:
    """Lines saying how the repeated measures spread (figures of :func:`spread`)."""
    def span(key: str, unit: str = "x", digits: int = 2) -> str:
        lo, mid, hi = s[key]
        return f"{lo:.{digits}f}{unit} to {hi:.{digits}f}{unit}, median {mid:.{digits}f}{unit}"

    return [
        f"{s['repeats']} measures: all logs / no output {span('ratio')} "
        f"(target {TARGET:g}x met in {s['met']} of {s['repeats']})",
        f"  two-core bound {span('two_cores')}; all logs / floor {span('floor_ratio')}",
        f"  cpu_time without outputs {span('cpu_physics_ms', ' ms', 1)}; "
        f"with all logs {span('cpu_all_ms', ' ms', 1)}",
    ]


def render_fresh(r: dict) -> list[str]:
    """Lines of the fresh-process table (figures of :func:`measure_fresh`)."""
    names = {"physics": "no output", "+csv": "`--out` (CSV, summary)", "+mcap": "`--mcap`",
             "+rrd": "`--rrd`", "all": "`--out --mcap --rrd`"}
    verdict = fresh_verdict(r)
    lines = [
        f"A fresh `vjm run {r['scene']} --integrator rk4 --closure exact --duration "
        f"{r['seconds']:g}` process per run, as a user runs it, best of {r['rounds']} "
        "interleaved: the `wall_time` it reports (first tick to last log finalized; the "
        "imports of the log libraries, made while the scene loads, and the opening of the "
        "logs, made while the compiled pipeline loads, are start-up) and the process's "
        "elapsed time (start-up included).",
        "",
        "| outputs | wall_time ms | / no output | after the last tick ms | elapsed ms "
        "| / no output | cpu_time ms |",
        "|---|---|---|---|---|---|---|",
    ]
    lines += [f"| {names[c]} | {r['wall_ms'][c]:.0f} | {r['ratio'][c]:.2f} | "
              f"{r['wait_ms'][c]:.1f} | {r['elapsed_ms'][c]:.0f} | "
              f"{r['elapsed_ratio'][c]:.2f} | {r['cpu_ms'][c]:.0f} |" for c in CONFIGS]
    lines += ["", f"- **All three logs**: `wall_time` {r['ratio']['all']:.2f}x the run without "
              f"outputs (target {TARGET:g}x: {verdict}); elapsed "
              f"{r['elapsed_ratio']['all']:.2f}x.",
              f"- **Two cores**: the run with all three logs uses {r['cpu_ms']['all']:.0f} ms of "
              f"CPU ({r['cpu_ms']['all'] / r['cpu_ms']['physics']:.2f}x the run without "
              "outputs); spread over both cores at best, it takes at least "
              f"{r['two_cores']:.2f}x the run without outputs: what is above that is the "
              "threads' scheduling and the finalization after the last tick.",
              f"- **After the last tick**: {r['wait_ms']['all']:.0f} ms of the best run with all "
              "three logs (its `outputs_wait_time`) went to the blocks the logs had not yet "
              "written when the physics ended and to finalizing the logs, against "
              f"{r['wait_ms']['physics']:.1f} ms without outputs."]
    if "floor" in r:
        f = r["floor"]
        lines += [f"- **The machine's floor**: the run without outputs, with the second core "
                  f"kept busy by another process at the logs' priority, takes {f['wall_ms']:.0f} "
                  f"ms, {f['ratio']:.2f}x the run without outputs on a free core (what the two "
                  "series of the physics alone differ by beyond that share is this machine's "
                  f"noise); the run with all three logs takes {f['all_ratio']:.2f}x that."]
    lines += [""]
    return lines


def render_section(r: dict) -> str:
    """The ``docs/accuracy.md`` section of measured figures ``r`` (:func:`measure`, with
    ``fresh`` from :func:`measure_fresh` and ``parts_s`` from :func:`breakdown` when
    present)."""
    import datetime
    import platform

    import numpy as np

    when = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()
    ratio, ms = r["ratio"], r["ms_per_sim_s"]
    verdict = "met" if ratio["all"] <= TARGET else "not met"
    lines = [
        LOG_COST_HEADING, "",
        f"This section is written by `python -m benchmarks.log_cost --rounds {r['rounds']} "
        f"--parts --docs docs/accuracy.md` ({when}; {os.cpu_count()}-core {platform.machine()} "
        f"machine, Python {platform.python_version()}, numpy {np.__version__}); `vjm bench` "
        "keeps it when it rewrites the page.",
        "",
        *(render_fresh(r["fresh"]) if "fresh" in r else []),
        f"`vjm run {r['scene']}` with rk4 at 1 kHz and exact closure for {r['seconds']:g} "
        "simulated seconds, in one process, without and with each log; every configuration "
        f"runs {r['rounds']} times, interleaved with the others, and the best wall time counts: "
        "the whole run (scene, logs opened, ticks in blocks of up to 1000, logs finalized, "
        "`trajectory.csv` and `summary.json` written), not the interpreter's start-up or the "
        "loading of compiled code and libraries (done once before). Only the ratios are "
        "meaningful, the machine is shared.",
        "",
        "| run | ms per sim s | / physics only | CPU ms per sim s (all threads) |",
        "|---|---|---|---|",
    ]
    names = {"physics": "physics only", "+csv": "`--out` (CSV, summary)", "+mcap": "`--mcap`",
             "+rrd": "`--rrd`", "all": "`--out --mcap --rrd`"}
    cpu = r.get("cpu_ms_per_sim_s", {})
    lines += [f"| {names[c]} | {ms[c]:.3g} | {ratio[c]:.2f} | {cpu.get(c, float('nan')):.3g} |"
              for c in CONFIGS]
    lines += [
        "",
        f"- **All three logs**: {ratio['all']:.2f}x the physics-only run; target "
        f"{TARGET:g}x {verdict}.",
        f"- **Each log alone** adds {ratio['+csv'] - 1:.2f} (CSV), {ratio['+mcap'] - 1:.2f} "
        f"(MCAP) and {ratio['+rrd'] - 1:.2f} (rerun) physics-only runs.",
        "- The CSV holds every value as Python's `repr` writes it (the shortest text that reads "
        "back to the same double), formatted by compiled code (Ryu's shortest digits); the file "
        "is byte-identical to the one written row by row. MCAP records are built a block of "
        "ticks at a time from byte images of each topic, in buffers kept for the whole file, "
        "and compressed per chunk (zstd level -3), every record the bytes rosbags' serializer "
        "writes; rerun receives arrow columns built from whole arrays, one chunk per entity in "
        "one `send_chunks` for each equal share of the run's samples, about 5000 each (a 10 s "
        "run at 1 kHz: two sends of 5001 and 5000).",
        "- The physics runs in one thread, blocks of up to 1000 ticks per compiled call (the "
        "first ones shorter, so that the logs start early) without the GIL; the MCAP log takes "
        "the blocks in a thread of its own, the trajectory and its CSV and the rerun recording "
        "in another (opening their files there while the compiled "
        "pipeline loads), at a lower scheduling priority than the physics, so on two cores the "
        "logs are written while the next blocks are computed. The wall time then depends on "
        "what else the machine runs: with the second core busy, the logs' CPU adds up with the "
        f"physics (1-minute load average when measured: {r.get('load', 'not recorded')}). "
        "On two free cores a run takes at least half its CPU time: with all three logs "
        f"{cpu.get('all', float('nan')) / 2:.3g} ms per simulated s (half of "
        f"{cpu.get('all', float('nan')):.3g}), where the target allows "
        f"{TARGET * ms['physics']:.3g}.",
    ]
    if "parts_s" in r:
        parts = r["parts_s"]
        lines += [
            "",
            "Where the time of one run with all logs goes, under `cProfile`, with the outputs "
            "written one after the other in the thread of the physics (in `vjm run` they work "
            "in two threads of their own; here each part's cost shows without waits) "
            f"({1e3 * parts['run']:.0f} ms; profiling slows small calls most, so read shares, "
            "not times):",
            "",
            "| part | ms | share of the run |",
            "|---|---|---|",
        ]
        lines += [f"| {label.strip()} | {1e3 * parts[label]:.1f} | "
                  f"{100 * parts[label] / parts['run']:.1f} % |" for label, _, _ in PARTS]
    return "\n".join(lines) + "\n"


def _print_fresh(fresh: dict) -> None:
    """Print the table of one fresh-process measure (figures of :func:`measure_fresh`)."""
    print(f"{fresh['scene']}, rk4 1 kHz exact, {fresh['seconds']:g} s, fresh processes, "
          f"best of {fresh['rounds']} rounds; 1-minute load average {fresh['load']}")
    print(f"{'outputs':10s} {'wall_time ms':>13s} {'/ none':>7s} {'after last':>11s} "
          f"{'elapsed ms':>11s} {'/ none':>7s} {'cpu_time ms':>12s}")
    for c in CONFIGS:
        print(f"{c:10s} {fresh['wall_ms'][c]:13.1f} {fresh['ratio'][c]:7.2f} "
              f"{fresh['wait_ms'][c]:11.1f} {fresh['elapsed_ms'][c]:11.0f} "
              f"{fresh['elapsed_ratio'][c]:7.2f} {fresh['cpu_ms'][c]:12.1f}")
    floor = fresh["floor"]
    print(f"{'busy core':10s} {floor['wall_ms']:13.1f} {floor['ratio']:7.2f}   (floor: the "
          f"physics beside a busy core; all / floor {floor['all_ratio']:.2f})")
    print(f"{'two cores':10s} {'':13s} {fresh['two_cores']:7.2f}   (the least the run with all "
          "logs can take: its cpu_time spread over two cores)")


def main(argv: list[str] | None = None) -> int:
    """Command line entry: measure and print the table (or JSON)."""
    from vjm_ros.jit import tiers

    tiers.compile_first()  # times compiled code, never the plain-Python tier
    p = argparse.ArgumentParser(prog="python -m benchmarks.log_cost", description=__doc__)
    p.add_argument("--scene", default="four_bar")
    p.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per run")
    p.add_argument("--rounds", type=int, default=5, help="interleaved rounds (best is kept)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.add_argument("--in-process", action="store_true",
                   help="run the command in this process after a warm-up (steady cost only)")
    p.add_argument("--parts", action="store_true",
                   help="also profile one run with all logs and print its parts")
    p.add_argument("--docs", type=Path, metavar="FILE",
                   help="write the figures as a section of FILE (e.g. docs/accuracy.md)")
    p.add_argument("--repeats", type=int, default=1, metavar="N",
                   help="measure the fresh processes N times and say how the measures spread")
    args = p.parse_args(argv)
    if args.repeats < 1:
        p.error(f"--repeats: expected a whole number of at least 1, found {args.repeats}")
    if args.repeats > 1:
        if args.in_process or args.parts or args.docs is not None:
            p.error("--repeats: only for the fresh processes' measure, without --in-process, "
                    "--parts and --docs")
        runs = []
        for _ in range(args.repeats):
            runs.append(measure_fresh(args.scene, args.seconds, args.rounds))
            if not args.json:
                _print_fresh(runs[-1])
        if args.json:
            print(json.dumps({"measures": runs, "spread": spread(runs)}))
        else:
            print("\n".join(render_spread(spread(runs))))
        return 0
    if not args.in_process:
        fresh = measure_fresh(args.scene, args.seconds, args.rounds)
        if args.json:
            print(json.dumps(fresh))
            return 0
        _print_fresh(fresh)
        if args.docs is None and not args.parts:
            return 0
    r = measure(args.scene, args.seconds, args.rounds)
    if not args.in_process:
        r["fresh"] = fresh
    if args.parts:
        r["parts_s"] = breakdown(args.scene, args.seconds)
    if args.docs is not None:
        page = args.docs.read_text() if args.docs.is_file() else ""
        args.docs.write_text(with_section(page, LOG_COST_HEADING, render_section(r)))
    if args.json:
        print(json.dumps(r))
        return 0
    print(f"{r['scene']}, rk4 1 kHz exact, {r['seconds']:g} s, best of {r['rounds']} rounds; "
          f"1-minute load average {r['load']}")
    print(f"{'run':10s} {'ms per sim s':>13s} {'/ physics':>10s} {'CPU ms per sim s':>17s}")
    for c in CONFIGS:
        print(f"{c:10s} {r['ms_per_sim_s'][c]:13.2f} {r['ratio'][c]:10.2f} "
              f"{r['cpu_ms_per_sim_s'][c]:17.2f}")
    if args.parts:
        parts = r["parts_s"]
        print(f"\nparts of one run with all logs, profiled, outputs written in the thread of "
              f"the physics ({1e3 * parts['run']:.0f} ms):")
        for label, _, _ in PARTS:
            share = parts[label] / parts["run"]
            print(f"{label:38s} {1e3 * parts[label]:8.1f} ms {100 * share:6.1f} %")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
