"""Checks of ``vjm sweep`` and ``vjm tune`` that the other sweep tests leave open.

Refusals that must come before any cluster starts (an engine that records whether it was
entered stands in for Dask: no cluster is wanted there), the tuner's default duration (a scene
file whose duration differs from every built-in's 10 s, so a hard-coded default cannot pass),
``--overwrite`` and ``--resume`` together, and one end-to-end run on a scheduler started here and
reached by its address: the handshake accepts a real scheduler, the scene file is deleted
before the rows run (its text, not its path, must reach the workers), a per-scene axis runs, and
``--resume`` says how many ``error`` rows it runs again.
"""

from __future__ import annotations

import csv
import logging
from pathlib import Path

import pytest

from vjm_ros.scene import load_scene
from vjm_ros.studies.sweep import cli as sweep_cli
from vjm_ros.studies.sweep.engine import Engine, Sweep
from vjm_ros.studies.sweep.spec import parse_spec
from vjm_ros.studies.sweep.table import RESULTS_CSV, begin_table, inspect_table

BASE = "scenes: [four_bar]\nduration: 0.01\nreference: false\n"


class _NoCluster:
    """An engine that must not be entered: records it if it is."""

    entered = 0

    def __init__(self, *args, **kwargs) -> None:
        pass

    def __enter__(self):
        type(self).entered += 1
        raise AssertionError("a cluster was started for a refused sweep")

    def __exit__(self, *exc) -> None:
        pass


@pytest.mark.parametrize("text", [
    BASE + "grid:\n  rate: [500, -100]\n",
    BASE + "grid:\n  kp: [100]\n  omega_n: [60]\n",
    BASE.replace("[four_bar]", "[four_bar, no_such_scene_here]"),
    BASE + "grid:\n  mass.knee: [1.0]\n",
], ids=["value", "row", "scene", "parameter"])
def test_bad_input_is_refused_before_any_cluster_is_started(tmp_path, capsys, monkeypatch,
                                                            text):
    monkeypatch.setattr(sweep_cli, "Engine", _NoCluster)
    _NoCluster.entered = 0
    spec = tmp_path / "bad.yaml"
    spec.write_text(text)
    code = sweep_cli.main("sweep", [str(spec), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert _NoCluster.entered == 0
    assert f"vjm sweep: error: {spec}: " in err and not (tmp_path / "out").exists()


def test_a_scene_that_does_not_load_is_refused_naming_its_entry(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sweep_cli, "Engine", _NoCluster)
    spec = tmp_path / "bad.yaml"
    spec.write_text(BASE.replace("[four_bar]", "[four_bar, no_such_scene_here]"))
    assert sweep_cli.main("sweep", [str(spec), "--out", str(tmp_path / "out")]) == 2
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"{spec}: scenes[1]: " in line and "no_such_scene_here" in line, line


def test_resume_and_overwrite_together_are_refused_and_the_table_kept(tmp_path, capsys,
                                                                      monkeypatch):
    monkeypatch.setattr(sweep_cli, "Engine", _NoCluster)
    out = tmp_path / "out"
    out.mkdir()
    table = out / RESULTS_CSV
    table.write_text("key,scene,status\nabc,four_bar,ok\n")
    spec = tmp_path / "s.yaml"
    spec.write_text(BASE)
    code = sweep_cli.main("sweep", [str(spec), "--out", str(out), "--resume", "--overwrite"])
    assert code == 2
    assert "--resume, --overwrite: expected one of them, found both" in capsys.readouterr().err
    assert table.read_text() == "key,scene,status\nabc,four_bar,ok\n"


def test_overwrite_starts_the_table_again(tmp_path):
    spec = parse_spec(BASE, "s.yaml")
    sweep_columns = Sweep(spec, tmp_path / "fresh").columns
    table = tmp_path / RESULTS_CSV
    table.write_text("key,scene,status\nabc,four_bar,ok\ndef,four_bar,error\n")
    start = inspect_table(tmp_path, sweep_columns, {"k"}, resume=False, overwrite=True)
    assert (start.replaced, start.kept, start.retried) == (2, [], 0)
    assert table.read_text().count("\n") == 3  # nothing written before the run
    begin_table(start, sweep_columns)
    with table.open(newline="") as f:  # read back by the csv module: the header alone
        assert list(csv.reader(f)) == [sweep_columns]


def test_tune_lasts_the_scene_files_own_duration_by_default(tmp_path):
    from vjm_ros.studies.sweep.tune import tuning_spec

    text = load_scene("four_bar").text
    assert "duration: 10" in text
    scene = tmp_path / "short_four_bar.yaml"
    scene.write_text(text.replace("duration: 10", "duration: 3.5", 1))
    assert load_scene(str(scene)).defaults["duration"] == 3.5
    assert sweep_cli.tune_parser().parse_args([str(scene)]).duration is None
    cases = tuning_spec(str(scene), "rk4", 1000.0, 1).cases()
    assert cases and {c.settings["duration"] for c in cases} == {3.5}
    cases = tuning_spec(str(scene), "rk4", 1000.0, 1, duration=0.5).cases()
    assert {c.settings["duration"] for c in cases} == {0.5}  # --duration wins


@pytest.fixture(scope="module")
def scheduler():
    """A scheduler and one worker process, reached only by address (an external cluster)."""
    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                           dashboard_address=":0", silence_logs=logging.ERROR)
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()


@pytest.mark.slow  # a scheduler and a worker of its own: the suite's five-minute budget
def test_a_sweep_on_a_scheduler_given_by_address_sends_the_scene_text(scheduler, tmp_path,
                                                                      monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    Path("mine.yaml").write_text(load_scene("four_bar").text)
    spec = parse_spec("scenes:\n  - scene: mine.yaml\n    grid: {mass.crank: [1.0, 2.0]}\n"
                      "duration: 0.02\nsettings: {closure: exact}\n", "s.yaml")
    sweep = Sweep(spec, "out")  # reads the scene file: every check is done here
    Path("mine.yaml").unlink()  # a worker reading the path would find nothing
    with Engine(scheduler, timeout=10.0) as engine:  # the handshake accepts a real scheduler
        assert engine.cluster is None and engine.n_workers == 1
        result = sweep.run(engine, progress=False)
    with open("out/results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["status"] for r in rows] == ["ok", "ok"], rows
    assert sorted(r["mass.crank"] for r in rows) == ["1.0", "2.0"]
    assert all(float(r["position_deviation"]) >= 0 for r in rows)  # reference from the text
    assert (result["run"], result["errors"]) == (2, 0)

    # one row made an 'error' row, as a lost worker leaves it: --resume says it runs it again
    Path("mine.yaml").write_text(load_scene("four_bar").text)
    Path("s.yaml").write_text("scenes:\n  - scene: mine.yaml\n    grid: {mass.crank: [1.0, "
                              "2.0]}\nduration: 0.02\nsettings: {closure: exact}\n")
    header, *lines = Path("out/results.csv").read_text().splitlines()
    names = header.split(",")
    broken = dict(zip(names, next(csv.reader([lines[0]])), strict=True))
    broken.update({k: "" for k in names[names.index("status"):]}, status="error")
    lines[0] = ",".join(broken[k] for k in names)
    Path("out/results.csv").write_text("\n".join([header, *lines]) + "\n")
    code = sweep_cli.main("sweep", ["s.yaml", "--out", "out", "--resume", "--cluster", scheduler,
                                    "--no-progress", "--figure"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "1 finished rows kept, 1 'error' rows run again" in err
    with open("out/results.csv", newline="") as f:
        assert [r["status"] for r in csv.DictReader(f)] == ["ok", "ok"]
    # the summary a reader sees: counts, what ran, where the table and the figure are
    assert "vjm sweep: 2 rows in out/results.csv (and out/results.parquet): 2 ok\n" in err
    assert "vjm sweep: 1 run this time, 1 kept from before, 1 'error' rows run again; " in err
    assert "vjm sweep: figure: out/sweep.png" in err and Path("out/sweep.png").is_file()


def test_a_sweep_whose_every_row_fails_exits_non_zero(scheduler, tmp_path, capsys):
    from distributed import Client

    def lose_a_module() -> None:  # on the worker: every run raises, as a missing module would
        import vjm_ros.studies.sweep.run as run

        def run_case(*args, **kwargs):
            raise ModuleNotFoundError("No module named 'numba'")

        run._kept_run_case = run.run_case
        run.run_case = run_case

    def restore() -> None:
        import vjm_ros.studies.sweep.run as run

        run.run_case = run._kept_run_case

    spec = tmp_path / "s.yaml"
    spec.write_text(BASE + "settings: {closure: exact}\ngrid:\n  integrator: [rk4, "
                    "semi_implicit_euler]\n")
    out = tmp_path / "out"
    with Client(scheduler) as client:
        client.run(lose_a_module)
        try:
            code = sweep_cli.main("sweep", [str(spec), "--out", str(out), "--cluster",
                                            scheduler, "--no-progress"])
        finally:
            client.run(restore)
    err = capsys.readouterr().err
    assert code == 1, err
    assert "every row run failed with an error" in err
    with (out / RESULTS_CSV).open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["status"] for r in rows] == ["error", "error"]
    assert all("ModuleNotFoundError: No module named 'numba'" in r["message"] for r in rows)


def test_the_sweep_figure_plots_every_row_with_both_measures(tmp_path, monkeypatch):
    import matplotlib.figure

    from vjm_ros.studies.sweep.summary import plot_sweep

    spec = parse_spec(BASE + "settings: {closure: exact}\ngrid:\n  integrator: [rk4, "
                      "semi_implicit_euler]\n  rate: [500, 1000]\n", "s.yaml")
    sweep = Sweep(spec, tmp_path)
    # a table written here: the oracle is these numbers, not the code's own output
    columns = sweep.columns
    values = {  # (integrator, rate): (max_closure_error, wall_time); None: not measured
        ("rk4", 500): (1e-6, 0.02), ("rk4", 1000): (2e-7, 0.04),
        ("semi_implicit_euler", 500): (3e-4, 0.01), ("semi_implicit_euler", 1000): (None, None)}
    with sweep.start.path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for case in sweep.plan.cases:
            err, wall = values[case.settings["integrator"], case.settings["rate"]]
            writer.writerow({**dict.fromkeys(columns, ""), **case.as_row(),
                             "status": "ok" if err else "diverged",
                             "max_closure_error": "" if err is None else repr(err),
                             "wall_time": "" if wall is None else repr(wall)})
    saved = []
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                        lambda fig, *a, **k: saved.append(fig))
    plot_sweep(sweep, "max_closure_error", "wall_time", tmp_path / "sweep.png")
    (ax,) = [a for a in saved[0].axes if a.collections]
    points = {tuple(p) for c in ax.collections for p in c.get_offsets().tolist()}
    assert points == {(w, e) for e, w in values.values() if e is not None}
    labels = sorted(t.get_text() for t in ax.get_legend().get_texts())
    assert labels == ["integrator rk4", "integrator semi_implicit_euler"]
