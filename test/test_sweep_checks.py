"""What ``vjm sweep`` and ``vjm tune`` refuse before any cluster starts, and the pieces that need
no cluster: the scheduler handshake, the table's guard and schema, the tuner's margin, the
example specs.

No Dask cluster starts here (a refused spec exits before one would), so these tests are fast;
the end-to-end runs are in ``test_sweep.py``.
"""

from __future__ import annotations

import http.server
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from vjm_ros.core.errors import ConfigurationError
from vjm_ros.studies.sweep import cli as sweep_cli
from vjm_ros.studies.sweep.engine import Engine
from vjm_ros.studies.sweep.spec import SpecError, load_spec, parse_spec
from vjm_ros.studies.sweep.table import RESULTS_CSV, write_parquet

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.yaml"))
HANG_GUARD = 120.0  # s: a hang guard, never a speed requirement


def refused(tmp_path: Path, text: str, capsys, *extra: str) -> str:
    """``vjm sweep`` on a spec of ``text``: exit 2, nothing written; the error line."""
    spec = tmp_path / "bad.yaml"
    spec.write_text(text)
    out = tmp_path / "out"
    code = sweep_cli.main("sweep", [str(spec), "--out", str(out), "--workers", "1", *extra])
    err = capsys.readouterr().err
    assert code == 2, err
    assert not out.exists()  # refused before anything is written
    return err.strip().splitlines()[-1]


BASE = "scenes: [four_bar]\nduration: 0.01\nreference: false\n"


@pytest.mark.parametrize(
    "grid, message",
    [
        ("integrator: [rk4, runge_kutta_9]", "grid.integrator[1]: expected one of ['explicit_euler'"),
        ("closure: [magic]", "grid.closure[0]: expected one of ['penalty', 'exact'], found 'magic'"),
        ("kernel: [fortran]", "grid.kernel[0]: expected one of ['auto', 'numba'], found 'fortran'"),
        ("rate: [fast]", "grid.rate[0]: expected a finite number, found 'fast'"),
        ("rate: [500, -100]", "grid.rate[1]: expected a positive number of Hz, found -100"),
        ("omega_n: [abc]", "grid.omega_n[0]: expected a finite number, found 'abc'"),
        ("substeps: [1.5]", "grid.substeps[0]: expected a whole number of steps per tick >= 1, "
                            "found 1.5"),
        ("projection: [maybe]", "grid.projection[0]: expected true or false, found 'maybe'"),
        ("kp: [100]\n  omega_n: [60]", "row 1 of 1 (four_bar: kp=100, omega_n=60): give either "
                                       "grid.kp/kv or grid.omega_n/zeta, not both"),
        ("zeta: [0.7]", "row 1 of 1 (four_bar: zeta=0.7): grid.zeta needs omega_n"),
        ("mass.crank: [1.0, -1.0]", "row 2 of 2 (four_bar: mass.crank=-1.0): four_bar with "
                                    '{"mass.crank": -1.0}: chains[0].links[0].mass: expected'),
        ("mass.knee: [1.0]", "grid.mass.knee: expected a link of four_bar (crank, coupler, "
                             "rocker), found 'knee'"),
    ],
    ids=["integrator", "closure", "kernel", "rate_word", "rate_negative", "omega_n_word",
         "substeps_fraction", "projection_word", "kp_with_omega_n", "zeta_alone",
         "negative_mass", "unknown_link"],
)
def test_bad_values_are_refused_before_any_cluster_naming_file_row_and_key(
        tmp_path, capsys, grid, message):
    line = refused(tmp_path, BASE + f"grid:\n  {grid}\n", capsys)
    assert line.startswith(f"vjm sweep: error: {tmp_path / 'bad.yaml'}: "), line
    assert message in line, line


def test_a_fixed_setting_is_checked_as_an_axis_is(tmp_path, capsys):
    line = refused(tmp_path, BASE + "settings: {integrator: runge_kutta_9}\n", capsys)
    assert "settings.integrator: expected one of [" in line


def test_a_yaml_syntax_error_names_line_and_column(tmp_path, capsys):
    line = refused(tmp_path, BASE + "grid:\n  rate: [500, 1000\n  zeta: [1]\n", capsys)
    assert "bad.yaml: line 6, column 7: expected valid YAML" in line, line


def test_the_command_line_refuses_a_bad_spec_at_once(tmp_path):
    spec = tmp_path / "bad.yaml"
    spec.write_text(BASE + "grid:\n  substeps: [1, 1.5]\n")
    done = subprocess.run(
        [sys.executable, "-m", "vjm_ros.app.cli", "sweep", str(spec), "--out",
         str(tmp_path / "out")], capture_output=True, text=True, timeout=HANG_GUARD)
    assert done.returncode == 2, done.stderr
    assert "grid.substeps[1]: expected a whole number" in done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "out").exists()


def test_a_per_scene_axis_is_checked_against_its_scene_only(tmp_path, capsys):
    text = ("scenes:\n  - five_bar\n  - scene: four_bar\n    grid: {mass.crank: [1.0, 1.5]}\n"
            "duration: 0.01\n")
    spec = parse_spec(text, "s.yaml")
    cases = spec.cases()
    # five_bar has no link "crank": its single row has no such parameter
    assert [(c.scene, c.parameters) for c in cases] == [
        ("five_bar", {}), ("four_bar", {"mass.crank": 1.0}), ("four_bar", {"mass.crank": 1.5})]
    assert spec.columns == ["key", "scene", "mass.crank", "duration"]
    line = refused(tmp_path, text.replace("crank", "knee"), capsys)
    assert "scenes[1].grid.mass.knee: expected a link of four_bar" in line, line
    with pytest.raises(SpecError, match=r"scenes\[1\]\.grid\.rate: expected an axis that is not "
                                        "also in the common grid"):
        parse_spec("scenes: [five_bar, {scene: four_bar, grid: {rate: [500]}}]\n"
                   "grid: {rate: [1000]}\n", "s.yaml")


def test_an_existing_table_is_never_replaced_by_surprise(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    table = out / RESULTS_CSV
    table.write_text("key,scene,status\nabc,four_bar,ok\n")
    spec = tmp_path / "s.yaml"
    spec.write_text(BASE)
    code = sweep_cli.main("sweep", [str(spec), "--out", str(out), "--workers", "1"])
    err = capsys.readouterr().err
    assert code == 2
    assert f"{table}: expected no results table, found one with 1 rows; --resume" in err
    assert table.read_text() == "key,scene,status\nabc,four_bar,ok\n"
    code = sweep_cli.main("sweep", [str(spec), "--out", str(out), "--resume", "--workers", "1"])
    assert code == 2
    assert "expected the columns of this spec to resume" in capsys.readouterr().err
    assert table.read_text() == "key,scene,status\nabc,four_bar,ok\n"


class _Http(http.server.BaseHTTPRequestHandler):
    def do_GET(self):  # noqa: N802 - the handler's name in http.server
        self.send_response(200)
        self.end_headers()

    def log_message(self, *args):
        pass


@pytest.fixture
def http_server():
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Http)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


def test_a_server_that_is_not_a_scheduler_is_refused_within_the_timeout(http_server, tmp_path):
    spec = tmp_path / "s.yaml"
    spec.write_text(BASE)
    done = subprocess.run(
        [sys.executable, "-m", "vjm_ros.app.cli", "sweep", str(spec), "--out",
         str(tmp_path / "out"), "--cluster", http_server, "--cluster-timeout", "0.5"],
        capture_output=True, text=True, timeout=HANG_GUARD)
    assert done.returncode == 2, done.stderr
    assert (f"--cluster {http_server}: expected a Dask scheduler to answer within 0.5 s "
            "(--cluster-timeout)") in done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "out").exists()


@pytest.mark.parametrize("address, found", [
    ("tcp://127.0.0.1:notaport", "a malformed address"),
    ("scheduler", "a malformed address (missing port number"),
    ("http://127.0.0.1:8786", "a malformed address (unknown scheme 'http'"),
    ("tcp://127.0.0.1", "a malformed address"),
])
def test_a_malformed_address_is_refused_with_a_message(address, found):
    with pytest.raises(ConfigurationError) as info:
        with Engine(address, timeout=1.0):
            pass
    assert str(info.value).startswith(f"--cluster {address}: expected a scheduler address "
                                      "such as tcp://host:8786, found ")
    assert found in str(info.value)


def test_the_cluster_timeout_must_be_positive():
    with pytest.raises(ConfigurationError, match="--cluster-timeout: expected a positive"):
        Engine("tcp://127.0.0.1:8786", timeout=0.0)


def test_parquet_columns_have_one_type_whatever_the_values(tmp_path):
    header = "key,scene,rate,substeps,projection,status,message,diverged_at,finite\n"
    (tmp_path / "a.csv").write_text(header + "k1,four_bar,500,1,False,ok,,,True\n")
    (tmp_path / "b.csv").write_text(
        header + "k2,five_bar,1000.5,2,True,diverged,closure residual,0.25,False\n")
    a = pq.read_table(write_parquet(tmp_path / "a.csv", tmp_path / "a.parquet"))
    b = pq.read_table(write_parquet(tmp_path / "b.csv", tmp_path / "b.parquet"))
    assert a.schema == b.schema
    assert a.schema.field("rate").type == pa.float64()
    assert a.schema.field("diverged_at").type == pa.float64()
    assert a.schema.field("substeps").type == pa.int64()
    both = pa.concat_tables([a, b])
    assert both.column("rate").to_pylist() == [500.0, 1000.5]
    assert both.column("diverged_at").to_pylist() == [None, 0.25]
    assert both.column("message").to_pylist() == [None, "closure residual"]


def test_floats_are_written_short_and_read_back_exactly():
    from vjm_ros.studies.sweep.table import cell

    for value in (0.1, 1 / 3, 1e-300, 2.5e17, np.float64(0.1), np.float64(np.pi)):
        text = cell(value)
        assert float(text) == value and text == repr(float(value)), text
    assert (cell(None), cell(True), cell(500)) == ("", "True", "500")


def _row(omega_n: float, zeta: float, status: str, error: float | None = None) -> dict:
    return {"omega_n": omega_n, "zeta": zeta, "status": status, "max_closure_error": error,
            "wall_time": 0.1 if error else None, "duration": 1.0}


def test_the_tuner_keeps_a_margin_from_the_stability_edge():
    from vjm_ros.studies.sweep.tune import MARGIN, choose, stability_edge

    # five_bar, semi_implicit_euler at 1 kHz over 1 s (measured): too soft below 79.6 rad/s,
    # the edge at 1786.2 rad/s for zeta 0.5 and at 1063.5 for zeta 1; 1063.5 at zeta 0.5 is
    # the tightest row of 1 s, and diverges at 9.1 s of the scene's 10 s
    rows = [_row(47.4, 0.5, "diverged"), _row(79.6, 0.5, "ok", 0.12),
            _row(377.0, 0.5, "ok", 0.0117), _row(633.2, 0.5, "ok", 0.0041),
            _row(1063.5, 0.5, "ok", 0.00136), _row(1786.2, 0.5, "refused (stiffness)"),
            _row(79.6, 1.0, "ok", 0.113), _row(377.0, 1.0, "ok", 0.0102),
            _row(633.2, 1.0, "ok", 0.0036), _row(1063.5, 1.0, "refused (stiffness)"),
            _row(10.0, 2.0, "diverged")]
    edges = stability_edge(rows)
    assert edges == {0.5: 1786.2, 1.0: 1063.5, 2.0: None}  # too soft is not the edge
    chosen = choose(rows, edges)
    assert (chosen["omega_n"], chosen["zeta"]) == (633.2, 0.5)
    assert chosen["omega_n"] <= edges[0.5] / MARGIN
    assert choose(rows)["omega_n"] == 1063.5  # without the margin: the tightest, on the edge
    assert choose([_row(16.8, 1.0, "ok", 0.1), _row(28.2, 1.0, "diverged")],
                  {1.0: 28.2}) is None  # nothing far enough below


def test_the_tuning_figure_has_no_overlapping_tick_labels():
    from vjm_ros.studies.sweep.tune import choose, pareto_front, tuning_figure

    rng = np.random.default_rng(1)
    # costs within one decade (where the default log ticks crowd), then over several
    for low, high in ((0.021, 0.034), (0.002, 3.0)):
        rows = [{"omega_n": float(w), "zeta": 1.0, "status": "ok",
                 "max_closure_error": float(10 ** rng.uniform(-7, -2)),
                 "wall_time": float(rng.uniform(low, high)), "duration": 1.0}
                for w in np.geomspace(10, 3000, 12)]
        _no_overlap(tuning_figure(rows, pareto_front(rows), choose(rows), "four_bar"))


def _no_overlap(fig) -> None:
    import matplotlib.pyplot as plt

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for axis in (fig.axes[0].xaxis, fig.axes[0].yaxis):
        boxes = [t.get_window_extent(renderer) for t in axis.get_ticklabels(which="both")
                 if t.get_visible() and t.get_text()]
        for i, a in enumerate(boxes):
            for b in boxes[i + 1:]:
                assert not a.overlaps(b), (axis.axis_name, a, b)
    plt.close(fig)


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_every_example_spec_is_valid_in_every_row(path):
    from vjm_ros.studies.sweep.plan import plan_sweep

    plan = plan_sweep(load_spec(path))
    assert plan.cases


def test_the_gains_example_varies_what_its_comment_says():
    from vjm_ros.studies.sweep.plan import plan_sweep

    path = ROOT / "examples" / "sweep_gains.yaml"
    comment = " ".join(path.read_text().split("\nname:")[0].replace("#", " ").split())
    assert "crank's mass varied on the four-bar" in comment
    cases = plan_sweep(load_spec(path)).cases
    masses = {s: {c.parameters.get("mass.crank") for c in cases if c.scene == s}
              for s in ("five_bar", "four_bar")}
    assert masses["four_bar"] == {1.0, 1.5} and masses["five_bar"] == {None}
    assert yaml.safe_load(path.read_text())["scenes"][0] == "five_bar"


def test_the_summary_names_every_count():
    from vjm_ros.studies.sweep.summary import summary_lines

    result = {"statuses": {"ok": 7, "diverged": 1, "error": 0}, "run": 6, "skipped": 2,
              "retried": 1, "dropped": 3, "same_as_another": 2, "wall_time": 12.34,
              "csv": "o/results.csv", "parquet": "o/results.parquet"}
    first, second = summary_lines(result)
    assert first == "8 rows in o/results.csv (and o/results.parquet): 7 ok, 1 diverged"
    assert second == ("6 run this time, 2 kept from before, 1 'error' rows run again, 3 rows no "
                      "longer in the spec dropped, 2 the same run as another row (filled from "
                      "it, see message); 12.3 s")


def test_the_bench_refuses_a_server_that_is_not_a_scheduler(http_server, tmp_path, capsys):
    from vjm_ros.studies.bench import main as bench_main

    code = bench_main(["--quick", "--no-mujoco", "--no-scaling", "--no-progress", "--out",
                       str(tmp_path / "bench"), "--cluster", http_server,
                       "--cluster-timeout", "0.5"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert f"--cluster {http_server}: expected a Dask scheduler to answer within 0.5 s" in err
    assert not (tmp_path / "bench").exists()


def test_exit_codes_say_whether_anything_could_run():
    from vjm_ros.studies.sweep.cli import exit_code

    done = {"interrupted": False, "run": 4, "errors": 0}
    assert exit_code(done) == 0
    assert exit_code({**done, "errors": 3}) == 0  # some rows ran: their errors are rows
    assert exit_code({**done, "errors": 4}) == 1  # nothing could run
    assert exit_code({**done, "run": 0}) == 0  # nothing left to run (resumed)
    assert exit_code({**done, "errors": 4, "interrupted": True}) == 130


def test_a_figure_of_unknown_measures_is_refused_before_any_cluster(tmp_path, capsys):
    line = refused(tmp_path, BASE, capsys, "--figure", "max_closure_error,speed")
    assert "--figure: expected two measures Y,X of status" not in line
    assert "--figure: expected two measures Y,X of diverged_at, max_closure_error" in line
    assert line.endswith("found 'max_closure_error,speed'")


@pytest.mark.parametrize("flags, message", [
    (["--integrator", "foo"], "--integrator: expected one of ['explicit_euler'"),
    (["--rate", "-5"], "--rate: expected a positive number of Hz, found -5.0"),
    (["--substeps", "0"], "--substeps: expected a whole number of steps per tick >= 1, found 0"),
    (["--duration", "-1"], "--duration: expected a positive number of simulated seconds"),
], ids=["integrator", "rate", "substeps", "duration"])
def test_tune_refuses_bad_flags_before_any_cluster(tmp_path, capsys, flags, message):
    out = tmp_path / "tune"
    code = sweep_cli.main("tune", ["four_bar", *flags, "--out", str(out), "--workers", "1"])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists(), err
    assert f"vjm tune: error: vjm tune four_bar: {message}" in err


@pytest.mark.parametrize("command", ["sweep", "tune"])
def test_a_malformed_address_on_the_command_line_exits_2_naming_it(command, tmp_path, capsys):
    """What ``Engine`` refuses (test_a_malformed_address_is_refused_with_a_message) reaches the
    user of either command as one line and exit code 2, with no table started."""
    out = tmp_path / "out"
    if command == "sweep":
        spec = tmp_path / "s.yaml"
        spec.write_text(BASE)
        target = [str(spec)]
    else:
        target = ["four_bar", "--duration", "0.1"]
    code = sweep_cli.main(command, [*target, "--out", str(out), "--cluster", "scheduler",
                                    "--cluster-timeout", "0.5", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert ("--cluster scheduler: expected a scheduler address such as tcp://host:8786, found "
            "a malformed address (missing port number") in err
    assert "Traceback" not in err and not out.exists()
