"""The closed-chain model refuses arguments it cannot use, naming them.

Each refusal is a ``ValueError`` (:class:`ConfigurationError`) or, for something that is not a
number at all, a ``TypeError`` (:class:`ArgumentTypeError`, also a ``ConfigurationError`` so
that ``vjm model`` exits with 2), whose message names the argument, what was expected and what
was found. Both paths of ``inverse_dynamics`` are exercised: joint accelerations (``udd``, the
compiled path) and a point's acceleration (``point``, ``xdd``, numpy).
"""

from __future__ import annotations

import numpy as np
import pytest

from vjm_ros.control import ArgumentTypeError, ClosedChainModel, InfeasibleEffortsError
from vjm_ros.control.closed_model import CLOSURE_RATE, CLOSURE_TOLERANCE
from vjm_ros.core.errors import ConfigurationError


def pose(name: str, du: float = 0.3):
    """An assembled pose away from the start (five_bar's start is singular for its pin)."""
    m = ClosedChainModel.from_scene(name)
    q0, _ = m.model.initial_state()
    q = m.assemble(q0[m.independent] + du, guess=q0)
    return m, q, m.dependent_velocities(q, np.linspace(0.4, -0.3, m.dof))


def both_paths(m, q, qd, **kwargs):
    """Call inverse_dynamics through the compiled (udd) and the numpy (point, xdd) path."""
    kw = {"respect_limits": False, **kwargs}
    yield lambda: m.inverse_dynamics(q, qd, np.array([0.2, -0.1]), **kw)
    yield lambda: m.inverse_dynamics(q, qd, point=m.model.points[0].name, xdd=[0.1, -0.2], **kw)


# ---------------------------------------------------------------------- rates off the closures
def closure_rate(m: ClosedChainModel, q: np.ndarray, qd: np.ndarray) -> float:
    """Oracle: ``max |dC/dt|`` along ``qd`` by a central difference of the closure residual
    (h = 1e-6 s: truncation ~h^2 |qd|^3 ~1e-12, round-off 1e-16 / h ~1e-10 m/s)."""
    h = 1e-6
    return float(np.max(np.abs(m.closure_residual(q + h * qd) - m.closure_residual(q - h * qd)))
                 / (2 * h))


@pytest.mark.parametrize("name", ["five_bar", "three_chain"])
def test_rates_off_the_closures_are_refused_beyond_the_tolerance(name):
    m, q, qd = pose(name, 0.05)
    tol = CLOSURE_TOLERANCE * CLOSURE_RATE
    assert m.velocity_tolerance == tol
    assert closure_rate(m, q, qd) < 1e-9  # the model's own rates keep the closures
    dq = np.zeros(m.n)
    dq[m.dependent[0]] = 1.0  # a rate on a dependent joint (an elbow), rad/s
    per_unit = closure_rate(m, q, qd + dq) - closure_rate(m, q, qd)  # |A e|, m per rad
    assert per_unit > 0.1
    within = qd + dq * 0.5 * tol / per_unit  # a rate of half the tolerance: accepted
    beyond = qd + dq * 2.0 * tol / per_unit  # twice: refused
    assert 0.4 * tol < closure_rate(m, q, within) < 0.6 * tol
    for call in both_paths(m, q, within):
        call()
    m.reduced_dynamics(q, within)
    for call in [*both_paths(m, q, beyond), lambda: m.reduced_dynamics(q, beyond),
                 lambda: m.task_bias(q, beyond, m.model.points[0].name)]:
        with pytest.raises(ConfigurationError,
                           match=r"qd: expected joint rates that keep the closures .*found"):
            call()
    loose = ClosedChainModel(m.model, velocity_tolerance=10 * tol)
    for call in both_paths(loose, q, beyond):
        call()


def test_a_forgotten_dependent_rate_is_refused_naming_the_closure():
    """The mistake the check is for: rates given for the actuated joints only."""
    m, q, qd = pose("five_bar")
    partial = np.zeros(m.n)
    partial[m.independent] = qd[m.independent]
    assert closure_rate(m, q, partial) > 0.05
    for call in both_paths(m, q, partial):
        with pytest.raises(ConfigurationError, match="found .* on closure 'pin'.*"
                                                     "dependent_velocities"):
            call()


def test_a_penalty_closed_simulators_states_pass_with_the_looser_closure_tolerance():
    """The computed-torque controller reads penalty-closed simulators with a closure tolerance
    of 1e-2 m; their rates are off the closures by up to ~0.2 m/s (the default rate tolerance
    follows the closure tolerance: 10 m/s there). 0.5 s of five_bar's fall from bent elbows."""
    from vjm_ros.scene.loader import load_scene
    from vjm_ros.sim.simulator import SimulationSettings, Simulator

    m, q, _ = pose("five_bar")
    scene = load_scene("five_bar")
    sim = Simulator(m.model.with_state(q, np.zeros(m.n)), SimulationSettings(closure="penalty"),
                    scene.gains)
    reader = ClosedChainModel(m.model, closure_tolerance=1e-2)
    worst = 0.0
    for _ in range(500):
        sim.advance()
        s = sim.sample(geometry=False)
        worst = max(worst, closure_rate(m, s.q, s.qd))
        reader.inverse_dynamics(s.q, s.qd, [0.0, 0.0], respect_limits=False)
    assert worst > CLOSURE_TOLERANCE * CLOSURE_RATE  # the default would refuse these states


# ---------------------------------------------------------------------------------- preload
@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_a_non_finite_preload_is_refused(value):
    m, q, qd = pose("three_chain", 0.05)
    for call in both_paths(m, q, qd, preload=value):
        with pytest.raises(ConfigurationError, match=r"preload: expected a finite number "
                                                     r"\(N m or N\), found (nan|inf|-inf)"):
            call()


@pytest.mark.parametrize("value", ["20", b"20", [20.0], True, None])
def test_a_preload_that_is_not_a_number_is_a_type_error(value):
    m, q, qd = pose("three_chain", 0.05)
    for call in both_paths(m, q, qd, preload=value):
        with pytest.raises(ArgumentTypeError, match="preload: expected a finite number") as exc:
            call()
        assert isinstance(exc.value, TypeError)


def test_a_numpy_number_is_a_preload():
    m, q, qd = pose("three_chain", 0.05)
    for kind in (np.float32(5.0), np.int64(5), np.array(5.0), 5):
        a = m.inverse_dynamics(q, qd, [0.2, -0.1], preload=kind, respect_limits=False)
        b = m.inverse_dynamics(q, qd, [0.2, -0.1], preload=5.0, respect_limits=False)
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("name", ["five_bar", "four_bar"])
def test_a_preload_without_a_redundant_actuator_is_refused(name):
    m = ClosedChainModel.from_scene(name)
    q0, _ = m.model.initial_state()
    q = m.assemble(q0[m.independent] + 0.3, guess=q0)
    qd = np.zeros(m.n)
    udd = np.zeros(m.dof)
    with pytest.raises(ConfigurationError, match=rf"preload: expected redundant actuation .*"
                                                 rf"found {m.dof} actuators for {m.dof} degrees"):
        m.inverse_dynamics(q, qd, udd, preload=20.0)
    m.inverse_dynamics(q, qd, udd, preload=0.0)  # zero is no preload


# -------------------------------------------------------------------------- infeasible efforts
def test_infeasible_efforts_name_the_actuators_joint():
    m, q, qd = pose("three_chain", 0.05)
    calls = [lambda: m.inverse_dynamics(q, qd, [50.0, -40.0]),
             lambda: m.inverse_dynamics(q, qd, point="chain1_tip", xdd=[80.0, -60.0])]
    for call in calls:
        with pytest.raises(InfeasibleEffortsError) as exc:
            call()
        err = exc.value
        assert err.actuator in m.model.actuator_names
        assert f"{err.actuator} needs" in str(err) and "actuator 0" not in str(err)
        k = m.model.actuator_names.index(err.actuator)
        assert err.limit == m.limits[k] == 200.0
        assert abs(err.needed) > err.limit


# ----------------------------------------------------------------------- numbers given as text
@pytest.mark.parametrize("arg, value", [("udd", "ab"), ("udd", ["0.1", "0.2"]),
                                        ("udd", [0.1, None]), ("xdd", "ab"), ("q", "ab"),
                                        ("qd", {"left_base": "x", "left_elbow": 0.0,
                                                "right_base": 0.0, "right_elbow": 0.0}),
                                        ("weights", "ab")])
def test_text_where_numbers_are_expected_is_a_type_error_naming_the_argument(arg, value):
    m, q, qd = pose("five_bar")
    kwargs = {"q": q, "qd": qd}
    if arg == "xdd":
        kwargs.update(point="left_tip", xdd=value)
    else:
        kwargs.update(udd=[0.2, -0.1])
        kwargs[arg] = value
    with pytest.raises(ArgumentTypeError, match=rf"^{arg}: expected .*, found ") as exc:
        m.inverse_dynamics(**kwargs)
    assert isinstance(exc.value, TypeError) and isinstance(exc.value, ConfigurationError)


@pytest.mark.parametrize("weights, found", [([1.0, np.inf, 1.0], "inf"), ([1.0, -1.0, 1.0], "-1"),
                                            ([1.0, 1.0], r"\[1.0, 1.0\]")])
def test_weights_must_be_positive_and_finite(weights, found):
    m, q, qd = pose("three_chain", 0.05)
    for call in both_paths(m, q, qd, weights=weights):
        with pytest.raises(ConfigurationError, match=rf"weights: expected 3 positive finite "
                                                     rf"numbers, found .*{found}"):
            call()


def test_udd_and_xdd_together_are_refused_naming_both():
    m, q, qd = pose("five_bar")
    with pytest.raises(ConfigurationError, match="udd and xdd: expected either"):
        m.inverse_dynamics(q, qd, [0.0, 0.0], point="left_tip", xdd=[0.0, -1.0])
    with pytest.raises(ConfigurationError, match="xdd: expected the acceleration of 'left_tip'"):
        m.inverse_dynamics(q, qd, point="left_tip")
    with pytest.raises(ConfigurationError, match="point: expected the named point"):
        m.inverse_dynamics(q, qd, xdd=[0.0, -1.0])
