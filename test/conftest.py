"""Test-wide set-up: keep DDS discovery on this host and give each pytest process its own domain.

Set before anything imports rclpy (rclpy reads them when it starts): ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` keeps
discovery traffic on loopback; one ``ROS_DOMAIN_ID`` per process (1-101) keeps parallel runs on
one machine from seeing each other's messages. ``VJM_TIERED=0``: see below.
"""

import os

import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + (os.getpid() % 101)))
os.environ.setdefault(
    "ROS_LOG_DIR", os.path.join(os.environ.get("TMPDIR", "/tmp"), "vjm_ros_test_logs")
)
os.environ.setdefault("MPLBACKEND", "Agg")
# Compiled code from the first call, in this process and in those it starts: the suite asserts
# what the compiled kernels do (call counts, timings of studies); test/test_tiers.py tests the
# plain-Python tier of a first run on its own.
os.environ["VJM_TIERED"] = "0"

FIXED_STEP_SETTINGS = [
    {"integrator": "rk4", "closure": "exact"},
    {"integrator": "rk4", "closure": "exact", "projection": True},
    {"integrator": "semi_implicit_euler", "closure": "penalty"},
    {"integrator": "implicit_euler", "closure": "penalty", "substeps": 2},
    {"integrator": "implicit_euler", "closure": "exact"},
    {"integrator": "explicit_euler", "closure": "exact", "substeps": 4},
]
"""Every branch of the compiled tick: each fixed-step method, penalty and exact closure,
projection, substeps (the block and plain-Python tests run each)."""


def four_bar_samples(ticks):
    """Run the built-in four-bar with exact closure for ``ticks`` ticks.

    Returns ``(scene, simulator, samples)``, one sample per tick; shared by the log tests.
    """
    from vjm_ros.scene.loader import load_scene
    from vjm_ros.sim.simulator import SimulationSettings, Simulator

    scene = load_scene("four_bar")
    sim = Simulator(scene.model, SimulationSettings(closure="exact"), scene.gains)
    samples = []
    for _ in range(ticks):
        sim.advance()
        samples.append(sim.sample())
    return scene, sim, samples


@pytest.fixture(scope="session")
def reset_run(tmp_path_factory):
    """One live ``vjm_sim_node`` run reset half-way (:func:`reset_run.run_with_reset`), shared by
    the tests that only read it: test_node_duration.py (``duration`` across the reset) and
    test_log_reset_event.py (the reset event in the node's MCAP log).

    100 Hz ticks (two substeps keep the thesis gains inside rk4's bound) for ``duration`` s of
    simulated time, recording an MCAP; the reset comes once ``/clock`` has passed
    ``reset_after`` s. Returns ``(probe, returncode, out, mcap, rate, duration, reset_after)``.
    """
    from reset_run import run_with_reset

    rate, duration, reset_after = 100.0, 2.0, 1.0
    mcap = tmp_path_factory.mktemp("reset_run") / "run.mcap"
    probe, returncode, out = run_with_reset(
        [f"rate_hz:={rate}", "substeps:=2", f"duration:={duration}", f"mcap:={mcap}"],
        reset_after, "reset_probe")
    return probe, returncode, out, mcap, rate, duration, reset_after
