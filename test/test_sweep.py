"""``vjm sweep`` and ``vjm tune`` on a real Dask ``LocalCluster`` of two worker processes.

Checks: specs are validated before any run, naming the key; every case becomes one row (failed
and refused ones with their reason); rows are keyed by their settings and the same spec gives the
same numbers (timing aside); ``--resume`` runs only what is missing; Ctrl-C leaves a complete
table and no worker process; tuning picks the gains with the smallest closure error among the
rows that ran and writes them as a scene snippet that loads.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from vjm_ros.core.errors import ConfigurationError
from vjm_ros.studies.sweep.engine import Engine, Sweep
from vjm_ros.studies.sweep.run import MEASURES
from vjm_ros.studies.sweep.spec import SpecError, load_spec, parse_spec
from vjm_ros.studies.sweep.table import RESULTS_CSV, RESULTS_PARQUET, cell

ROOT = Path(__file__).resolve().parents[1]
SPEC = """
name: small
scenes: [five_bar, four_bar]
duration: 0.05
settings: {closure: penalty}
grid:
  integrator: [rk4, semi_implicit_euler]
  omega_n: [60, 5000]
  zeta: [1.0]
"""


@pytest.fixture(scope="module")
def engine():
    with Engine(workers=2) as eng:
        yield eng


def rows_of(path: Path) -> list[dict]:
    with (path / RESULTS_CSV).open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize(
    "text, key, expected",
    [
        ("scenes: [four_bar]\ncolour: red\n", "colour", "one of the keys"),
        ("scenes: []\n", "scenes", "a non-empty list"),
        ("scenes: [four_bar]\nsettings: {warp: 9}\n", "settings.warp", "one of ["),
        ("scenes: [four_bar]\ngrid: {rate: []}\n", "grid.rate", "a non-empty list of values"),
        ("scenes: [four_bar]\ngrid: {speed: [1]}\n", "grid.speed", "a vjm run setting"),
        ("scenes: [four_bar]\ngrid: {rate: [.nan]}\n", "grid.rate[0]", "a finite number"),
        ("scenes: [four_bar]\nduration: -1\n", "duration", "a positive number"),
        ("scenes: [four_bar]\nsettings: {rate: 500}\ngrid: {rate: [1000]}\n", "grid.rate",
         "not also fixed"),
    ],
    ids=["unknown_key", "no_scenes", "unknown_setting", "empty_axis", "unknown_axis", "nan",
         "negative_duration", "fixed_and_swept"],
)
def test_bad_specs_are_refused_naming_the_key(text, key, expected):
    with pytest.raises(SpecError) as info:
        parse_spec(text, "bad.yaml")
    assert info.value.key == key and expected in info.value.expected
    assert str(info.value).startswith(f"bad.yaml: {key}: expected ")


def test_an_unreachable_scheduler_is_refused_before_any_run():
    with pytest.raises(ConfigurationError, match=r"--cluster tcp://127\.0\.0\.1:9: expected a "
                                                 r"reachable Dask scheduler"):
        with Engine("tcp://127.0.0.1:9", timeout=1.0):
            pass


def test_a_worker_address_is_refused_as_not_a_scheduler(engine):
    worker = next(iter(engine.client.scheduler_info()["workers"]))
    with pytest.raises(ConfigurationError, match=f"--cluster {worker}: expected a Dask "
                                                 "scheduler, found Worker"):
        with Engine(worker, timeout=5.0):
            pass


def test_unknown_scene_parameters_are_refused_before_any_run(engine, tmp_path):
    spec = parse_spec(SPEC.replace("zeta: [1.0]", "mass.knee: [1.0]"), "s.yaml")
    with pytest.raises(ConfigurationError, match="grid.mass.knee: expected a link of five_bar"):
        Sweep(spec, tmp_path).run(engine, progress=False)
    assert not (tmp_path / RESULTS_CSV).exists()


def test_every_case_is_a_row_and_the_same_spec_gives_the_same_numbers(engine, tmp_path):
    spec = parse_spec(SPEC, "small.yaml")
    first = Sweep(spec, tmp_path / "a").run(engine, progress=False)
    Sweep(spec, tmp_path / "b").run(engine, progress=False)
    assert first["rows"] == first["run"] == 8 and not first["interrupted"]
    a, b = rows_of(tmp_path / "a"), rows_of(tmp_path / "b")
    assert len({r["key"] for r in a}) == 8  # keyed by scene and settings
    statuses = {r["status"] for r in a}
    assert statuses == {"ok", "refused (stiffness)"}  # 5000 rad/s is beyond either method's bound
    refused = [r for r in a if r["status"] != "ok"]
    assert all(r["omega_n"] == "5000" and "stability bound" in r["message"] for r in refused)
    ok = [r for r in a if r["status"] == "ok"]
    assert all(float(r["position_deviation"]) > 0 for r in ok)  # against the shared reference
    by_key = {r["key"]: r for r in b}
    for row in a:  # reproducible: every measure but the timing
        other = by_key[row["key"]]
        for m in MEASURES:
            if m != "wall_time":
                assert row[m] == other[m], (row["key"], m)
    table = pq.read_table(tmp_path / "a" / RESULTS_PARQUET)
    assert table.num_rows == 8 and set(spec.columns + list(MEASURES)) == set(table.column_names)
    # the Parquet holds the CSV's values, each column of one type: numbers a reader can compute
    # with (the measures float64, empty cells null), text as text
    for name in table.column_names:
        kind = table.schema.field(name).type
        for row, value in zip(a, table.column(name).to_pylist(), strict=True):
            text = row[name]
            if text == "":
                assert value is None, (name, row["key"])
            elif kind == pa.string():
                assert value == text, (name, row["key"])
            elif kind == pa.bool_():
                assert value is (text == "True"), (name, row["key"])
            else:
                assert value == float(text), (name, row["key"])
    assert {table.schema.field(m).type for m in MEASURES if m not in ("status", "message")} <= {
        pa.float64(), pa.int64(), pa.bool_()}


def test_resume_runs_only_the_missing_rows(engine, tmp_path):
    spec = parse_spec(SPEC, "small.yaml")
    Sweep(spec, tmp_path).run(engine, progress=False)
    lines = (tmp_path / RESULTS_CSV).read_text().splitlines()
    (tmp_path / RESULTS_CSV).write_text("\n".join(lines[:4]) + "\n")  # header and three rows
    again = Sweep(spec, tmp_path, resume=True).run(engine, progress=False)
    assert (again["run"], again["skipped"]) == (5, 3)
    rows = rows_of(tmp_path)
    assert len(rows) == 8 and len({r["key"] for r in rows}) == 8


def test_a_resumed_table_keeps_to_the_spec_and_runs_error_rows_again(engine, tmp_path):
    spec = parse_spec(SPEC, "small.yaml")
    Sweep(spec, tmp_path).run(engine, progress=False)
    table = tmp_path / RESULTS_CSV
    rows = rows_of(tmp_path)
    lost = next(r for r in rows if r["omega_n"] == "60" and r["status"] == "ok")
    # one ok row becomes an error row, as a lost worker leaves it
    text = table.read_text()
    line = next(x for x in text.splitlines() if x.startswith(lost["key"]))
    names = list(lost)
    error = {**lost, **dict.fromkeys(MEASURES, ""), "status": "error",
             "message": "KilledWorker: lost"}
    table.write_text(text.replace(line, ",".join(error[k] for k in names)))
    shrunk = parse_spec(SPEC.replace("omega_n: [60, 5000]", "omega_n: [60]"), "small.yaml")
    again = Sweep(shrunk, tmp_path, resume=True).run(engine, progress=False)
    assert (again["dropped"], again["retried"], again["skipped"], again["run"]) == (4, 1, 3, 1)
    after = rows_of(tmp_path)
    assert sorted(r["key"] for r in after) == sorted(c.key for c in shrunk.cases())
    assert {r["key"]: r["status"] for r in after}[lost["key"]] == "ok"
    assert again["statuses"] == {"ok": 4}


def test_workers_elsewhere_run_a_scene_file_named_by_a_relative_path(engine, tmp_path,
                                                                     monkeypatch):
    from vjm_ros.scene import load_scene

    # the workers run in the directory the cluster started in; the spec's scene is a file
    # relative to this one, which they cannot see
    monkeypatch.chdir(tmp_path)
    Path("my_four_bar.yaml").write_text(load_scene("four_bar").text)
    spec = parse_spec("scenes: [my_four_bar.yaml]\nduration: 0.05\n"
                      "settings: {closure: exact}\n", "s.yaml")
    result = Sweep(spec, "out").run(engine, progress=False)
    rows = rows_of(tmp_path / "out")
    assert [r["status"] for r in rows] == ["ok"], rows
    assert float(rows[0]["position_deviation"]) >= 0  # the reference ran on a worker too
    assert result["errors"] == 0


def test_runs_that_are_one_computation_run_once_and_say_so(engine, tmp_path):
    from vjm_ros.studies.sweep.run import run_case, scene_source

    spec = parse_spec(
        "scenes: [four_bar]\nduration: 0.05\nreference: false\ngrid:\n"
        "  closure: [penalty, exact]\n  integrator: [semi_implicit_euler, implicit_euler]\n"
        "  omega_n: [60, 120]\n  projection: [false, true]\n", "dup.yaml")
    sweep = Sweep(spec, tmp_path)
    # exact: one run per projection (gains and implicit_euler make no difference);
    # penalty: one per integrator and omega_n (projection makes none)
    assert len(sweep.plan.cases) == 16 and len(sweep.plan.same_as) == 16 - 2 - 4
    result = sweep.run(engine, progress=False)
    assert result["same_as_another"] == 10 and result["run"] == 16
    rows = {r["key"]: r for r in rows_of(tmp_path)}
    scene = scene_source("four_bar")
    for case in sweep.plan.cases:
        if case.key not in sweep.plan.same_as:
            continue
        first, why = sweep.plan.same_as[case.key]
        assert rows[case.key]["message"].startswith(f"same run as row {first} (")
        # the claim checked by running the repeated row as it is: every measure the same
        ran = run_case(case, scene)
        for m in MEASURES:
            if m not in ("wall_time", "message"):
                assert cell(ran[m]) == rows[first][m], (case.settings, m, why)


@pytest.mark.slow  # ~7 s: kernels no other test here compiles (every row of every example is
# checked in the default suite by test_sweep_checks.py)
def test_every_example_spec_runs(engine, tmp_path):
    for path in sorted((ROOT / "examples").glob("*.yaml")):
        spec = load_spec(path)
        spec.duration, spec.reference = 0.02, False  # every row, briefly
        result = Sweep(spec, tmp_path / path.stem).run(engine, progress=False)
        assert result["run"] == result["rows"] == len(spec.cases())
        assert result["errors"] == 0, result


def test_the_summary_and_the_figure_of_a_sweep(engine, tmp_path):
    from vjm_ros.studies.sweep.summary import plot_sweep, summary_lines

    spec = parse_spec(SPEC, "small.yaml")
    sweep = Sweep(spec, tmp_path)
    result = sweep.run(engine, progress=False)
    lines = summary_lines(result)
    ok = sum(r["status"] == "ok" for r in rows_of(tmp_path))
    assert lines[0] == (f"8 rows in {tmp_path / RESULTS_CSV} (and {tmp_path / RESULTS_PARQUET})"
                        f": {ok} ok, {8 - ok} refused (stiffness)")
    assert lines[1].startswith("8 run this time, 0 kept from before; ")
    figure = plot_sweep(sweep, "max_closure_error", "wall_time", tmp_path / "sweep.png")
    assert figure.stat().st_size > 10_000


def test_scene_parameters_change_the_mechanism(engine, tmp_path):
    spec = parse_spec(
        "scenes: [four_bar]\nduration: 0.05\nsettings: {closure: exact}\nreference: false\n"
        "grid:\n  mass.crank: [1.0, 4.0]\n  initial.crank_joint: [0.0, 20.0]\n", "p.yaml")
    Sweep(spec, tmp_path).run(engine, progress=False)
    rows = rows_of(tmp_path)
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows)
    drifts = {(r["mass.crank"], r["initial.crank_joint"]): float(r["energy_drift"]) for r in rows}
    assert len(set(drifts.values())) == 4  # four different mechanisms or start poses


def _children(pid: int) -> set[int]:
    """Descendants of ``pid`` (a process that exits meanwhile has none)."""
    out = set()
    try:
        tasks = list(Path(f"/proc/{pid}/task").glob("*"))
    except OSError:  # it exited between being listed and being read
        return out
    for task in tasks:
        try:
            out |= {int(x) for x in (task / "children").read_text().split()}
        except OSError:
            continue
    for child in list(out):
        out |= _children(child)
    return out


def _cmdline(pid: int) -> bytes | None:
    """The start of a live process's command line; None once it has exited."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()[:200]
    except OSError:
        return None


@pytest.mark.slow  # a sweep interrupted mid-run, with its workers: the signal tests' suite
def test_ctrl_c_leaves_a_complete_table_and_no_worker(tmp_path):
    spec = tmp_path / "big.yaml"
    # 320 runs of 2 simulated s: minutes of work, so the signal always comes while it runs
    spec.write_text(SPEC.replace("duration: 0.05", "duration: 2.0").replace(
        "omega_n: [60, 5000]", "omega_n: [40, 50, 60, 70, 80, 90, 100, 110]").replace(
        "zeta: [1.0]", "zeta: [0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4]"))
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "vjm_ros.app.cli", "sweep", str(spec), "--out", str(out),
         "--workers", "2", "--no-progress"], cwd=ROOT, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True)
    workers: set[int] = set()
    try:
        deadline = time.monotonic() + 120  # a hang guard
        while time.monotonic() < deadline:
            workers |= _children(proc.pid)
            if (out / RESULTS_CSV).exists() and len(rows_of(out)) >= 2:
                break
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, stderr
    result = json.loads(stdout.strip().splitlines()[-1])
    assert result["interrupted"]
    rows = rows_of(out)
    assert 2 <= len(rows) < 320
    # what ran, what is left, and how to run it
    assert (result["run"], result["left"]) == (len(rows), 320 - len(rows))
    assert (f"interrupted after {len(rows)} of 320 rows ({320 - len(rows)} left); to run the "
            f"rest: vjm sweep {spec} --out {out} --resume --workers 2") in stderr
    assert all(r["status"] in ("ok", "refused (stiffness)", "diverged") for r in rows)
    assert pq.read_table(out / RESULTS_PARQUET).num_rows == len(rows)
    deadline = time.monotonic() + 30  # a hang guard: processes need a moment to exit
    while time.monotonic() < deadline and any(Path(f"/proc/{p}").exists() for p in workers):
        time.sleep(0.1)
    alive = {p: _cmdline(p) for p in workers}
    alive = {p: c for p, c in alive.items() if c is not None}
    assert workers and not alive, alive


@pytest.mark.slow  # a local cluster of its own and 60 runs: ~15 s
def test_tune_writes_the_best_gains_as_a_loadable_snippet(tmp_path):
    out = tmp_path / "tune"
    done = subprocess.run(
        [sys.executable, "-m", "vjm_ros.app.cli", "tune", "four_bar", "--integrator", "rk4",
         "--rate", "1000", "--duration", "0.1", "--workers", "2", "--no-progress",
         "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    assert any(r["status"].startswith("refused") for r in rows_of(out))  # beyond the bound
    edges = {float(z): e for z, e in summary["stability_edge"].items()}
    # the best of the rows that ran a factor MARGIN below their damping ratio's edge
    rows = [r for r in rows_of(out) if r["status"] == "ok" and (
        edges[float(r["zeta"])] is None
        or float(r["omega_n"]) <= edges[float(r["zeta"])] / summary["margin"])]
    best = min(float(r["max_closure_error"]) for r in rows)
    assert summary["chosen"]["max_closure_error"] == best
    snippet = yaml.safe_load((out / "gains.yaml").read_text())["closure_method"]
    assert snippet["omega_n"] == summary["chosen"]["omega_n"]
    from vjm_ros.scene import load_scene, parse_scene

    base = yaml.safe_load(load_scene("four_bar").text)
    base["closure_method"] = snippet
    assert parse_scene(yaml.safe_dump(base), "tuned").gains["omega_n"] == snippet["omega_n"]
    assert (out / "tuning.png").stat().st_size > 10_000
    assert os.path.exists(summary["figure"])


def test_tune_runs_on_an_existing_scheduler(engine, tmp_path, capsys):
    """``vjm tune --cluster``: the runs go to the scheduler named (the module's cluster, whose
    workers count the tasks they execute), and the choice is the one the rows make."""
    from vjm_ros.studies.sweep import cli as sweep_cli

    def executed(dask_worker):
        return dask_worker.state.executed_count

    before = sum(engine.client.run(executed).values())
    out = tmp_path / "tune"
    code = sweep_cli.main("tune", ["four_bar", "--integrator", "rk4", "--rate", "1000",
                                   "--duration", "0.1", "--no-progress", "--out", str(out),
                                   "--cluster", engine.client.scheduler.address])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    rows = rows_of(out)
    ran = [r for r in rows if r["status"] == "ok"]
    assert ran and sum(engine.client.run(executed).values()) - before >= len(ran)
    summary = json.loads(stdout.strip().splitlines()[-1])
    edges = {float(z): e for z, e in summary["stability_edge"].items()}
    within = [r for r in ran if edges[float(r["zeta"])] is None
              or float(r["omega_n"]) <= edges[float(r["zeta"])] / summary["margin"]]
    assert summary["chosen"]["max_closure_error"] == min(
        float(r["max_closure_error"]) for r in within)
    snippet = yaml.safe_load((out / "gains.yaml").read_text())["closure_method"]
    assert snippet["omega_n"] == summary["chosen"]["omega_n"]
