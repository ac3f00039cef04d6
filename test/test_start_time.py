"""The start-time study (studies.start_time) runs end to end; its figures are benchmarks, not
asserted here."""

from __future__ import annotations

import math

import pytest

from vjm_ros.studies import start_time

STAGES = ["import", "numba", "registries", "scene", "kernel", "simulator", "pipeline",
          "first_tick"]


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


def test_start_time_measures_warm_and_cold_runs_with_their_stages():
    row = start_time.measure("four_bar", repeats=1, cold_repeats=1)
    assert len(row["warm_runs_s"]) == 1 and len(row["cold_runs_s"]) == 1
    for key in ("floor_s", "warm_s", "cold_s"):
        assert math.isfinite(row[key]) and row[key] > 0, key
    for key in ("warm_stages_s", "cold_stages_s"):
        assert list(row[key]) == STAGES, key
        assert all(math.isfinite(v) and v >= 0 for v in row[key].values()), row[key]
    assert row["warm_imports_s"] and all(v > 0 for v in row["warm_imports_s"].values())
