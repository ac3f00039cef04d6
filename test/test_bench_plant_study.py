"""``vjm bench --plant``: the friction and hard-stop study runs every row and renders its
section (speed is not asserted; the errors are, against the study's own fine reference)."""

from __future__ import annotations

import math

from vjm_ros.studies.bench import plant
from vjm_ros.studies.pages import section, with_section


def test_rows_converge_to_the_reference_and_render(monkeypatch):
    monkeypatch.setattr(plant, "GRID", {"integrators": ("semi_implicit_euler",),
                                        "substeps": (1, 4), "closures": ("exact",)})
    monkeypatch.setattr(plant, "CASES", {
        "rod": (lambda: plant.ROD_ON_STOP, 0.8)})
    rows = plant.measure(repeats=1)
    assert [(r["integrator"], r["substeps"]) for r in rows] == [
        ("semi_implicit_euler", 1), ("semi_implicit_euler", 4)]
    assert all(r["status"] == "ok" and math.isfinite(r["us_per_sim_s"]) for r in rows)
    # first order through the impacts: 4 substeps cut the error about 4x (measured 4.0)
    assert 2.5 < rows[0]["error"] / rows[1]["error"] < 6.0
    text = plant.render(rows)
    assert text.startswith(plant.HEADING + "\n")
    page = with_section("# Accuracy\n", plant.HEADING, text)
    assert section(page, plant.HEADING).startswith(plant.HEADING)
    assert "semi_implicit_euler 4" in text or "semi_implicit_euler 3" in text
