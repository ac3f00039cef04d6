"""The kernel-cost study (benchmarks.kernel_cost) runs end to end; its figures are benchmarks, not
asserted here beyond being positive and finite."""

from __future__ import annotations

import json
import math

import pytest

from benchmarks import kernel_cost

pytest.importorskip("numba")


def test_the_study_times_each_scene_and_closure_method(capsys):
    assert kernel_cost.main(["--scenes", "four_bar", "--steps", "50", "--repeats", "2",
                             "--json"]) == 0
    rows = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert sorted(rows) == ["four_bar exact", "four_bar penalty"]
    assert all(math.isfinite(v) and v > 0 for v in rows.values())
