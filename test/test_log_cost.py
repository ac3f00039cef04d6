"""The log-cost study: its runs and its page section (no speed is asserted)."""

from __future__ import annotations

from benchmarks import log_cost
from benchmarks.log_cost import LOG_COST_HEADING
from vjm_ros.studies.pages import section, with_section

PAGE = "# Title\n\nintro\n\n## First\n\none\n\n## Last\n\ntwo\n"


def test_section_is_replaced_in_place_or_appended():
    assert section(PAGE, "## First") == "## First\n\none\n\n"
    assert section(PAGE, "## Missing") is None
    replaced = with_section(PAGE, "## First", "## First\n\nnew")
    assert replaced == "# Title\n\nintro\n\n## First\n\nnew\n\n## Last\n\ntwo\n"
    assert with_section(PAGE, "## Last", "## Last\n\nnew\n") == PAGE.replace("two", "new")
    assert with_section(PAGE, "## Added", "## Added\n\nx") == PAGE + "\n## Added\n\nx\n"
    assert with_section("", "## Added", "## Added\n\nx") == "## Added\n\nx\n"  # a new page


def test_measure_runs_every_configuration_and_renders_its_section(tmp_path):
    r = log_cost.measure("four_bar", seconds=0.05, rounds=1)
    assert set(r["ratio"]) == set(log_cost.CONFIGS) and r["ratio"]["physics"] == 1.0
    assert all(v > 0 for v in r["ms_per_sim_s"].values())
    text = log_cost.render_section(r)
    assert text.startswith(LOG_COST_HEADING + "\n")
    assert f"| `--out --mcap --rrd` | {r['ms_per_sim_s']['all']:.3g} |" in text
    assert ("target 1.5x met" in text) == (r["ratio"]["all"] <= 1.5)
