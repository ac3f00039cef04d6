"""The start-time study (benchmarks.start_time) runs end to end; its figures are benchmarks, not
asserted here."""

from __future__ import annotations

import math

import pytest

from benchmarks import start_time

STAGES = ["import", "scene", "kernel", "simulator", "first_tick", "numba", "compiled"]


def test_import_times_sum_self_times_per_top_level_package():
    stderr = "\n".join([
        "import time: self [us] | cumulative | imported package",
        "import time:       100 |        100 |     numpy._core._multiarray_umath",
        "import time:        50 |        150 |   numpy._core",
        "import time:      2000 |       2150 | numpy",
        "import time:         7 |          7 | vjm_ros",
        "a line from something else",
    ])
    times = start_time.import_times(stderr)
    assert list(times) == ["numpy", "vjm_ros"]  # largest first
    assert times["numpy"] == pytest.approx(2150e-6, rel=1e-12)  # sums of microseconds
    assert times["vjm_ros"] == pytest.approx(7e-6, rel=1e-12)


@pytest.mark.slow  # two compiles from an empty numba cache: 25-50 s on this machine
def test_start_time_measures_warm_and_cold_runs_with_their_stages():
    row = start_time.measure("four_bar", repeats=1, cold_repeats=1)
    assert len(row["warm_runs_s"]) == 1 and len(row["cold_runs_s"]) == 1
    for key in ("floor_s", "warm_s", "cold_s", "warm_cpu_s", "cold_cpu_s",
                "cold_compiled_first_s", "cold_compiled_first_cpu_s"):
        assert math.isfinite(row[key]) and row[key] > 0, key
    for key in ("warm_stages_s", "cold_stages_s"):
        assert list(row[key]) == STAGES, key
        assert all(math.isfinite(v) and v >= 0 for v in row[key].values()), row[key]
    # warm, the compiled code is loaded at the call after the first tick; cold, it takes over
    # later
    assert row["warm_plain_ticks"] == 0 < row["cold_plain_ticks"]
    assert row["warm_imports_s"] and all(v > 0 for v in row["warm_imports_s"].values())


def test_the_section_replaces_its_old_self(tmp_path):
    page = tmp_path / "accuracy.md"
    page.write_text("# Accuracy and speed\n\n## Findings\n\nx\n")
    start_time.write_section(page, "## Start time\n\nfirst\n")
    assert page.read_text() == "# Accuracy and speed\n\n## Findings\n\nx\n\n## Start time\n\nfirst\n"
    page.write_text(page.read_text() + "\n## Later\n\ny\n")
    start_time.write_section(page, "## Start time\n\nsecond\n")
    assert page.read_text() == ("# Accuracy and speed\n\n## Findings\n\nx\n\n## Start time\n\n"
                                "second\n\n## Later\n\ny\n")


def test_the_section_shows_the_measured_figures():
    row = {"scene": "four_bar", "floor_s": 0.02, "warm_s": 0.456, "cold_s": 7.891,
           "warm_cpu_s": 0.4, "cold_cpu_s": 7.0,
           "warm_runs_s": [0.456] * 3, "cold_runs_s": [7.891],
           "warm_stages_s": dict.fromkeys(STAGES, 0.01),
           "cold_stages_s": dict.fromkeys(STAGES, 0.02), "warm_imports_s": {"numba": 0.2},
           "load_1min": 1.0}
    text = start_time.render_section(row, "2026-01-01T00:00:00+00:00")
    assert text.startswith(start_time.HEADING + "\n")
    assert "| warm | 0.46 | 0.40 | 0.5 |" in text and "| cold | 7.89 | 7.00 | 3 |" in text
    assert "| stage | " + " | ".join(STAGES) + " |" in text
    assert "numba 0.200" in text


def test_a_warm_start_loads_the_compiled_code_without_numbas_compiler_tables(tmp_path):
    """Loading compiled functions from numba's cache skips the refresh of numba's typing and
    lowering tables (``vjm_ros.jit``): a fresh process that runs a tick from a filled cache has not
    imported the modules that refresh installs, and gives the same numbers as the process that
    compiled them. The first process fills the cache where it is cold (CI's fresh clone)."""
    import json
    import os
    import subprocess
    import sys

    script = (
        "import json, sys\n"
        "import numpy as np\n"
        "from vjm_ros.scene.loader import load_scene\n"
        "from vjm_ros.sim.settings import resolve_settings\n"
        "from vjm_ros.sim.simulator import Simulator\n"
        "sc = load_scene('four_bar')\n"
        "sim = Simulator(sc.model, resolve_settings(sc.defaults, sc.gains), sc.gains)\n"
        "for _ in range(5):\n"
        "    sim.advance()\n"
        "print(json.dumps({'q': [float(v).hex() for v in sim.q],\n"
        "                  'tables': 'numba.np.arrayobj' in sys.modules}))\n")
    runs = []
    for _ in range(2):
        # VJM_TIERED=0: the kernel is loaded (or compiled) at its first call, not left to plain
        # Python for a few ticks
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                              timeout=600, env={**os.environ, "VJM_TIERED": "0"})
        assert done.returncode == 0, done.stderr[-2000:]
        runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    assert runs[1]["tables"] is False  # the second process only loaded from the cache
    assert runs[1]["q"] == runs[0]["q"]  # bit for bit
