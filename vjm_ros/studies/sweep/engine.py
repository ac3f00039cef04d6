"""The sweep engine: runs cases on Dask distributed and writes each row as it arrives.

A local cluster by default (one single-threaded worker process per core, so the compiled
kernels run in parallel and their numba caches load once per worker), or an existing scheduler
(``tcp://host:8786``, e.g. one started by dask-jobqueue on a Slurm cluster or by the Dask
Kubernetes operator); the code is the same either way.

Rows go to ``results.csv`` in the output directory as they finish (keyed by the hash of their
scene, settings and parameters), so a crash or Ctrl-C loses only the runs under way and
``--resume`` skips the finished ones; ``results.parquet`` is written from it at the end (also
after Ctrl-C). References are computed once per scene and parameter set, on a worker, and shared
by that set's runs.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from vjm_ros.core.errors import ConfigurationError
from vjm_ros.logs.signals import StopSignals
from vjm_ros.studies.sweep.run import MEASURES, case_duration, case_scene, case_settings
from vjm_ros.studies.sweep.spec import Case, SweepSpec

RESULTS_CSV = "results.csv"
RESULTS_PARQUET = "results.parquet"


class Engine:
    """A Dask client on a local cluster or on an existing scheduler; a context manager.

    Parameters
    ----------
    address : str, optional
        Scheduler address (``tcp://host:port``); a local cluster when None.
    workers : int, optional
        Worker processes of the local cluster (one per core by default), one thread each.
    timeout : float
        Longest wait to reach an existing scheduler, s.
    """

    def __init__(self, address: str | None = None, workers: int | None = None,
                 timeout: float = 10.0) -> None:
        self.address = address
        self.workers = workers or os.cpu_count() or 1
        self.timeout = timeout
        self.cluster = None
        self.client = None

    def __enter__(self) -> Engine:
        from distributed import Client, LocalCluster

        if self.address:
            try:
                self.client = Client(self.address, timeout=f"{self.timeout}s")
            except (OSError, TimeoutError) as exc:
                raise ConfigurationError(
                    f"--cluster {self.address}: expected a reachable Dask scheduler, found none "
                    f"({exc})") from None
        else:
            self.cluster = LocalCluster(
                n_workers=self.workers, threads_per_worker=1, processes=True,
                # a free port for the scheduler's HTTP endpoint: several clusters may run on one
                # machine, and a fixed port would collide
                dashboard_address=":0", silence_logs=logging.ERROR,
            )
            self.client = Client(self.cluster)
        self.client.run(_warm_up)  # the compiled kernels load once per worker, before timing
        return self

    def __exit__(self, *exc) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    @property
    def n_workers(self) -> int:
        """Workers the client sees."""
        return len(self.client.scheduler_info()["workers"])


def _warm_up() -> None:
    """Load the compiled kernels in a worker (from numba's on-disk cache after the first time),
    compiled in the worker before its first run where the cache lacks them: runs are timed."""
    from vjm_ros.jit import tiers
    from vjm_ros.scene import load_scene
    from vjm_ros.sim.simulator import SimulationSettings, Simulator

    tiers.compile_first()
    scene = load_scene("pendulum")
    Simulator(scene.model, SimulationSettings(closure="exact"), scene.gains).advance()


def check_cases(spec: SweepSpec, cases: Sequence[Case]) -> None:
    """Refuse, before any run, what would fail in every run: scenes, parameters, settings."""
    seen = set()
    for case in cases:
        sig = (case.scene, json.dumps(case.parameters, sort_keys=True))
        if sig in seen:
            continue
        seen.add(sig)
        try:
            scene = case_scene(*sig)
            case_settings(Case(case.scene, {k: v for k, v in case.settings.items()
                                            if k in ("integrator", "closure")}), scene)
        except (ConfigurationError, ValueError) as exc:
            raise ConfigurationError(f"{spec.source}: {exc}") from None


class SweepProgress:
    """Rows done and failed, and the time left, on stderr (a line a second at most)."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.total, self.enabled = total, enabled
        self.start = time.monotonic()
        self.last = 0.0
        self.tty = sys.stderr.isatty()

    def update(self, done: int, failed: int, final: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if not final and now - self.last < 1.0:
            return
        self.last = now
        rate = done / max(now - self.start, 1e-9)
        left = (self.total - done) / rate if rate > 0 else math.inf
        eta = f"{int(left // 60)}:{int(left % 60):02d}" if math.isfinite(left) else "?"
        line = f"sweep: {done}/{self.total} rows, {failed} failed, ETA {eta}"
        end = "\n" if final or not self.tty else ""
        print(("\r" if self.tty else "") + line, end=end, file=sys.stderr, flush=True)


def _finished_keys(path: Path, columns: list[str]) -> set[str]:
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames != columns:
            raise ConfigurationError(
                f"{path}: expected the columns of this spec to resume, found "
                f"{reader.fieldnames} (use another --out, or no --resume)")
        return {row["key"] for row in reader}


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return str(value) if not isinstance(value, float) else repr(value)


def run_sweep(
    spec: SweepSpec,
    out: str | Path,
    engine: Engine,
    resume: bool = False,
    progress: bool = True,
    on_row: Callable[[dict], None] | None = None,
) -> dict:
    """Run every case of ``spec`` not yet in ``out`` (with ``resume``) and write the table.

    Returns
    -------
    dict
        ``rows`` (cases in the spec), ``run`` (this time), ``skipped`` (finished before),
        ``failed`` (rows whose status is not ``ok``), ``wall_time`` (s), ``csv``, ``parquet``
        and ``interrupted``.
    """
    from distributed import as_completed

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cases = spec.cases()
    check_cases(spec, cases)
    columns = spec.columns + list(MEASURES)
    table = out / RESULTS_CSV
    done_keys = _finished_keys(table, columns) if resume and table.exists() else set()
    todo = [c for c in cases if c.key not in done_keys]
    client = engine.client
    references = _references(spec, todo, client) if spec.reference else {}
    batches = _batches(todo, engine.n_workers)
    futures = [
        client.submit(_run_batch, batch, references.get(_ref_key(batch[0])),
                      key=f"cases-{batch[0].key}-{len(batch)}-{os.getpid()}", pure=False)
        for batch in batches
    ]
    bar = SweepProgress(len(todo), progress)
    failed = 0
    started = time.perf_counter()
    interrupted = False
    mode = "a" if resume and table.exists() else "w"
    # SIGINT/SIGTERM only set a flag (logs.signals): nothing inside Dask is interrupted, and the
    # loop stops at the next finished batch, keeping every row written.
    with StopSignals() as stop, table.open(mode, newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        if mode == "w":
            writer.writeheader()
        n = 0
        try:
            for fut in as_completed(futures):
                if stop.requested:
                    break
                try:
                    rows = fut.result()
                except Exception as exc:  # a worker died or a run raised: rows with why
                    batch = batches[futures.index(fut)]
                    rows = [{**case.as_row(), **dict.fromkeys(MEASURES), "status": "error",
                             "message": f"{type(exc).__name__}: {exc}"} for case in batch]
                for row in rows:
                    writer.writerow({k: _cell(row.get(k)) for k in columns})
                    failed += row.get("status") != "ok"
                    if on_row is not None:
                        on_row(row)
                f.flush()
                n += len(rows)
                bar.update(n, failed)
        except KeyboardInterrupt:  # a signal handler other than ours (not the main thread)
            interrupted = True
        if stop.requested:
            interrupted = True
        if interrupted:
            client.cancel(futures)
        bar.update(n, failed, final=True)
    parquet = write_parquet(table, out / RESULTS_PARQUET)
    return {
        "rows": len(cases), "run": len(todo), "skipped": len(cases) - len(todo), "failed": failed,
        "wall_time": time.perf_counter() - started, "csv": str(table), "parquet": str(parquet),
        "interrupted": interrupted,
    }


def _run_batch(cases: list[Case], reference) -> list[dict]:
    from vjm_ros.studies.sweep.run import run_case

    return [run_case(case, reference) for case in cases]


BATCHES_PER_WORKER = 25
"""Tasks per worker a sweep is cut into: few enough that the scheduler's cost per task is small
against the runs (one task per run cost 4.9 ms per run here, batches of four 1.8-2.4 ms), many
enough that the workers finish together (8 per worker left one idle at the end: 1.71x on two
workers against 1.80-1.85x with 25)."""


def _batches(cases: Sequence[Case], workers: int) -> list[list[Case]]:
    """Consecutive cases of one scene and parameter set (one reference), in tasks of equal size."""
    size = max(1, len(cases) // max(workers * BATCHES_PER_WORKER, 1))
    out: list[list[Case]] = []
    for case in cases:
        if out and len(out[-1]) < size and _ref_key(out[-1][0]) == _ref_key(case):
            out[-1].append(case)
        else:
            out.append([case])
    return out


def _ref_key(case: Case) -> tuple:
    return case.scene, json.dumps(case.parameters, sort_keys=True)


def _references(spec: SweepSpec, cases: Sequence[Case], client) -> dict:
    """One reference future per scene and parameter set, at a rate every case's rate divides."""
    from vjm_ros.studies.sweep.run import reference_for

    groups: dict[tuple, list[Case]] = {}
    for c in cases:
        groups.setdefault(_ref_key(c), []).append(c)
    refs = {}
    for key, group in groups.items():
        scene = case_scene(*key)
        horizon = max(case_duration(c, scene) for c in group)
        rates = {float(case_settings(c, scene).rate) for c in group if _settles(c, scene)}
        rate = _common_rate(rates)
        refs[key] = client.submit(reference_for, key[0], key[1], horizon, rate, pure=False)
    return refs


def _settles(case: Case, scene) -> bool:
    try:
        case_settings(case, scene)
    except (ConfigurationError, ValueError):
        return False
    return True


def _common_rate(rates: set[float]) -> float:
    """The smallest rate (Hz) that every integer rate divides, if at most 10 kHz; else 1 kHz."""
    if rates and all(r == int(r) for r in rates):
        lcm = math.lcm(*(int(r) for r in rates))
        if lcm <= 10_000:
            return float(lcm)
    return 1000.0


def write_parquet(csv_path: Path, parquet_path: Path) -> Path:
    """The CSV table as Parquet (columns typed by pyarrow's CSV reader)."""
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    pq.write_table(pacsv.read_csv(csv_path), parquet_path)
    return parquet_path
