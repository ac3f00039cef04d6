"""``vjm sweep SPEC.yaml`` and ``vjm tune SCENE``: the command lines of the sweep engine.

Exit codes: 0 done (rows that failed or diverged are rows of the table, with their reason);
2 bad input (spec, scene, settings, unreachable scheduler), refused before any run; 130
interrupted (the table holds every row finished before).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from vjm_ros.core.errors import ConfigurationError, SceneError
from vjm_ros.studies.sweep.engine import RESULTS_CSV, Engine, run_sweep
from vjm_ros.studies.sweep.spec import load_spec

EXIT_BAD_INPUT, EXIT_INTERRUPTED = 2, 130


def _engine_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--cluster", metavar="ADDRESS",
                   help="an existing Dask scheduler, e.g. tcp://host:8786 (default: a local "
                        "cluster)")
    p.add_argument("--workers", type=int, help="local worker processes (default: one per core)")
    p.add_argument("--no-progress", action="store_true", help="no progress line on stderr")


def sweep_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vjm sweep", description="Run a sweep spec on Dask.")
    p.add_argument("spec", type=Path, help="sweep spec (YAML), see docs/sweeps.md")
    p.add_argument("--out", type=Path, help="output directory (default: sweep_out/<name>)")
    p.add_argument("--resume", action="store_true", help="skip the rows already in --out")
    _engine_args(p)
    return p


def tune_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vjm tune",
                                description="Penalty gains for an integrator and step.")
    p.add_argument("scene", help="built-in scene name or YAML path")
    p.add_argument("--integrator", default="rk4")
    p.add_argument("--rate", type=float, default=1000.0, help="tick rate, Hz (1000)")
    p.add_argument("--substeps", type=int, default=1)
    p.add_argument("--duration", type=float, default=1.0, help="simulated s per run (1)")
    p.add_argument("--out", type=Path, help="output directory (default: tune_out/<scene>)")
    _engine_args(p)
    return p


def main(command: str, argv: list[str]) -> int:
    """``vjm sweep`` or ``vjm tune`` with their arguments."""
    from vjm_ros.jit import tiers

    tiers.compile_first()  # times compiled code, never the plain-Python tier
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


def _sweep(args) -> int:
    spec = load_spec(args.spec)
    out = args.out or Path("sweep_out") / spec.name
    with Engine(args.cluster, args.workers) as engine:
        result = run_sweep(spec, out, engine, resume=args.resume, progress=not args.no_progress)
        result["workers"] = engine.n_workers
    print(json.dumps(result))
    return EXIT_INTERRUPTED if result["interrupted"] else 0


def _tune(args) -> int:
    from vjm_ros.studies.sweep.tune import (
        choose,
        gains_snippet,
        pareto_front,
        plot_tuning,
        read_rows,
        tuning_spec,
    )

    spec = tuning_spec(args.scene, args.integrator, args.rate, args.substeps, args.duration)
    out = args.out or Path("tune_out") / Path(args.scene).stem
    with Engine(args.cluster, args.workers) as engine:
        result = run_sweep(spec, out, engine, progress=not args.no_progress)
    rows = read_rows(out / RESULTS_CSV)
    front, chosen = pareto_front(rows), choose(rows)
    figure = plot_tuning(rows, front, chosen, out / "tuning.png",
                         f"{args.scene}: {args.integrator} {args.rate:g} Hz x{args.substeps}")
    summary = {**result, "figure": str(figure), "front": [
        {k: r[k] for k in ("omega_n", "zeta", "max_closure_error", "wall_time")} for r in front]}
    if chosen is None:
        summary["chosen"] = None
        print(json.dumps(summary))
        print(f"vjm tune: no gains of the grid ran on {args.scene} with {args.integrator} at "
              f"{args.rate:g} Hz x{args.substeps}; add substeps or use implicit_euler",
              file=sys.stderr)
        return 0
    snippet = gains_snippet(chosen, args.scene, args.integrator, args.rate, args.substeps)
    (out / "gains.yaml").write_text(snippet)
    summary["chosen"] = {k: chosen[k] for k in ("omega_n", "zeta", "max_closure_error",
                                                "wall_time")}
    summary["snippet"] = str(out / "gains.yaml")
    print(snippet, end="")
    print(json.dumps(summary))
    return EXIT_INTERRUPTED if result["interrupted"] else 0
