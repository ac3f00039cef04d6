"""``vjm sweep SPEC.yaml`` and ``vjm tune SCENE``: the command lines of the sweep engine.

Exit codes: 0 done (rows refused or diverged are rows of the table, with their reason); 1 every
row run this time is an ``error`` row (nothing could run: say, the workers lack a module);
2 bad input (spec, scene, settings, an existing table, the scheduler), refused before any run
and before anything is written; 130 interrupted (the table holds every row finished before, and
stderr says how to resume).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from vjm_ros.core.errors import ConfigurationError, SceneError
from vjm_ros.studies.sweep.engine import CLUSTER_TIMEOUT, Engine, Sweep
from vjm_ros.studies.sweep.spec import check_value, load_spec
from vjm_ros.studies.sweep.table import RESULTS_CSV

EXIT_ALL_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 1, 2, 130


def _engine_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--cluster", metavar="ADDRESS",
                   help="an existing Dask scheduler, e.g. tcp://host:8786 (default: a local "
                        "cluster)")
    p.add_argument("--cluster-timeout", type=float, default=CLUSTER_TIMEOUT, metavar="S",
                   help="longest wait for --cluster's scheduler to connect and answer, s "
                        f"({CLUSTER_TIMEOUT:g})")
    p.add_argument("--workers", type=int, help="local worker processes (default: one per core)")
    p.add_argument("--no-progress", action="store_true", help="no progress line on stderr")


def sweep_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vjm sweep", description="Run a sweep spec on Dask.")
    p.add_argument("spec", type=Path, help="sweep spec (YAML), see docs/sweeps.md")
    p.add_argument("--out", type=Path, help="output directory (default: sweep_out/<name>)")
    p.add_argument("--resume", action="store_true",
                   help="keep the rows already in --out, run the rest and retry 'error' rows")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the table already in --out")
    p.add_argument("--figure", nargs="?", const="max_closure_error,wall_time", metavar="Y,X",
                   help="also write OUT/sweep.png: measure Y against X per setting (default "
                        "max_closure_error,wall_time)")
    _engine_args(p)
    return p


def tune_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vjm tune",
                                description="Penalty gains for an integrator and step.")
    p.add_argument("scene", help="built-in scene name or YAML path")
    p.add_argument("--integrator", default="rk4")
    p.add_argument("--rate", type=float, default=1000.0, help="tick rate, Hz (1000)")
    p.add_argument("--substeps", type=int, default=1)
    p.add_argument("--duration", type=float,
                   help="simulated s per run (default: the scene's own duration)")
    p.add_argument("--out", type=Path, help="output directory (default: tune_out/<scene>)")
    _engine_args(p)
    return p


def main(command: str, argv: list[str]) -> int:
    """``vjm sweep`` or ``vjm tune`` with their arguments."""
    parser = sweep_parser() if command == "sweep" else tune_parser()
    args = parser.parse_args(argv)
    if args.workers is not None and args.workers < 1:
        parser.error("--workers: expected a whole number >= 1")
    try:
        if command == "sweep":
            return _sweep(args)
        return _tune(args)
    except (SceneError, ConfigurationError) as exc:
        print(f"vjm {command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:  # before the runs started (the cluster was starting)
        print(f"vjm {command}: interrupted before any run", file=sys.stderr)
        return EXIT_INTERRUPTED


def _compile_first() -> None:
    """Runs are timed: the workers (started after this) compile the kernels before their first
    call, never running the plain-Python tier. The checks before run in this process as they
    come (a scene loads faster without loading its machine code)."""
    from vjm_ros.jit import tiers

    tiers.compile_first()


def _sweep(args) -> int:
    from vjm_ros.studies.sweep.summary import parse_figure, plot_sweep, summary_lines

    spec = load_spec(args.spec)
    out = args.out or Path("sweep_out") / spec.name
    figure = parse_figure(args.figure) if args.figure else None
    sweep = Sweep(spec, out, args.resume, args.overwrite)  # every check; nothing written yet
    start = sweep.start
    if args.resume and (start.kept or start.retried or start.dropped):
        print(f"vjm sweep: resuming {start.path}: {len(start.kept)} finished rows kept, "
              f"{start.retried} 'error' rows run again, {start.dropped} rows the spec no longer "
              f"has dropped", file=sys.stderr)
    _compile_first()
    with Engine(args.cluster, args.workers, args.cluster_timeout) as engine:
        result = sweep.run(engine, progress=not args.no_progress)
        result["workers"] = engine.n_workers
    if figure is not None:
        result["figure"] = str(plot_sweep(sweep, *figure, out / "sweep.png"))
    for line in summary_lines(result):
        print(f"vjm sweep: {line}", file=sys.stderr)
    print(json.dumps(result))
    if result["interrupted"]:
        again = ["vjm", "sweep", str(args.spec), "--out", str(out), "--resume"]
        if args.cluster:
            again += ["--cluster", args.cluster]
        elif args.workers:
            again += ["--workers", str(args.workers)]
        print(f"vjm sweep: interrupted after {result['run']} of {len(sweep.todo)} rows "
              f"({result['left']} left); to run the rest: {' '.join(again)}", file=sys.stderr)
    code = exit_code(result)
    if code == EXIT_ALL_FAILED:
        print("vjm sweep: every row run failed with an error (see the message column); "
              "--resume runs them again", file=sys.stderr)
    return code


def exit_code(result: dict) -> int:
    """The exit code of a sweep that ran (see the module documentation)."""
    if result["interrupted"]:
        return EXIT_INTERRUPTED
    if result["run"] and result["errors"] == result["run"]:
        return EXIT_ALL_FAILED
    return 0


def _tune(args) -> int:
    from vjm_ros.studies.sweep.tune import (
        MARGIN,
        choose,
        gains_snippet,
        pareto_front,
        plot_tuning,
        read_rows,
        stability_edge,
        tuning_spec,
    )

    for key in ("integrator", "rate", "substeps", "duration"):  # as a spec's values are
        if getattr(args, key) is not None:
            check_value(f"vjm tune {args.scene}", f"--{key}", key, getattr(args, key))
    spec = tuning_spec(args.scene, args.integrator, args.rate, args.substeps, args.duration)
    out = args.out or Path("tune_out") / Path(args.scene).stem
    sweep = Sweep(spec, out, overwrite=True)  # a tuning owns its directory
    _compile_first()
    with Engine(args.cluster, args.workers, args.cluster_timeout) as engine:
        result = sweep.run(engine, progress=not args.no_progress)
    rows = read_rows(out / RESULTS_CSV)
    edges = stability_edge(rows)
    front, chosen = pareto_front(rows), choose(rows, edges)
    figure = plot_tuning(rows, front, chosen, out / "tuning.png",
                         f"{args.scene}: {args.integrator} {args.rate:g} Hz x{args.substeps}")
    summary = {**result, "figure": str(figure),
               "stability_edge": {f"{z:g}": e for z, e in edges.items()},
               "margin": MARGIN, "front": [
        {k: r[k] for k in ("omega_n", "zeta", "max_closure_error", "wall_time")} for r in front]}
    if chosen is None:
        summary["chosen"] = None
        print(json.dumps(summary))
        print(f"vjm tune: no gains of the grid ran on {args.scene} with {args.integrator} at "
              f"{args.rate:g} Hz x{args.substeps} a factor {MARGIN:g} below the stability edge; "
              "add substeps or use implicit_euler",
              file=sys.stderr)
        return 0
    snippet = gains_snippet(chosen, args.scene, args.integrator, args.rate, args.substeps,
                            edges.get(chosen["zeta"]))
    (out / "gains.yaml").write_text(snippet)
    summary["chosen"] = {k: chosen[k] for k in ("omega_n", "zeta", "max_closure_error",
                                                "wall_time")}
    summary["snippet"] = str(out / "gains.yaml")
    print(snippet, end="")
    print(json.dumps(summary))
    return EXIT_INTERRUPTED if result["interrupted"] else 0
