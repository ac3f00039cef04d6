"""Speed of the sweep engine: a 200-run sweep on 1 and 2 local workers against a serial loop.

Run with ``python -m pytest -m bench test/bench_sweep.py -s -p no:cacheprovider``. Reports the
speed-up on two workers (target >= 1.8x the serial loop) and the engine's overhead per run
(target <= 20 ms: one worker's sweep against the serial loop, per run). Figures go to
docs/sweeps.md; compare them within one run (the machine is shared).
"""

from __future__ import annotations

import json
import time

import pytest

from vjm_ros.studies.sweep.engine import Engine, Sweep
from vjm_ros.studies.sweep.run import reference_for, run_case, scene_source
from vjm_ros.studies.sweep.spec import parse_spec

pytestmark = pytest.mark.bench

SPEC_200 = """
name: bench200
scenes: [five_bar, four_bar]
duration: 0.5
settings: {closure: penalty}
grid:
  integrator: [rk4, semi_implicit_euler]
  rate: [500, 1000]
  omega_n: [40, 60, 80, 100, 120]
  zeta: [0.6, 0.8, 1.0, 1.2, 1.5]
"""


def test_two_workers_against_a_serial_loop(tmp_path):
    spec = parse_spec(SPEC_200, "bench200.yaml")
    cases = spec.cases()
    assert len(cases) == 200
    texts = {s: scene_source(s) for s in spec.scenes}
    warm = {s: reference_for(*texts[s], "{}", 0.05, 1000.0) for s in spec.scenes}
    for c in cases[:4]:
        run_case(c, texts[c.scene], warm[c.scene])  # compile and cache before timing
    t0 = time.perf_counter()  # the same work as the sweep: one reference per scene, every run
    refs = {s: reference_for(*texts[s], "{}", 0.5, 1000.0) for s in spec.scenes}
    for c in cases:
        run_case(c, texts[c.scene], refs[c.scene])
    serial = time.perf_counter() - t0
    walls = {}
    for workers in (1, 2):
        with Engine(workers=workers) as engine:
            t0 = time.perf_counter()
            result = Sweep(spec, tmp_path / f"w{workers}").run(engine, progress=False)
            walls[workers] = time.perf_counter() - t0
        assert result["run"] == 200
    figures = {
        "runs": 200,
        "serial_s": round(serial, 2),
        "one_worker_s": round(walls[1], 2),
        "two_workers_s": round(walls[2], 2),
        "speedup_two_workers": round(serial / walls[2], 2),
        "overhead_per_run_ms": round((walls[1] - serial) / 200 * 1e3, 2),
    }
    print("sweep figures:", json.dumps(figures))
