"""The gains ``vjm tune`` chooses hold for the scene's whole duration (slow: a tuning sweep).

The documented example tunes five_bar's penalty gains for semi-implicit Euler at 1 kHz over runs
of 1 s. The row with the tightest closure of those runs sits on the stability edge: it diverges
before the scene's 10 s end. The chosen gains keep a margin from the edge and must run the
scene's full duration; the gains chosen without the margin must not (so the check can fail).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from vjm_ros.studies.sweep.table import RESULTS_CSV
from vjm_ros.studies.sweep.tune import choose, read_rows

ROOT = Path(__file__).resolve().parents[1]
HANG_GUARD = 900.0  # s: a hang guard, never a speed requirement


def _ticks(omega_n: float, zeta: float) -> int:
    """Ticks five_bar runs over its 10 s with these gains (10000: it did not diverge)."""
    done = subprocess.run(
        [sys.executable, "-m", "vjm_ros.app.cli", "run", "five_bar", "--integrator",
         "semi_implicit_euler", "--rate", "1000", "--closure", "penalty", "--omega-n",
         f"{omega_n}", "--zeta", f"{zeta}", "--json"],
        cwd=ROOT, capture_output=True, text=True, timeout=HANG_GUARD)
    return json.loads(done.stdout.strip().splitlines()[-1])["ticks"]


@pytest.mark.slow
def test_the_documented_tuning_holds_for_the_scene_duration(tmp_path):
    out = tmp_path / "tune"
    done = subprocess.run(
        [sys.executable, "-m", "vjm_ros.app.cli", "tune", "five_bar", "--integrator",
         "semi_implicit_euler", "--rate", "1000", "--duration", "1", "--workers", "2",
         "--no-progress", "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=HANG_GUARD)
    assert done.returncode == 0, done.stderr
    chosen = json.loads(done.stdout.strip().splitlines()[-1])["chosen"]
    assert _ticks(chosen["omega_n"], chosen["zeta"]) == 10_000
    edge_row = choose(read_rows(out / RESULTS_CSV))  # the tightest of 1 s, no margin
    assert _ticks(edge_row["omega_n"], edge_row["zeta"]) < 10_000
