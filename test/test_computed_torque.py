"""The computed-torque example controller, through ROS 2 as users run it, and its paths.

Lockstep at 1 kHz with exact closure (each tick waits for the controller's command, so the
result does not depend on the machine's speed): after the approach the five-bar's pin stays on
its circle within the issue's target of 0.02 mm RMS (measured 0.0022 mm; the bound leaves a
factor of nine for other machines' floating point and scheduling). The error is measured from
the simulator's own log, read with rosbags, against the path function.
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 101))

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from vjm_ros.control.paths import Circle, FigureEight  # noqa: E402
from vjm_ros.studies.tracking import run_case  # noqa: E402


@pytest.mark.parametrize("path", [Circle((0.7, 0.4), 0.05, 2.0, 1.0),
                                  FigureEight((3.4, 1.2), 0.2, 4.0, 1.0)])
def test_paths_start_at_rest_and_their_derivatives_agree(path):
    x0, v0, a0 = path.at(0.0)
    np.testing.assert_allclose(x0, path.start, atol=1e-15)
    np.testing.assert_allclose(v0, 0.0, atol=1e-15)
    h = 1e-5  # central differences: error ~h^2 |x'''| ~1e-9
    for t in (0.3, 0.999, 1.0, 1.7, 3.2):
        x, v, a = path.at(t)
        np.testing.assert_allclose((path.at(t + h)[0] - path.at(t - h)[0]) / (2 * h), v,
                                   atol=1e-7)
        np.testing.assert_allclose((path.at(t + h)[1] - path.at(t - h)[1]) / (2 * h), a,
                                   atol=1e-5)


@pytest.mark.ros
def test_five_bar_tracks_its_circle_in_lockstep():
    r = run_case("five_bar_circle", "lockstep", duration=2.5, settle=1.5,
                 domain=int(os.environ["ROS_DOMAIN_ID"]))
    assert r.states == 2501
    assert r.rms_mm < 0.02, r


@pytest.mark.ros
@pytest.mark.slow  # two node + controller pairs of 4 s in lockstep
def test_friction_compensation_tracks_the_circle_better_than_the_ideal_model():
    """five_bar_friction: the computed-torque controller on the ideal model lags where the
    joints' Coulomb friction holds them; with ``compensate_plant`` its model adds the friction
    and damping. Measured for docs/controllers.md: RMS 6.57 mm ideal, 0.36 mm compensated; the
    bound asks for a fivefold gain, well inside that eighteenfold."""
    domain = int(os.environ["ROS_DOMAIN_ID"])
    ideal = run_case("five_bar_friction_circle", "lockstep", domain=domain)
    compensated = run_case("five_bar_friction_circle_compensated", "lockstep", domain=domain)
    assert ideal.states == compensated.states == 4001
    assert compensated.rms_mm < ideal.rms_mm / 5, (ideal, compensated)
