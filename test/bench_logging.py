"""Cost of logging one 1 kHz tick of the four-bar to rerun, against its target.

Run with ``python -m pytest -m bench test/bench_logging.py --benchmark-enable -p no:cacheprovider``
(benchmarks are outside the default suite; without ``--benchmark-enable`` each case runs once as
a smoke test). Target: the mean cost per tick stays below 10 % of the tick (100 us), for writing
a file tick by tick and with viewer batching. Absolute figures vary 2-4x between runs on a shared
machine; compare the two cases within one run.
"""

from __future__ import annotations

import pytest
from conftest import four_bar_samples

from vjm_ros.logs.rerun_recorder import RerunRecorder

pytestmark = pytest.mark.bench

TICKS = 400
TARGET_PER_TICK = 100e-6  # s: a tenth of a 1 kHz tick


@pytest.fixture(scope="module")
def run():
    return four_bar_samples(TICKS)


@pytest.mark.parametrize("batch", [None, 100], ids=["per_tick", "batch_100"])
def test_rerun_logging_cost_per_tick(benchmark, run, tmp_path, batch):
    scene, sim, samples = run
    paths = iter(tmp_path / f"cost_{i}.rrd" for i in range(10_000))

    def log_all():
        rec = RerunRecorder(next(paths), scene.model, sim.describe(), batch=batch,
                            batch_seconds=1e9)
        for s in samples:
            rec.write(s)
        rec.close()

    benchmark.pedantic(log_all, rounds=3, iterations=1)
    if benchmark.enabled:
        per_tick = benchmark.stats.stats.mean / len(samples)
        benchmark.extra_info["per_tick_us"] = per_tick * 1e6
        print(f"rerun logging, batch={batch}: {per_tick * 1e6:.1f} us per tick")
        assert per_tick < TARGET_PER_TICK


@pytest.mark.parametrize("path", ["fast_path", "rosbags_from_dict"])
@pytest.mark.parametrize("kind", ["joint_state", "wrench_stamped", "markers"])
def test_per_tick_encoding_cost(benchmark, run, path, kind):
    """A per-tick message: the fixed-layout fast path against rosbags' serializer from the dict.

    The fast paths stay only while they are measurably faster (test_cdr_rosbags.py checks that
    they write the same bytes).
    """
    from vjm_ros.logs import cdr, messages

    scene, _, samples = run
    s, ns = samples[-1], 1_234_567_890
    names = scene.model.joint_names
    if kind == "joint_state":
        fast = cdr.joint_state_encoder(names)
        args, slow = (ns, s.q, s.qd, s.effort), (messages.JOINT_STATE,
                                                  messages.joint_state(names, s, ns))
    elif kind == "markers":
        value = messages.markers(s, ns)
        fast, args, slow = cdr.encode_markers, (value,), (messages.MARKER_ARRAY, value)
    else:
        fast = cdr.wrench_stamped_encoder()
        args, slow = (ns, *s.closure_force[0]), (messages.WRENCH_STAMPED,
                                                 messages.wrench(s, 0, ns))
    if path == "fast_path":
        benchmark(fast, *args)
    else:
        benchmark(cdr.encode, *slow)
