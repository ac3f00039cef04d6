"""Actuator dynamics (``gear``, ``time_constant``, ``delay``) against closed forms.

The oracle is a rod turning freely about its pivot (no gravity, no closure): its acceleration is
the applied effort over the pivot inertia ``J``. For a step command through a delay and a
first-order lag, the effort over each tick must be the closed-form lag's mean over that tick, so
the rate after each tick is the closed-form integral of the continuous lag over ``J`` (every
fixed-step method integrates a constant acceleration exactly in the rate); the angle is the sum
of the ticks' constant-acceleration steps, each method's own known map (:data:`POSITION_SHARE`).
"""

from __future__ import annotations

import numpy as np
import pytest

from vjm_ros.app import cli
from vjm_ros.core.errors import ConfigurationError, SceneError
from vjm_ros.scene.loader import parse_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator

J = 1.0 / 12.0 + 0.25  # pivot inertia of a 1 m, 1 kg uniform rod, kg m^2
RATE = 1000.0
DT = 1.0 / RATE
POSITION_SHARE = {"rk4": 0.5, "semi_implicit_euler": 1.0, "explicit_euler": 0.0}
"""Each method's step of the angle under a constant acceleration ``a`` from rate ``w``:
``w dt + share * a dt^2`` (rk4 exact; semi-implicit Euler uses the new rate, explicit the old)."""


def rod(actuator: str, extra: str = "") -> str:
    """A free rod on a revolute pivot, gravity off, with the given actuator entry."""
    return f"""\
name: rod
gravity: [0.0, 0.0]
chains:
  - name: arm
    links:
      - {{name: rod, length: 1.0, mass: 1.0, inertia: 0.0833333333333333333, com: [0.5, 0.0],
         joint: {{name: pivot, type: revolute, angle: 0.0}}}}
actuators:
  - {actuator}
defaults: {{integrator: rk4, rate: {RATE:g}, duration: 1}}
{extra}"""


def step_integrals(t, gain, lag, dead):
    """Effort, its integral and its double integral at ``t`` (s) of ``gain * (1 - exp(-s/lag))``
    for ``s = t - dead >= 0`` (0 before): the lag's response to a step that started ``dead``
    seconds late."""
    s = np.maximum(np.asarray(t, dtype=float) - dead, 0.0)
    if lag == 0:
        return gain * (s > 0), gain * s, gain * s * s / 2
    e = np.exp(-s / lag)
    return (gain * (1 - e), gain * (s - lag * (1 - e)),
            gain * (s * s / 2 - lag * s + lag * lag * (1 - e)))


def run(sim: Simulator, ticks: int, command: float):
    """States and applied efforts after each of ``ticks`` ticks of ``sim.advance``."""
    sim.set_efforts([command])
    rows = []
    for _ in range(ticks):
        sim.advance()
        s = sim.sample()
        rows.append((s.t, s.q[0], s.qd[0], s.effort[0]))
    return np.array(rows).T


@pytest.mark.parametrize("integrator", ["rk4", "semi_implicit_euler", "explicit_euler"])
@pytest.mark.parametrize("lag, delay", [(0.05, 0.003), (0.0, 0.004), (0.02, 0.0)])
def test_step_through_lag_and_delay_matches_the_closed_form(integrator, lag, delay):
    """A step command: the effort held over each tick is the mean of the closed-form lag over
    that tick, and the rod's rate and angle are its integrals, along a 1 s motion."""
    gear, command = 3.0, 2.0
    scene = parse_scene(rod(f"{{joint: pivot, limit: 20.0, gear: {gear}, "
                            f"time_constant: {lag}, delay: {delay}}}"))
    sim = Simulator(scene.model, SimulationSettings(integrator=integrator), scene.gains,
                    scene.plant)
    t, q, qd, effort = run(sim, 1000, command)
    _, w1, w2 = step_integrals(t, gear * command, lag, delay)
    _, w0, _ = step_integrals(t - DT, gear * command, lag, delay)
    # the tick's mean of the lag, and the rate its integral over J. Round-off: each of 1000
    # ticks adds a few ulp of the values (~1e-15 relative), well inside 1e-11.
    scale = gear * command
    mean = (w1 - w0) / DT
    np.testing.assert_allclose(effort, mean, rtol=0, atol=1e-11 * scale)
    np.testing.assert_allclose(qd, w1 / J, rtol=1e-11, atol=1e-13)
    rate_before = np.concatenate(([0.0], w1[:-1])) / J
    angle = np.cumsum(rate_before * DT + POSITION_SHARE[integrator] * mean / J * DT * DT)
    np.testing.assert_allclose(q, angle, rtol=1e-11, atol=1e-13)
    # held efforts move the rod as the continuous lag would, to O(dt) in the angle
    assert np.max(np.abs(q - w2 / J)) < 2 * scale / J * DT * 1.0
    # the dead time, to the tick: nothing before it, something from the tick after it on
    ticks = round(delay * RATE)
    assert np.all(effort[:ticks] == 0.0) and effort[ticks] > 0


def test_delay_without_lag_is_the_command_shifted_by_whole_ticks():
    scene = parse_scene(rod("{joint: pivot, limit: 20.0, gear: 2.5, delay: 0.005}"))
    sim = Simulator(scene.model, SimulationSettings(), scene.gains, scene.plant)
    _, _, _, effort = run(sim, 10, 4.0)
    assert effort.tolist() == [0.0] * 5 + [10.0] * 5


def test_gear_multiplies_the_command_and_the_limit_bounds_the_command():
    """``limit`` clamps the command (20), the joint gets gear times that (60); a gear alone adds
    no state: the efforts reach the joint at once, as without the key."""
    scene = parse_scene(rod("{joint: pivot, limit: 20.0, gear: 3.0}"))
    sim = Simulator(scene.model, SimulationSettings(), scene.gains, scene.plant)
    assert not sim.actuation.dynamic
    assert sim.set_efforts([30.0]).tolist() == [20.0]
    assert sim.tau.tolist() == [60.0]
    t, _, qd, effort = run(sim, 5, 30.0)
    assert effort.tolist() == [60.0] * 5
    np.testing.assert_allclose(qd, 60.0 * t / J, rtol=1e-13)


def test_lag_settles_exactly_and_blocks_equal_ticks():
    """``advance_block`` (one compiled call per tick until the lag has settled, then one call)
    gives the states and efforts of tick-by-tick ``advance`` to the bit, in blocks of many
    ticks as in ``vjm run`` and of one tick as in the node; a short lag reaches the command
    exactly within the run, so the last block runs as one call."""
    text = rod("{joint: pivot, limit: 20.0, gear: 2.0, time_constant: 0.002, delay: 0.002}")
    scene = parse_scene(text)
    settings = SimulationSettings(integrator="rk4")
    ticks = 300
    ref = Simulator(scene.model, settings, scene.gains, scene.plant)
    _, q_ref, qd_ref, e_ref = run(ref, ticks, 1.5)
    assert ref.actuation.settled(ref.efforts)  # exp(-t/T) * 3 below half an ulp of 3

    big = Simulator(scene.model, settings, scene.gains, scene.plant)
    big.set_efforts([1.5])
    block = SampleBlock(big.model, 100)
    q, e = [], []
    for _ in range(ticks // 100):
        big.advance_block(block, 100)
        q.append(block.q[:, 0].copy())
        e.append(block.effort[:, 0].copy())
    assert np.array_equal(np.concatenate(q), q_ref)
    assert np.array_equal(np.concatenate(e), e_ref)

    one = Simulator(scene.model, settings, scene.gains, scene.plant)
    one.set_efforts([1.5])
    block = SampleBlock(one.model, 1)
    rows = []
    for _ in range(ticks):
        one.advance_block(block, 1)
        rows.append((block.qd[0, 0], block.effort[0]))
    assert np.array_equal([r[0] for r in rows], qd_ref)
    assert np.array_equal([r[1] for r in rows], e_ref)


def test_reset_clears_the_actuator_state():
    scene = parse_scene(rod("{joint: pivot, limit: 20.0, time_constant: 0.01, delay: 0.001}"))
    sim = Simulator(scene.model, SimulationSettings(), scene.gains, scene.plant)
    first = run(sim, 50, 1.0)
    sim.reset()
    again = run(sim, 50, 1.0)
    assert np.array_equal(first, again)


@pytest.mark.parametrize("entry, key, expected", [
    ("gear: 0.0", "actuators[0].gear", "a number > 0"),
    ("gear: -2.0", "actuators[0].gear", "a number > 0"),
    ("time_constant: -0.1", "actuators[0].time_constant", "a number >= 0"),
    ("delay: -0.001", "actuators[0].delay", "a number >= 0"),
    ("delay: 0.0015", "actuators[0].delay", "a whole number of ticks at defaults.rate 1000 Hz"),
    ("gear: fast", "actuators[0].gear", "a number"),
    ("lag: 0.1", "actuators[0].lag", "one of the keys"),
])
def test_bad_actuator_keys_are_refused_naming_the_key(entry, key, expected):
    with pytest.raises(SceneError) as err:
        parse_scene(rod(f"{{joint: pivot, limit: 20.0, {entry}}}"), source="rod.yaml")
    assert err.value.key == key
    assert expected in str(err.value) and str(err.value).startswith("rod.yaml: ")


def test_a_delay_that_is_not_whole_ticks_at_the_run_rate_is_refused(tmp_path, capsys):
    """Whole ticks at the scene's rate, not at the one asked for: the simulator refuses it
    naming the file and key, and ``vjm run`` exits 2."""
    path = tmp_path / "rod.yaml"
    path.write_text(rod("{joint: pivot, limit: 20.0, delay: 0.003}"))
    scene = parse_scene(path.read_text(), source=str(path))
    with pytest.raises(ConfigurationError, match=r"rod\.yaml: actuators\[0\]\.delay: expected "
                       r"a whole number of ticks of 0\.004 s \(rate 250 Hz\), found 0\.003 s"):
        Simulator(scene.model, SimulationSettings(rate=250.0), scene.gains, scene.plant)
    Simulator(scene.model, SimulationSettings(rate=2000.0), scene.gains, scene.plant)
    assert cli.main(["run", str(path), "--rate", "250", "--duration", "0.01"]) == 2
    assert "actuators[0].delay" in capsys.readouterr().err


def test_the_csv_reports_the_applied_effort(tmp_path):
    """``vjm run --out``: ``effort.<joint>`` is the effort applied over the tick that ended at
    the row (zero during the dead time, then the lag's tick means)."""
    path = tmp_path / "rod.yaml"
    path.write_text(rod("{joint: pivot, limit: 20.0, effort: 2.0, gear: 3.0, "
                        "time_constant: 0.05, delay: 0.003}"))
    assert cli.main(["run", str(path), "--duration", "0.2", "--out", str(tmp_path / "out")]) == 0
    table = np.genfromtxt(tmp_path / "out" / "trajectory.csv", delimiter=",", names=True)
    t, effort = table["t"], table["effortpivot"]
    _, w1, _ = step_integrals(t, 6.0, 0.05, 0.003)
    _, w0, _ = step_integrals(t - DT, 6.0, 0.05, 0.003)
    expected = np.where(t > 0, (w1 - w0) / DT, 0.0)
    np.testing.assert_allclose(effort, expected, rtol=0, atol=1e-11 * 6.0)


def test_a_lag_reaches_a_held_command_exactly_also_at_zero():
    """Within about 36 time constants (2^-52 of the range) the lag state is the command itself,
    towards a command of 0 too (where rounding alone would take ~750 time constants), so that
    the ticks after it run as one block; until then, applied efforts follow the closed form."""
    lag = 0.002  # 2 ticks
    scene = parse_scene(rod(f"{{joint: pivot, limit: 20.0, gear: 3.0, time_constant: {lag}}}"))
    sim = Simulator(scene.model, SimulationSettings(), scene.gains, scene.plant)
    run(sim, 200, 2.0)
    assert sim.actuation.settled(sim.efforts) and sim.tau[0] == 6.0
    _, _, _, effort = run(sim, 200, 0.0)
    assert sim.actuation.settled(sim.efforts) and effort[-1] == 0.0
    ticks = np.arange(1, 201)
    mean = 6.0 * lag / DT * (np.exp(-(ticks - 1) * DT / lag) - np.exp(-ticks * DT / lag))
    np.testing.assert_allclose(effort, mean, rtol=0, atol=1e-12 * 6.0)
    settled_at = int(np.argmax(effort == 0.0))
    assert 30 * lag / DT < settled_at < 40 * lag / DT
