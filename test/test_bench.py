"""``vjm bench`` on a tiny grid: outputs, row states, fronts and tiers, the MuJoCo translation."""

import json
import math

import numpy as np
import pytest

from vjm_ros.scene.generated import chain_scene, star_scene
from vjm_ros.scene.loader import load_scene
from vjm_ros.studies import compare_mujoco
from vjm_ros.studies.bench.analysis import pareto_front, recommend
from vjm_ros.studies.bench.cli import main
from vjm_ros.studies.bench.grid import (
    EXACT,
    REFUSED,
    THESIS,
    TIERS,
    BenchOptions,
    ClosureVariant,
    Grid,
    full_grid,
)
from vjm_ros.studies.bench.runs import RowResult, compute_reference
from vjm_ros.studies.bench.study import horizon_for, run_bench


def test_quick_cli_on_a_tiny_horizon(tmp_path):
    """The CLI path end to end: report, results, one Pareto PNG per scene, docs and figures."""
    out, docs = tmp_path / "out", tmp_path / "docs" / "accuracy.md"
    code = main(["four_bar", "--quick", "--horizon", "0.02", "--repeats", "2", "--no-scaling",
                 "--no-progress", "--out", str(out), "--docs", str(docs)])
    assert code == 0
    results = json.loads((out / "results.json").read_text())
    rows = results["scenes"]["four_bar"]["rows"]
    vjm_rows = [r for r in rows if r["engine"] == "vjm"]
    assert len(vjm_rows) == 4 * 3 * 4 + 3  # integrators x steps x closures + adaptive
    states = {r["status"] for r in vjm_rows}
    assert "ok" in states and "refused (stiffness)" in states
    for r in rows:
        if r["status"] == "ok":
            assert r["wall_per_sim_s"] > 0 and len(r["wall_samples"]) == 2
            assert r["position_deviation"] is not None and r["position_deviation"] >= r["tip_deviation"]
        else:
            assert r["message"]
    report = (out / "report.md").read_text()
    assert "refused (stiffness)" in report and "## four_bar" in report
    assert (out / "four_bar_pareto.png").stat().st_size > 10_000
    assert (docs.parent / "figures" / "four_bar_pareto.png").exists()
    text = docs.read_text()
    assert "## Recommended settings" in text and "figures/four_bar_pareto.png" in text
    assert set(results["recommended"]) == {t for t, _ in TIERS}
    again, docs2 = tmp_path / "again", tmp_path / "docs2" / "accuracy.md"
    assert main(["--from-results", str(out / "results.json"), "--out", str(again), "--docs",
                 str(docs2)]) == 0
    assert (again / "four_bar_pareto.png").exists() and "## four_bar" in docs2.read_text()
    # a refresh replaces the generated sections and keeps the ones written by hand
    docs2.write_text(docs2.read_text().replace("## four_bar", "## four_bar\nstale line")
                     + "\n## Live node\n\nmeasured by hand\n")
    assert main(["--from-results", str(out / "results.json"), "--out", str(again), "--docs",
                 str(docs2)]) == 0
    refreshed = docs2.read_text()
    assert "stale line" not in refreshed and refreshed.count("## four_bar") == 1
    assert refreshed.rstrip().endswith("## Live node\n\nmeasured by hand")


def test_diverged_rows_are_kept(tmp_path, monkeypatch):
    """With the stiffness check off, a too-stiff row is a 'diverged' row with the guard's message."""
    monkeypatch.setattr(compare_mujoco, "import_mujoco", lambda: None)
    stiff = ClosureVariant("penalty Kp=1e8", "penalty", kp=1e8, kv=0.0)
    grid = Grid(("explicit_euler", "rk4"), ((1000.0, 1),), (stiff, EXACT), (), (), (2,), (2,), 2)
    opts = BenchOptions(["four_bar"], out=tmp_path, repeats=1, horizon=0.05, grid=grid,
                        extra={"check_stiffness": False}, progress=False)
    results = run_bench(opts)
    rows = {(r["integrator"], r["closure"]): r for r in results["scenes"]["four_bar"]["rows"]}
    bad = rows[("explicit_euler", "penalty Kp=1e8")]
    assert bad["status"] == "diverged" and 0 < bad["diverged_at"] < 0.05
    assert "tip_pin" in bad["message"] and "Likely cause" in bad["message"]
    assert rows[("rk4", "exact")]["status"] == "ok"
    assert results["meta"]["mujoco"]["skipped"]
    assert all(r["engine"] == "vjm" for r in rows.values())
    assert results["scaling"]["links"]["table"][0]["n"] == 2
    assert "diverged at t = " in (tmp_path / "report.md").read_text()


def _row(cost, dev, rate=1000.0, step=1e-3, label="x"):
    r = RowResult("s", "vjm", "rk4", rate, 1, step, "exact", label, label, {})
    r.wall_per_sim_s, r.realtime_factor, r.position_deviation = cost, 1 / cost, dev
    r.tip_deviation = r.max_closure_error = r.energy_drift = dev
    return r


def test_pareto_front_and_tiers():
    rows = [_row(0.1, 1e-2, label="a"), _row(0.2, 1e-2, label="b"), _row(0.3, 1e-4, label="c"),
            _row(0.4, 1e-7, rate=250.0, step=4e-3, label="d"), _row(2.0, 1e-10, label="e")]
    rows.append(_row(0.05, 1.0, label="f"))
    rows[1].status = REFUSED
    assert [r.label for r in pareto_front(rows)] == ["f", "a", "c", "d", "e"]
    rec = recommend(rows)
    assert rec["live 1 kHz"]["label"] == "c"  # most accurate at 1 kHz with RTF >= 2
    assert rec["1e-3 m"]["label"] == "c" and rec["1e-6 m"]["label"] == "d"
    assert rec["1e-9 m"]["label"] == "e"


def test_generated_scenes():
    scene = chain_scene(5)
    assert scene.model.n == 5 and scene.model.n_rows == 1
    star = star_scene(4)
    assert star.model.n == 8 and star.model.n_rows == 6 and star.assembly_residual < 1e-10


def test_grids_cover_the_issue():
    full = full_grid()
    assert THESIS in full.closures and EXACT in full.closures
    assert any(c.projection for c in full.closures)
    assert any(c.omega_n for c in full.closures) and any(c.kp for c in full.closures)
    assert {"Euler", "implicitfast", "RK4"} == {m[0] for m in full.mujoco}
    assert all(math.isclose(1000.0 / r % 1, 0) for r, _ in full.steps)
    assert horizon_for("five_bar", False) <= 1.0
    assert horizon_for("three_chain", False) <= 1.0


def test_mujoco_requirement_excludes_4_0_0():
    req = compare_mujoco.MUJOCO_REQUIREMENT
    assert "!=4.0.0" in req
    assert compare_mujoco.version_note("4.0.0") and compare_mujoco.version_note("3.17.0") is None


def test_mujoco_model_matches_the_reference():
    """Same geometry, masses and gravity: stiff MuJoCo RK4 at 0.25 ms follows vjm's reference."""
    pytest.importorskip("mujoco")
    for name in ("four_bar", "five_bar"):
        scene = load_scene(name)
        ref = compute_reference(scene, 0.2, check=False)
        settings = compare_mujoco.MujocoSettings(
            integrator="RK4", substeps=4, solref=(-1e7, -2e3), solimp=(0.9999, 0.9999, 0.001, 0.5, 2))
        with compare_mujoco.MujocoSimulator(scene.model, settings) as sim:
            sim.refresh()
            np.testing.assert_allclose(sim.link_ends(), ref.ends[0], atol=1e-12)
            for _ in range(200):
                sim.advance()
            sim.refresh()
            assert np.max(np.linalg.norm(sim.link_ends() - ref.ends[200], axis=1)) < 1e-6
            assert np.max(np.linalg.norm(sim.points() - ref.points[200], axis=1)) < 1e-6
            assert sim.closure_errors().max() < 1e-6
