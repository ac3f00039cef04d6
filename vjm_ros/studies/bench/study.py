"""The whole study: options, the run over scenes and rows, results as data."""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import shutil
import time
from collections import Counter
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from vjm_ros.core.errors import (
    ConfigurationError,
    VjmError,
)
from vjm_ros.scene.loader import Scene, load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator
from vjm_ros.studies.bench.analysis import (
    live_comparison,
    matched_accuracy,
    pareto_front,
    recommend,
    recommend_overall,
)
from vjm_ros.studies.bench.docs import (
    merge_kept_sections,
    render_docs,
)
from vjm_ros.studies.bench.grid import (
    CHECK_SETTINGS,
    DEFAULT_HORIZON,
    HORIZON_NOTES,
    HORIZONS,
    LIVE_HEADROOM,
    LIVE_RATE,
    MUJOCO_SCENES,
    QUICK_HORIZON,
    REFERENCE_RATE,
    REFERENCE_SETTINGS,
    BenchOptions,
    Grid,
    full_grid,
    grid_rows,
    jsonable,
    quick_grid,
)
from vjm_ros.studies.bench.progress import (
    BenchProgress,
    _work,
    limit_threads,
)
from vjm_ros.studies.bench.report import (
    plot_pareto,
    plot_scaling,
    render_report,
)
from vjm_ros.studies.bench.runs import (
    RowResult,
    _finish_timing,
    _time_mujoco,
    _time_vjm,
    compute_reference,
    run_mujoco,
    run_vjm,
)
from vjm_ros.studies.bench.scaling import (
    SCALING_METHODS,
    run_scaling,
    scaling_work,
)


def horizon_for(name: str, quick: bool, override: float | None = None) -> float:
    """Simulated seconds compared for a scene."""
    if override is not None:
        return float(override)
    h = HORIZONS.get(name, DEFAULT_HORIZON)
    return min(h, QUICK_HORIZON) if quick else h


def _plan(opts: BenchOptions, grid, scenes: list, use_mujoco: bool) -> tuple[list, float]:
    """``(scene, horizon, rows)`` per scene, and the total work for the progress bar."""
    plan = []
    total = 0.0
    for sc in scenes:
        horizon = horizon_for(sc.name, opts.quick, opts.horizon)
        rows = grid_rows(grid, use_mujoco and sc.name in MUJOCO_SCENES, opts.extra)
        plan.append((sc, horizon, rows))
        total += 2 * 6000.0 * horizon  # reference and its check
        for cfg in rows:
            total += _work(cfg, horizon) * (1 + max(opts.repeats - 1, 0))
    if opts.scaling:
        for family, sizes in (("links", grid.scaling_links), ("chains", grid.scaling_chains)):
            for size in sizes:
                n = size if family == "links" else 2 * size
                total += sum(scaling_work(n, integ, grid, opts.repeats)
                             for integ, _ in SCALING_METHODS)
    return plan, total


def _kernel_name(scenes: list, opts: BenchOptions) -> str | None:
    """The kernel the rows run on (``numba``), from a probe simulator."""
    if not scenes:
        return None
    try:
        probe = Simulator(scenes[0].model, SimulationSettings(
            integrator="rk4", closure="exact", **opts.extra), scenes[0].gains)
        return probe.describe().get("kernel")
    except (VjmError, TypeError):
        return None


def _scene_rows(sc, horizon: float, rows: list, ref, engine, progress, repeats: int) -> list:
    """Every row of one scene (on the engine's workers when there is one), then the timing
    repeats in this process, one after another."""
    out_rows = []
    runners = [run_mujoco if cfg.engine == "mujoco" else run_vjm for cfg in rows]
    if engine is not None:
        futures = [engine.client.submit(run, sc, cfg, horizon, ref, pure=False)
                   for run, cfg in zip(runners, rows, strict=True)]
    for i, cfg in enumerate(rows):
        res = futures[i].result() if engine is not None else runners[i](sc, cfg, horizon, ref)
        out_rows.append(res)
        progress.advance(_work(cfg, horizon), f"{sc.name}: {cfg.label()}")
    for _ in range(max(repeats - 1, 0)):
        for cfg, res in zip(rows, out_rows, strict=True):
            if res.ok:
                timer = _time_mujoco if cfg.engine == "mujoco" else _time_vjm
                try:
                    wall_s, cpu_s = timer(sc, cfg, horizon)
                    res.wall_samples.append(wall_s)
                    res.cpu_samples.append(cpu_s)
                except (VjmError, np.linalg.LinAlgError, FloatingPointError) as exc:
                    res.message = f"a timing repeat failed: {exc}"
            progress.advance(_work(cfg, horizon), f"{sc.name}: timing {cfg.label()}")
    for res in out_rows:
        _finish_timing(res)
    return out_rows


def _cpu_share(all_rows: dict) -> float | None:
    """CPU time over wall time of every timed row (below 1: the machine was shared)."""
    timed = [r for rs in all_rows.values() for r in rs
             if r.ok and len(r.cpu_samples) == len(r.wall_samples)]
    wall = sum(sum(r.wall_samples) for r in timed)
    return sum(sum(r.cpu_samples) for r in timed) / wall if wall > 0 else None


def run_bench(opts: BenchOptions) -> dict:
    """Run the study and write the outputs.

    Parameters
    ----------
    opts : BenchOptions

    Returns
    -------
    dict
        Everything written to ``results.json``.
    """
    if opts.cluster:  # refused at once, before the references and the plan
        from vjm_ros.studies.sweep.engine import check_scheduler

        check_scheduler(opts.cluster, opts.cluster_timeout)
    threads = limit_threads()
    grid = opts.grid or (quick_grid() if opts.quick else full_grid())
    from vjm_ros.studies.compare_mujoco import mujoco_version, version_note

    mj_version = mujoco_version() if opts.mujoco else None
    scenes = [load_scene(s) for s in opts.scenes]
    plan, total = _plan(opts, grid, scenes, bool(mj_version))
    kernel = _kernel_name(scenes, opts)
    progress = BenchProgress(total, enabled=opts.progress)
    started = time.perf_counter()
    engine = None
    if opts.workers > 1 or opts.cluster:
        from vjm_ros.studies.sweep.engine import Engine  # the sweep engine, on Dask

        engine = Engine(opts.cluster, opts.workers, opts.cluster_timeout).__enter__()
    meta = _meta(opts, threads, mj_version, version_note(mj_version), grid)
    results: dict = {"meta": {**meta, "kernel": kernel}, "scenes": {}}
    all_rows: dict[str, list[RowResult]] = {}
    try:
        for sc, horizon, rows in plan:
            progress.draw(f"{sc.name}: reference")
            try:
                ref = compute_reference(sc, horizon)
                ref_info = ref.info
            except (VjmError, np.linalg.LinAlgError) as exc:
                ref, ref_info = None, {"error": str(exc)}
            progress.advance(2 * 6000.0 * horizon, f"{sc.name}: reference done")
            all_rows[sc.name] = _scene_rows(sc, horizon, rows, ref, engine, progress, opts.repeats)
            results["scenes"][sc.name] = _scene_summary(sc, horizon, ref_info, all_rows[sc.name])
        if opts.scaling:
            results["scaling"] = run_scaling(grid, opts.repeats, progress, opts.extra)
    finally:
        progress.close()
        if engine is not None:
            engine.__exit__(None, None, None)
    results["meta"]["cpu_share"] = _cpu_share(all_rows)
    results["meta"]["bench_wall_time"] = time.perf_counter() - started
    write_outputs(results, all_rows, opts)
    return results


def rows_from_results(results: dict) -> dict[str, list[RowResult]]:
    """The rows of a ``results.json`` as :class:`RowResult` objects, per scene."""
    names = {f.name for f in fields(RowResult)}

    def value(v):
        return float(v) if v in ("inf", "-inf") else v

    return {
        scene: [RowResult(**{k: value(v) for k, v in r.items() if k in names}) for r in sm["rows"]]
        for scene, sm in results["scenes"].items()
    }


def rerender(results_path: Path, opts: BenchOptions) -> dict:
    """Write the outputs again from a ``results.json`` (and the long runs found in ``opts.out``).

    Parameters
    ----------
    results_path : Path
    opts : BenchOptions
        ``out`` and ``docs`` are used.

    Returns
    -------
    dict
        The results as written.
    """
    try:
        results = json.loads(Path(results_path).read_text())
    except (OSError, ValueError) as exc:
        raise ConfigurationError(f"--from-results {results_path}: expected a results.json "
                                 f"written by vjm bench ({exc})") from None
    rows = rows_from_results(results)
    for name, rs in rows.items():
        results["scenes"][name].update(_analysis(rs))
    write_outputs(results, rows, opts)
    return results


def _scene_summary(sc: Scene, horizon: float, ref_info: dict, rows: list[RowResult]) -> dict:
    return {
        "horizon": horizon,
        "horizon_note": HORIZON_NOTES.get(sc.name, ""),
        "n": sc.model.n,
        "closure_rows": sc.model.n_rows,
        "reference": ref_info,
        "rows": [jsonable(asdict(r)) for r in rows],
        **_analysis(rows),
    }


def _analysis(rows: list[RowResult]) -> dict:
    """Counts, Pareto fronts, tiers and the MuJoCo comparison of one scene's rows."""
    return {
        "counts": dict(Counter(r.status for r in rows)),
        "pareto": {
            "vjm": [r.key for r in pareto_front([r for r in rows if r.engine == "vjm"])],
            "mujoco": [r.key for r in pareto_front([r for r in rows if r.engine == "mujoco"])],
        },
        "recommended": recommend(rows),
        "matched_accuracy": matched_accuracy(rows) if any(r.engine == "mujoco" for r in rows) else [],
        "live": live_comparison(rows) if any(r.engine == "mujoco" for r in rows) else {},
    }


def _meta(opts: BenchOptions, threads: dict, mj_version, mj_note, grid: Grid) -> dict:
    import scipy

    return {
        "command": opts.command,
        "date": _dt.datetime.now().astimezone().isoformat(timespec="seconds"),
        "quick": opts.quick,
        "repeats": opts.repeats,
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "scipy": scipy.__version__,
        },
        "threads": threads,
        "mujoco": {"version": mj_version, "note": mj_note,
                   "skipped": None if mj_version else "MuJoCo is not installed (pip install '.[compare]')"},
        "reference": {**REFERENCE_SETTINGS, "closure": "exact", "rate": REFERENCE_RATE,
                      "check": CHECK_SETTINGS},
        "live": {"rate": LIVE_RATE, "min_realtime_factor": LIVE_HEADROOM},
        "extra_settings": jsonable(opts.extra),
        "grid": jsonable(asdict(grid)),
    }




def write_outputs(results: dict, rows: dict[str, list[RowResult]], opts: BenchOptions) -> None:
    """Add the overall recommendation and the long runs found in ``opts.out`` to ``results``, then
    write ``results.json``, ``report.md``, the figures and (with ``--docs``) the docs page."""
    out = opts.out
    results["recommended"] = recommend_overall(rows) if rows else {}
    long_runs = []
    for path in sorted(out.glob("long_run*.json")) if out.is_dir() else []:
        try:
            long_runs.append({**json.loads(path.read_text()), "source": path.name})
        except (OSError, ValueError):
            continue
    if long_runs:
        results["long_runs"] = long_runs
    out.mkdir(parents=True, exist_ok=True)
    figures = {}
    for name, rs in rows.items():
        path = out / f"{name}_pareto.png"
        plot_pareto(name, rs, results["scenes"][name], path)
        figures[name] = path.name
    if "scaling" in results:
        plot_scaling(results["scaling"], out / "scaling.png")
        figures["scaling"] = "scaling.png"
    results["figures"] = figures
    (out / "results.json").write_text(json.dumps(jsonable(results), indent=1) + "\n")
    (out / "report.md").write_text(render_report(results, rows))
    if opts.docs is not None:
        docs = Path(opts.docs)
        fig_dir = docs.parent / "figures"
        fig_dir.mkdir(parents=True, exist_ok=True)
        for fname in figures.values():
            shutil.copyfile(out / fname, fig_dir / fname)
        previous = docs.read_text() if docs.exists() else ""
        docs.write_text(merge_kept_sections(render_docs(results, rows), previous))
