"""One settings resolver for ``vjm run``, the node and the studies: the rules, and that the command
line and the node's parameters reach the same settings for the same request."""

from __future__ import annotations

import pytest

from vjm_ros.app.cli import _parser, _settings
from vjm_ros.core.errors import ConfigurationError
from vjm_ros.realtime.parameters import NodeConfig, simulation_settings
from vjm_ros.scene import load_scene
from vjm_ros.sim.settings import SimulationSettings, resolve_settings

DEFAULTS = {"integrator": "semi_implicit_euler", "rate": 500, "substeps": 2}
GAINS = {"method": "exact", "alpha": 5.0, "beta": 7.0, "projection": True}


def test_scene_defaults_fill_what_is_not_given():
    s = resolve_settings(DEFAULTS, GAINS)
    assert (s.integrator, s.rate, s.substeps, s.closure) == ("semi_implicit_euler", 500.0, 2, "exact")
    assert (s.alpha, s.beta, s.projection) == (5.0, 7.0, True)
    assert (s.kp, s.kv, s.omega_n, s.zeta) == (None, None, None, None)
    assert resolve_settings({}, {}) == SimulationSettings()


def test_given_values_win():
    s = resolve_settings(DEFAULTS, GAINS, integrator="rk4", rate=1000, substeps=1,
                         closure="penalty", alpha=1.0, projection=False)
    assert (s.integrator, s.rate, s.substeps, s.closure) == ("rk4", 1000.0, 1, "penalty")
    assert (s.alpha, s.beta, s.projection) == (1.0, 7.0, False)


def test_gain_pairs_complete_themselves():
    assert resolve_settings({}, {}, kp=1e4).kv == 0.0  # stiffness alone: no damping
    assert resolve_settings({}, {}, omega_n=50.0).zeta == 1.0  # frequency alone: critical


@pytest.mark.parametrize(
    "given, message",
    [
        ({"kp": 1.0, "omega_n": 2.0}, "give either kp/kv or omega_n/zeta, not both"),
        ({"kv": 1.0, "zeta": 0.5}, "give either kp/kv or omega_n/zeta, not both"),
        ({"kv": 1.0}, "kv needs kp"),
        ({"zeta": 0.5}, "zeta needs omega_n"),
    ],
)
def test_contradictions_are_refused(given, message):
    with pytest.raises(ConfigurationError, match=message):
        resolve_settings({}, {}, **given)


def test_command_line_names_its_flags():
    args = _parser().parse_args(["run", "four_bar", "--zeta", "0.5"])
    with pytest.raises(ConfigurationError, match="--zeta needs --omega-n"):
        _settings(args, load_scene("four_bar"))


@pytest.mark.parametrize(
    "flags, params",
    [
        ([], {}),
        (["--rate", "500", "--substeps", "3", "--integrator", "implicit_euler"],
         {"rate_hz": 500.0, "substeps": 3, "integrator": "implicit_euler"}),
        (["--kp", "2e4"], {"kp": 2e4}),
        (["--kp", "2e4", "--kv", "30"], {"kp": 2e4, "kv": 30.0}),
        (["--closure", "exact"], {"closure": "exact"}),
    ],
    ids=["defaults", "rate_substeps_integrator", "kp_only", "kp_kv", "exact"],
)
def test_vjm_run_and_the_node_reach_the_same_settings(flags, params):
    scene = load_scene("five_bar")
    from_cli = _settings(_parser().parse_args(["run", "five_bar", *flags]), scene)
    from_node = simulation_settings(NodeConfig(**params), scene)
    assert from_cli == from_node


def test_unknown_setting_is_a_type_error_naming_it():
    # A misspelt keyword must not be dropped silently: the resolver accepts **given.
    with pytest.raises(TypeError, match="omgea_n"):
        resolve_settings({}, {}, omgea_n=3.0)


def test_every_user_setting_reaches_the_settings():
    given = {"integrator": "semi_implicit_euler", "closure": "exact", "rate": 500.0,
             "substeps": 3, "alpha": 7.0, "beta": 8.0, "projection": True, "rtol": 1e-5,
             "atol": 1e-7}
    s = resolve_settings({}, {}, **given)
    assert {k: getattr(s, k) for k in given} == given


def test_the_numpy_kernel_is_refused_with_what_to_use_instead():
    """The physics runs only in the compiled kernels: 'numpy' names the two choices left."""
    with pytest.raises(ConfigurationError, match="'numpy' is no longer a choice.*'auto' or 'numba'"):
        SimulationSettings(kernel="numpy").validated()
    with pytest.raises(ConfigurationError, match="expected 'auto' or 'numba', found 'cuda'"):
        SimulationSettings(kernel="cuda").validated()
    with pytest.raises(ConfigurationError, match="kernel: expected one of 'auto', 'numba', found 'numpy'"):
        NodeConfig.from_values({"kernel": "numpy"})
