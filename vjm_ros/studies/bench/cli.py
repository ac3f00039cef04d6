"""The command line of the study: ``vjm bench [SCENE ...] [--quick] [--out DIR] [--docs FILE]``."""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import fields
from pathlib import Path

from vjm_ros.core.errors import (
    ConfigurationError,
    SceneError,
)
from vjm_ros.scene.loader import builtin_scenes, load_scene
from vjm_ros.sim.settings import resolve_settings
from vjm_ros.sim.simulator import SimulationSettings
from vjm_ros.studies.bench.grid import (
    FULL_SCENES,
    QUICK_SCENES,
    TIERS,
    BenchOptions,
    jsonable,
)
from vjm_ros.studies.bench.long_run import (
    long_run,
)
from vjm_ros.studies.bench.progress import (
    BenchProgress,
    limit_threads,
)
from vjm_ros.studies.bench.report import (
    _long_run_line,
)
from vjm_ros.studies.bench.study import (
    rerender,
    run_bench,
)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="vjm bench",
        description="Speed/accuracy study: integrator x rate/substeps x closure per scene, against "
                    "an exact-closure reference, with MuJoCo side by side when it is installed.",
    )
    p.add_argument("scenes", nargs="*", metavar="SCENE",
                   help=f"built-in names or YAML paths (default: {' '.join(FULL_SCENES)}; "
                        f"--quick: {' '.join(QUICK_SCENES)})")
    p.add_argument("--quick", action="store_true",
                   help="reduced grid, horizons of at most 0.5 s (a few minutes)")
    p.add_argument("--out", type=Path, default=Path("bench_out"),
                   help="output directory (default: bench_out)")
    p.add_argument("--docs", type=Path, metavar="FILE",
                   help="also write the summary page (e.g. docs/accuracy.md) and copy the figures "
                        "to figures/ beside it")
    p.add_argument("--repeats", type=int, default=3, help="timed runs per row (median; default 3)")
    p.add_argument("--horizon", type=float, help="simulated seconds per scene (overrides defaults)")
    p.add_argument("--no-mujoco", action="store_true", help="leave out the MuJoCo rows")
    p.add_argument("--no-scaling", action="store_true", help="leave out the cost-per-tick study")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="extra SimulationSettings field for every vjm row (repeatable)")
    p.add_argument("--long-run", type=float, metavar="SECONDS",
                   help="instead of the grid: run four_bar for SECONDS simulated seconds and write "
                        "OUT/long_run_<setting>.json (included by later reports in OUT)")
    p.add_argument("--long-run-integrator", default=None,
                   help="integrator of --long-run (default: the scene's)")
    p.add_argument("--long-run-closure", choices=["penalty", "exact"], default=None,
                   help="closure of --long-run (default: the scene's)")
    p.add_argument("--long-run-projection", action="store_true",
                   help="exact closure of --long-run with projection")
    p.add_argument("--plant", action="store_true",
                   help="instead of the grid: the friction and hard-stop cases (stick-slip, "
                        "impacts) over integrators, substeps and closures against a fine "
                        "reference; with --docs, its section of that page")
    p.add_argument("--from-results", type=Path, metavar="FILE",
                   help="run nothing: write the report, figures and --docs again from a "
                        "results.json (adding the long runs found in --out)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.add_argument("--workers", type=int, default=1,
                   help="run the rows on this many local Dask workers (the sweep engine; "
                        "timings then share the machine); default 1: in this process")
    p.add_argument("--cluster", metavar="ADDRESS",
                   help="run the rows on an existing Dask scheduler (tcp://host:port)")
    p.add_argument("--cluster-timeout", type=float, default=10.0, metavar="S",
                   help="longest wait for --cluster's scheduler to connect and answer, s (10)")
    return p


def _parse_set(items: list[str]) -> dict:
    known = {f.name: f for f in fields(SimulationSettings)}
    out = {}
    for item in items:
        if "=" not in item:
            raise ConfigurationError(f"--set: expected KEY=VALUE, found {item!r}")
        key, raw = item.split("=", 1)
        if key not in known:
            raise ConfigurationError(
                f"--set: unknown SimulationSettings field {key!r}; known: {', '.join(known)}"
            )
        try:
            value = json.loads(raw)
        except ValueError:
            value = raw
        out[key] = value
    return out


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``vjm bench``.

    Parameters
    ----------
    argv : list of str, optional
        Arguments after ``bench``.

    Returns
    -------
    int
        0 on success, 2 on bad input.
    """
    from vjm_ros.jit import tiers

    tiers.compile_first()  # times compiled code, never the plain-Python tier
    argv = list(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(argv)
    try:
        if args.repeats < 1:
            raise ConfigurationError(f"--repeats: expected 1 or more, found {args.repeats}")
        if args.horizon is not None and not (math.isfinite(args.horizon) and args.horizon > 0):
            raise ConfigurationError(f"--horizon: expected a positive number, found {args.horizon}")
        extra = _parse_set(args.set)
        if args.long_run is not None:
            return _main_long_run(args)
        if args.plant:
            return _main_plant(args)
        if args.from_results is not None:
            opts = BenchOptions(scenes=[], out=args.out, docs=args.docs)
            results = rerender(args.from_results, opts)
            print(f"wrote {opts.out / 'report.md'} and {opts.out / 'results.json'}"
                  + (f"; docs: {opts.docs}" if opts.docs else ""))
            return 0
        names = args.scenes or list(QUICK_SCENES if args.quick else FULL_SCENES)
        for n in names:
            if n not in builtin_scenes() and not Path(n).exists():
                raise SceneError(n, "", f"a built-in scene ({', '.join(builtin_scenes())}) or a "
                                        "YAML file", "no such scene or file")
        opts = BenchOptions(
            scenes=names, quick=args.quick, out=args.out, repeats=args.repeats,
            horizon=args.horizon, mujoco=not args.no_mujoco, scaling=not args.no_scaling,
            docs=args.docs, extra=extra, progress=not args.no_progress,
            command="vjm bench " + " ".join(argv), workers=args.workers, cluster=args.cluster,
            cluster_timeout=args.cluster_timeout,
        )
        results = run_bench(opts)
    except (SceneError, ConfigurationError) as exc:
        print(f"vjm bench: error: {exc}", file=sys.stderr)
        return 2
    rec = results.get("recommended", {})
    print(f"wrote {opts.out / 'report.md'}, {opts.out / 'results.json'} and "
          f"{len(results.get('figures', {}))} figures"
          + (f"; docs: {opts.docs}" if opts.docs else ""))
    for tier, _ in TIERS:
        b = rec.get(tier)
        print(f"  {tier:11s} {b['label'] if b else 'no single setting qualifies on every scene'}")
    if results["meta"]["mujoco"]["skipped"] and not args.no_mujoco:
        print(f"  MuJoCo rows skipped: {results['meta']['mujoco']['skipped']}")
    return 0


def _main_plant(args) -> int:
    from vjm_ros.studies.bench import plant
    from vjm_ros.studies.pages import with_section

    limit_threads()
    rows = plant.measure(args.repeats)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "plant.json").write_text(json.dumps(jsonable(rows), indent=1) + "\n")
    text = plant.render(rows)
    print(text)
    if args.docs is not None:
        page = args.docs.read_text() if args.docs.is_file() else ""
        args.docs.write_text(with_section(page, plant.HEADING, text))
    print(f"wrote {args.out / 'plant.json'}" + (f"; docs: {args.docs}" if args.docs else ""))
    return 0


def _main_long_run(args) -> int:
    limit_threads()
    scene = load_scene("four_bar")
    settings = resolve_settings(scene.defaults, scene.gains, integrator=args.long_run_integrator,
                                closure=args.long_run_closure,
                                projection=bool(args.long_run_projection))
    bar = BenchProgress(args.long_run, enabled=not args.no_progress)
    last = [0.0]

    def tick(t: float) -> None:
        bar.advance(t - last[0], f"four_bar long run, t = {t:.0f} s")
        last[0] = t

    try:
        result = long_run(args.long_run, settings, progress=tick)
    finally:
        bar.close()
    args.out.mkdir(parents=True, exist_ok=True)
    tag = f"{settings.integrator}_{settings.closure}" + ("_projection" if settings.projection else "")
    path = args.out / f"long_run_{tag}.json"
    path.write_text(json.dumps(jsonable(result), indent=1) + "\n")
    print(_long_run_line(result))
    print(f"wrote {path}")
    return 0 if result["error"] is None else 3


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
