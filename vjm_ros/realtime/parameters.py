"""Parameters of ``vjm_sim_node``: names, defaults, ranges, validation, no ROS.

:data:`PARAMETERS` is the single table the node declares its ROS parameters from (descriptions and
ranges included) and that ``config/sim_node.yaml`` mirrors. Each parameter takes effect at one of
three moments (:attr:`ParamSpec.applies`):

* ``now``: at the next tick (``realtime``, ``duration``, rates, timeouts, ``lockstep``, ...);
* ``reset``: the simulator is rebuilt with the new value at the next ``~/reset`` (``scene``,
  ``rate_hz``, ``substeps``, ``integrator``, ``closure``, ``kp``, ``kv``, ``kernel``); a value that cannot
  build a simulator (unknown scene, penalty gains too stiff for the integrator, ...) is refused
  when set, with the reason;
* ``start``: read-only after start (``mcap``, ``rrd``, ``realtime_priority``, ``start_paused``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, make_dataclass, replace

from vjm_ros.core.errors import ConfigurationError, StiffnessError
from vjm_ros.core.integrators import INTEGRATORS
from vjm_ros.scene.description import with_initial_positions
from vjm_ros.scene.loader import Scene, load_scene
from vjm_ros.sim.settings import SimulationSettings, resolve_settings
from vjm_ros.sim.simulator import Simulator

NOW, RESET, START = "now", "reset", "start"


@dataclass(frozen=True)
class ParamSpec:
    """One node parameter.

    Attributes
    ----------
    name : str
    default : bool, int, float or str
        Also fixes the ROS parameter type.
    description : str
        Meaning and unit.
    low, high : float, optional
        Inclusive range of a number.
    choices : tuple of str
        Admissible strings (empty: any).
    applies : str
        ``"now"``, ``"reset"`` or ``"start"`` (see the module documentation).
    """

    name: str
    default: bool | int | float | str
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    applies: str = NOW


PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec("scene", "four_bar",
              "Built-in scene name (see `vjm scenes`) or path to a scene YAML file.",
              applies=RESET),
    ParamSpec("rate_hz", 0.0,
              "Control ticks per second of simulated time, Hz (efforts are held over a tick); "
              "0: the scene's default rate.", 0.0, 1e5, applies=RESET),
    ParamSpec("substeps", 0,
              "Fixed integration steps per tick; 0: the scene's default.", 0, 10000,
              applies=RESET),
    ParamSpec("integrator", "",
              "Integration method; empty: the scene's default.",
              choices=("", *INTEGRATORS), applies=RESET),
    ParamSpec("closure", "",
              "Closure method: 'penalty' (PD forces, the thesis) or 'exact' (Lagrange "
              "multipliers); empty: the scene's method.",
              choices=("", "penalty", "exact"), applies=RESET),
    ParamSpec("kp", -1.0,
              "Penalty closure stiffness, N/m (N m/rad for angle closures); negative: the "
              "scene's gains.", -1.0, 1e12, applies=RESET),
    ParamSpec("kv", -1.0,
              "Penalty closure damping, N s/m (N m s/rad); negative: 0 when kp is given, else "
              "the scene's gains.", -1.0, 1e12, applies=RESET),
    ParamSpec("kernel", "auto",
              "Physics kernels: 'auto' (machine code with numba, plain Python without) or "
              "'numba' (an error without numba).",
              choices=("auto", "numba"), applies=RESET),
    ParamSpec("realtime", True,
              "Pace ticks to the wall clock (late and missed ticks are counted); false: run "
              "as fast as possible."),
    ParamSpec("duration", 0.0,
              "Simulated seconds after which the node stops with exit code 0, counted from "
              "the start as /clock counts them (a ~/reset does not restart it); 0: run until "
              "stopped.", 0.0, 1e9),
    ParamSpec("mcap", "",
              "Path of an MCAP log (ROS 2 profile) written while running; empty: none.",
              applies=START),
    ParamSpec("rrd", "",
              "Path of a rerun recording (.rrd) written while running; empty: none.",
              applies=START),
    ParamSpec("publish_clock", True,
              "Publish /clock (simulated time) every tick. /clock is absolute: in a graph of "
              "several simulators, false for all but one (false: no /clock publisher at all)."),
    ParamSpec("command_timeout", 0.5,
              "Wall-clock seconds the last valid command holds without a new one; then the "
              "efforts fall to zero (one warning). 0: hold forever.", 0.0, 3600.0),
    ParamSpec("publish_rate_hz", 0.0,
              "Rate of /joint_states in Hz of simulated time (every round(tick rate / "
              "publish_rate_hz) ticks); 0: every tick.", 0.0, 1e5),
    ParamSpec("forces_rate_hz", 0.0,
              "Rate of ~/constraint_forces, ~/closures/<name>/wrench and ~/energy in Hz of "
              "simulated time (each costs one more evaluation of the dynamics: lower it when "
              "ticks run late); 0: every tick.", 0.0, 1e5),
    ParamSpec("lockstep", False,
              "Each tick waits for a command received since the previous tick (or "
              "lockstep_timeout) before stepping; no wall-clock pacing."),
    ParamSpec("lockstep_timeout", 1.0,
              "Wall-clock seconds a lockstep tick waits for a fresh command before stepping "
              "with the command in force (counted in /diagnostics).", 1e-3, 3600.0),
    ParamSpec("marker_rate_hz", 30.0,
              "Wall-clock rate of ~/markers, Hz; 0: no markers.", 0.0, 1000.0),
    ParamSpec("wait_for_command", False,
              "Hold the initial state (at start and after ~/reset) until the first valid "
              "command arrives, republishing /joint_states every 0.1 s meanwhile: a controller "
              "that connects late finds the mechanism where the scene put it."),
    ParamSpec("realtime_priority", 0,
              "SCHED_FIFO priority (1-99) of the tick loop's thread on Linux, for fewer missed "
              "ticks on a busy machine (needs root, CAP_SYS_NICE or an rtprio limit; refused "
              "with a warning otherwise); 0: normal scheduling.", 0, 99, applies=START),
    ParamSpec("start_paused", False,
              "Start paused (resume with the ~/pause service, data: false).", applies=START),
)
"""Every parameter of the node, in declaration order."""

SPECS = {p.name: p for p in PARAMETERS}


class _Config:
    """Validated parameter values (see :data:`PARAMETERS` for meanings and units): one field per
    parameter, its default the parameter's (:class:`NodeConfig` is made from the table)."""

    @classmethod
    def from_values(cls, values: Mapping[str, object]) -> NodeConfig:
        """Check every value against its :class:`ParamSpec`.

        Raises
        ------
        ConfigurationError
            Naming the parameter, the expected and the found value.
        """
        unknown = sorted(set(values) - set(SPECS))
        if unknown:
            raise ConfigurationError(f"unknown parameter(s) {unknown}; known: {list(SPECS)}")
        checked = {name: _check(SPECS[name], v) for name, v in values.items()}
        config = replace(cls(), **checked)
        if config.kv >= 0 and config.kp < 0:
            raise ConfigurationError("kv: a damping needs a stiffness; set kp too (or kv < 0)")
        return config

    def updated(self, changes: Mapping[str, object]) -> NodeConfig:
        """A copy with ``changes`` applied and validated."""
        return NodeConfig.from_values({**asdict(self), **changes})

    def changed(self, other: NodeConfig) -> dict[str, str]:
        """Names of the parameters that differ from ``other``, with when each applies."""
        return {
            f.name: SPECS[f.name].applies
            for f in fields(self)
            if getattr(self, f.name) != getattr(other, f.name)
        }


NodeConfig = make_dataclass("NodeConfig", [(p.name, type(p.default), p.default) for p in PARAMETERS],
                            bases=(_Config,), frozen=True)
NodeConfig.__module__ = __name__
NodeConfig.__doc__ = _Config.__doc__


def _check(spec: ParamSpec, value: object) -> bool | int | float | str:
    kind = type(spec.default)
    name = spec.name
    if kind is bool:
        if not isinstance(value, bool):
            raise ConfigurationError(f"{name}: expected true or false, found {value!r}")
        return value
    if kind is str:
        if not isinstance(value, str):
            raise ConfigurationError(f"{name}: expected a string, found {value!r}")
        if spec.choices and value not in spec.choices:
            shown = ", ".join(repr(c) for c in spec.choices)
            raise ConfigurationError(f"{name}: expected one of {shown}, found {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigurationError(f"{name}: expected a number, found {value!r}")
    if kind is int and int(value) != value:
        raise ConfigurationError(f"{name}: expected a whole number, found {value!r}")
    if not math.isfinite(value) or not spec.low <= value <= spec.high:
        raise ConfigurationError(
            f"{name}: expected a number from {spec.low:g} to {spec.high:g}, found {value!r}"
        )
    return kind(value)


def simulation_settings(config: NodeConfig, scene: Scene) -> SimulationSettings:
    """Settings of the simulator: the node's values, else the scene's defaults.

    Resolved by :func:`~vjm_ros.sim.settings.resolve_settings`, as ``vjm run`` does: a given
    ``kp`` without ``kv`` means ``kv = 0``; Baumgarte gains and projection come from the scene.
    """
    given_kp = config.kp >= 0
    return resolve_settings(
        scene.defaults,
        scene.gains,
        integrator=config.integrator or None,
        closure=config.closure or None,
        rate=config.rate_hz or None,
        substeps=config.substeps or None,
        kp=config.kp if given_kp else None,
        kv=config.kv if given_kp and config.kv >= 0 else None,
        kernel=config.kernel,
    )


def build_simulator(
    config: NodeConfig, initial_positions: dict[str, float] | None = None
) -> tuple[Scene, Simulator]:
    """Load the scene and build its simulator; refuse settings that cannot run.

    Parameters
    ----------
    config : NodeConfig
    initial_positions : dict, optional
        Joint name to initial value (rad or m): these joints start there and the others are
        assembled so that the closures hold (:func:`~vjm_ros.scene.description.
        with_initial_positions`).

    Raises
    ------
    SceneError
        The scene cannot be loaded.
    ConfigurationError
        A setting is out of range, the penalty gains are too stiff for the integrator and step
        (:class:`~vjm_ros.core.errors.StiffnessError`), ``publish_rate_hz`` exceeds the tick
        rate, or the initial positions name an unknown joint or cannot close the mechanism.
    """
    scene = load_scene(config.scene)
    if initial_positions:
        scene = replace(scene, model=with_initial_positions(scene.model, initial_positions))
    settings = simulation_settings(config, scene)
    try:
        sim = Simulator(scene.model, settings, scene.gains, scene.plant)
    except StiffnessError as exc:
        raise StiffnessError(
            f"{exc} (here: the parameters substeps, integrator, closure, kp and kv)") from None
    except ValueError as exc:  # unknown integrator and the like
        if isinstance(exc, ConfigurationError):
            raise
        raise ConfigurationError(str(exc)) from None
    check_rates(config, sim.settings.rate)
    return scene, sim


def check_rates(config: NodeConfig, rate: float) -> None:
    """Refuse output rates above the tick rate ``rate`` (Hz)."""
    for key in ("publish_rate_hz", "forces_rate_hz"):
        value = getattr(config, key)
        if value > rate * (1 + 1e-12):
            raise ConfigurationError(
                f"{key}: expected at most the tick rate {rate:g} Hz (or 0: every tick), "
                f"found {value:g}"
            )


def ticks_between(rate_hz: float, tick_rate: float) -> int:
    """Ticks between two outputs at ``rate_hz`` (0: every tick) for ticks at ``tick_rate`` Hz."""
    if rate_hz <= 0:
        return 1
    return max(1, round(tick_rate / rate_hz))
