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
    from rosbags_cdr import serialize

    from vjm_ros.logs import cdr, messages

    scene, _, samples = run
    s, ns = samples[-1], 1_234_567_890
    names = scene.model.joint_names
    if kind == "joint_state":
        fast = cdr.joint_state_layout(names).encode
        args, slow = (ns, s.q, s.qd, s.effort), (messages.JOINT_STATE,
                                                  messages.joint_state(names, s, ns))
    elif kind == "markers":
        value = messages.markers(s, ns)
        fast, args, slow = cdr.encode_markers, (value,), (messages.MARKER_ARRAY, value)
    else:
        fast = cdr.wrench_stamped_layout().encode
        args, slow = (ns, s.closure_force[0, :2], s.closure_force[0, 2:]), (messages.WRENCH_STAMPED,
                                                 messages.wrench(s, 0, ns))
    if path == "fast_path":
        benchmark(fast, *args)
    else:
        benchmark(serialize, *slow)


def mcap_recording_memory(seconds: float, path, scene_name: str = "five_bar") -> dict:
    """Record ``seconds`` of a scene at 1 kHz into an MCAP file; resident memory as it grows.

    Returns the RSS (MB) sampled every simulated minute, the peak RSS, the messages written and
    the file's size.
    """
    import resource

    from vjm_ros.logs.mcap_recorder import McapRecorder
    from vjm_ros.scene import load_scene
    from vjm_ros.sim.simulator import SimulationSettings, Simulator

    def rss_mb():
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
        return float("nan")

    scene = load_scene(scene_name)
    sim = Simulator(scene.model, SimulationSettings(closure="exact"), scene.gains)
    ticks_per_minute = int(60 * sim.settings.rate)
    series = []
    with McapRecorder(path, scene.model, sim.describe(), scene.text) as rec:
        rec.write(sim.sample())
        for k in range(int(seconds * sim.settings.rate)):
            sim.advance()
            rec.write(sim.sample())
            if (k + 1) % ticks_per_minute == 0:
                series.append(rss_mb())
        count = rec.message_count
    return {
        "seconds": seconds,
        "rss_mb_per_minute": series,
        "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "messages": count,
        "file_mb": path.stat().st_size / 2**20,
    }


def test_mcap_recording_memory_stays_bounded(tmp_path):
    """Target: a 1 h recording at 1 kHz grows the process by less than 64 MB.

    Runs ``VJM_BENCH_RECORD_SECONDS`` (default 600) simulated seconds and extrapolates the growth
    after the first minute linearly to an hour (the writer's index grows by one entry per chunk;
    everything else is bounded).
    """
    import os

    seconds = float(os.environ.get("VJM_BENCH_RECORD_SECONDS", "600"))
    r = mcap_recording_memory(seconds, tmp_path / "hour.mcap")
    series = r["rss_mb_per_minute"]
    per_hour = (series[-1] - series[0]) / max(len(series) - 1, 1) * 60 if len(series) > 1 else 0
    print(f"MCAP recording, {seconds:g} s of five_bar at 1 kHz: RSS per minute {series}, "
          f"{per_hour:.1f} MB per hour after the first minute, file {r['file_mb']:.0f} MB, "
          f"{r['messages']} messages")
    assert per_hour < 64.0
