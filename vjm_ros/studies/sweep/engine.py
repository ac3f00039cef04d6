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
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from vjm_ros.core.errors import ConfigurationError
from vjm_ros.logs.signals import StopSignals
from vjm_ros.studies.bench.grid import FAILED
from vjm_ros.studies.bench.progress import BenchProgress
from vjm_ros.studies.sweep.plan import plan_sweep
from vjm_ros.studies.sweep.run import MEASURES, case_duration, case_scene, case_settings
from vjm_ros.studies.sweep.spec import Case, SweepSpec
from vjm_ros.studies.sweep.table import (
    RESULTS_PARQUET,
    begin_table,
    cell,
    inspect_table,
    write_parquet,
)

CLUSTER_TIMEOUT = 10.0
"""Default longest wait, s, for ``--cluster``'s scheduler to accept the connection and answer."""


class Engine:
    """A Dask client on a local cluster or on an existing scheduler; a context manager.

    Parameters
    ----------
    address : str, optional
        Scheduler address (``tcp://host:port``); a local cluster when None.
    workers : int, optional
        Worker processes of the local cluster (one per core by default), one thread each.
    timeout : float
        Longest wait to reach an existing scheduler and hear it answer as one, s
        (:data:`CLUSTER_TIMEOUT` by default).
    """

    def __init__(self, address: str | None = None, workers: int | None = None,
                 timeout: float = CLUSTER_TIMEOUT) -> None:
        if not (isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0):
            raise ConfigurationError(
                f"--cluster-timeout: expected a positive number of seconds, found {timeout!r}")
        self.address = address
        self.workers = workers or os.cpu_count() or 1
        self.timeout = timeout
        self.cluster = None
        self.client = None

    def __enter__(self) -> Engine:
        from distributed import Client, LocalCluster

        if self.address:
            check_scheduler(self.address, self.timeout)
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


def check_scheduler(address: str, timeout: float = CLUSTER_TIMEOUT) -> None:
    """Refuse an address that is not a Dask scheduler's, within ``timeout`` s.

    Dask's own client waits for a handshake without a bound: a server that accepts the
    connection but speaks another protocol (an HTTP server, say) would hang it. Here the
    connection, the handshake and an ``identity`` request each have ``timeout`` s, and the
    answer must come from a scheduler.

    Raises
    ------
    ConfigurationError
        Naming the address and what was found: a malformed address, nothing listening, no
        answer in time, or a server that is not a Dask scheduler.
    """
    import asyncio

    from distributed.comm import connect
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import backends

    where = f"--cluster {address}"
    try:
        scheme, loc = parse_address(address)
        if scheme not in backends:
            raise ValueError(f"unknown scheme {scheme!r}; known: {', '.join(sorted(backends))}")
        if scheme in ("tcp", "tls"):
            parse_host_port(loc)
            if ":" not in loc.rsplit("]", 1)[-1]:
                raise ValueError("no port")
    except (ValueError, TypeError) as exc:
        raise ConfigurationError(
            f"{where}: expected a scheduler address such as tcp://host:8786, found a malformed "
            f"address ({exc})") from None

    async def identity() -> dict:
        # Dask's own bound first (it says what it found: nothing listening, refused); ours
        # a moment later, for a handshake it would wait for without end
        comm = await asyncio.wait_for(connect(address, timeout=timeout), 1.5 * timeout)
        try:
            await asyncio.wait_for(comm.write({"op": "identity", "reply": True}), timeout)
            return await asyncio.wait_for(comm.read(), timeout)
        finally:
            comm.abort()

    try:
        reply = asyncio.run(identity())
    except TimeoutError:
        raise ConfigurationError(
            f"{where}: expected a Dask scheduler to answer within {timeout:g} s "
            "(--cluster-timeout), found no answer: is it a Dask scheduler's address?") from None
    except (OSError, ValueError, EOFError) as exc:
        raise ConfigurationError(
            f"{where}: expected a reachable Dask scheduler, found none ({exc})") from None
    except Exception as exc:  # noqa: BLE001 - a peer that speaks another protocol
        raise ConfigurationError(
            f"{where}: expected a Dask scheduler, found a server that answers otherwise "
            f"({type(exc).__name__}: {exc})") from None
    kind = reply.get("type") if isinstance(reply, dict) else None
    if kind != "Scheduler":
        raise ConfigurationError(
            f"{where}: expected a Dask scheduler, found {kind or 'another kind of server'}")


def _warm_up() -> None:
    """Load the compiled kernels in a worker (from numba's on-disk cache after the first time),
    compiled in the worker before its first run where the cache lacks them: runs are timed."""
    from vjm_ros.jit import tiers
    from vjm_ros.scene import load_scene
    from vjm_ros.sim.simulator import SimulationSettings, Simulator

    tiers.compile_first()
    scene = load_scene("pendulum")
    Simulator(scene.model, SimulationSettings(closure="exact"), scene.gains).advance()


class Sweep:
    """A checked sweep and its table, ready to run; nothing is written before :meth:`run`.

    Parameters
    ----------
    spec : SweepSpec
    out : str or Path
        Output directory (``results.csv``, ``results.parquet``).
    resume, overwrite : bool
        What to do with a table that holds rows (:func:`~vjm_ros.studies.sweep.table.
        inspect_table`); without either such a table is refused.

    Raises
    ------
    ConfigurationError
        A spec row that cannot run (:func:`plan_sweep`), or a table that may not be written.
    """

    def __init__(self, spec: SweepSpec, out: str | Path, resume: bool = False,
                 overwrite: bool = False) -> None:
        self.spec = spec
        self.out = Path(out)
        self.plan = plan_sweep(spec)
        self.columns = spec.columns + list(MEASURES)
        self.start = inspect_table(self.out, self.columns, {c.key for c in self.plan.cases},
                                   resume, overwrite)
        done = self.start.done
        self.todo = [c for c in self.plan.cases if c.key not in done]

    def run(self, engine: Engine, progress: bool = True) -> dict:
        """Run the rows not in the table yet on ``engine``, writing each as it arrives.

        Returns
        -------
        dict
            ``rows`` (in the spec), ``run`` (written this time), ``skipped`` (finished
            before), ``left`` (not run: after an interrupt), ``retried`` (``error`` rows run
            again), ``dropped`` (rows the spec no longer has), ``same_as_another`` (rows that
            repeat another row's computation, filled from it), ``failed`` (rows written this
            time whose status is not ``ok``), ``errors`` (of those, ``error`` rows),
            ``statuses`` (rows of the table per status), ``wall_time`` (s), ``csv``,
            ``parquet``, ``interrupted``.
        """
        from distributed import as_completed

        plan, columns, table = self.plan, self.columns, self.start.path
        begin_table(self.start, columns)
        copies: dict[str, list[Case]] = {}
        for case in self.todo:
            if case.key in plan.same_as:
                copies.setdefault(plan.same_as[case.key][0], []).append(case)
        runs = [c for c in self.todo if c.key not in plan.same_as]
        client = engine.client
        references = self._references(runs, client) if self.spec.reference else {}
        batches = _batches(runs, engine.n_workers)
        futures = [
            client.submit(_run_batch, batch, plan.scenes[batch[0].scene],
                          references.get(_ref_key(batch[0])),
                          key=f"cases-{batch[0].key}-{len(batch)}-{os.getpid()}", pure=False)
            for batch in batches
        ]
        bar = BenchProgress(len(self.todo), enabled=progress)
        statuses = Counter(row["status"] for row in self.start.kept)
        written = {"n": 0, "failed": 0, "errors": 0}
        started = time.perf_counter()
        interrupted = False

        def put(writer, row: dict) -> None:
            writer.writerow({k: cell(row.get(k)) for k in columns})
            status = str(row.get("status"))
            statuses[status] += 1
            written["n"] += 1
            written["failed"] += status != "ok"
            written["errors"] += status == FAILED

        def put_copies(writer, row: dict) -> None:
            for case in copies.pop(row["key"], []):
                why = plan.same_as[case.key][1]
                note = f"same run as row {row['key']} ({why})"
                if row.get("message"):
                    note += f"; {row['message']}"
                put(writer, {**row, **case.as_row(), "message": note})

        # SIGINT/SIGTERM only set a flag (logs.signals): nothing inside Dask is interrupted, and
        # the loop stops at the next finished batch, keeping every row written.
        with StopSignals() as stop, table.open("a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
            for row in self.start.kept:  # rows that repeat a finished row, not written yet
                put_copies(writer, row)
            try:
                for fut in as_completed(futures):
                    if stop.requested:
                        break
                    try:
                        rows = fut.result()
                    except Exception as exc:  # a worker died or a run raised: rows with why
                        batch = batches[futures.index(fut)]
                        rows = [{**case.as_row(), **dict.fromkeys(MEASURES), "status": FAILED,
                                 "message": f"{type(exc).__name__}: {exc}"} for case in batch]
                    for row in rows:
                        put(writer, row)
                        put_copies(writer, row)
                    f.flush()
                    bar.advance(written["n"] - bar.done,
                                f"{written['n']}/{len(self.todo)} rows, {written['failed']} failed")
            except KeyboardInterrupt:  # a signal handler other than ours (not the main thread)
                interrupted = True
            if stop.requested:
                interrupted = True
            if interrupted:
                client.cancel(futures)
            bar.close()
        parquet = write_parquet(table, self.out / RESULTS_PARQUET)
        return {
            "rows": len(plan.cases), "run": written["n"], "skipped": len(self.start.kept),
            "left": len(self.todo) - written["n"], "retried": self.start.retried,
            "dropped": self.start.dropped, "same_as_another": len(plan.same_as),
            "failed": written["failed"], "errors": written["errors"],
            "statuses": dict(sorted(statuses.items())),
            "wall_time": time.perf_counter() - started, "csv": str(table),
            "parquet": str(parquet), "interrupted": interrupted,
        }

    def _references(self, cases: Sequence[Case], client) -> dict:
        """One reference future per scene and parameter set, at a rate every case's rate
        divides."""
        from vjm_ros.studies.sweep.run import reference_for

        groups: dict[tuple, list[Case]] = {}
        for c in cases:
            groups.setdefault(_ref_key(c), []).append(c)
        refs = {}
        for key, group in groups.items():
            text = self.plan.scenes[key[0]]
            scene = case_scene(*text, key[1])
            horizon = max(case_duration(c, scene) for c in group)
            rate = _common_rate({float(case_settings(c, scene).rate) for c in group})
            refs[key] = client.submit(reference_for, *text, key[1], horizon, rate, pure=False)
        return refs


def _run_batch(cases: list[Case], scene_text: tuple[str, str], reference) -> list[dict]:
    from vjm_ros.studies.sweep.run import run_case

    return [run_case(case, scene_text, reference) for case in cases]


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


def _common_rate(rates: set[float]) -> float:
    """The smallest rate (Hz) that every integer rate divides, if at most 10 kHz; else 1 kHz."""
    if rates and all(r == int(r) for r in rates):
        lcm = math.lcm(*(int(r) for r in rates))
        if lcm <= 10_000:
            return float(lcm)
    return 1000.0
