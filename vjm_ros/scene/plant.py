"""What a scene says about the plant between a controller and the mechanism: actuator dynamics
(``gear``, ``time_constant``, ``delay``) and the joint sensors (docs/design.md section 4).

Plain values, validated by :class:`~vjm_ros.scene.builder.SceneBuilder`; the dynamics are
:mod:`vjm_ros.sim.actuators` and :mod:`vjm_ros.sim.sensors`. A scene without these keys has
``Plant()``: unit gears, no lag, no delay, no sensors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from vjm_ros.core.errors import ConfigurationError

SENSOR_FIELDS = ("position", "velocity", "effort")
"""The fields of ``sensors.joint_states``, in the order of ``JointState``."""

WHOLE_TICK_TOLERANCE = 1e-9
"""Relative slack of a delay counted in ticks: ``delay * rate`` within this of a whole number
(delays written in decimal, such as 0.003 s at 1 kHz, are not exact binary multiples)."""


@dataclass(frozen=True)
class ActuatorDynamics:
    """The dynamics of one actuator between its command and the effort on its joint.

    Attributes
    ----------
    gear : float
        Joint effort per unit of command (the scene's ``limit`` bounds the command).
    time_constant : float
        First-order lag of the applied effort, s (0: none).
    delay : float
        Dead time between a command and its effect, s (a whole number of ticks at the run's rate).
    key : str
        Key path of the actuator in the scene (``actuators[0]``), for errors.
    """

    gear: float = 1.0
    time_constant: float = 0.0
    delay: float = 0.0
    key: str = ""

    @property
    def dynamic(self) -> bool:
        """True when the applied effort depends on past commands (a lag or a delay)."""
        return self.time_constant > 0.0 or self.delay > 0.0


@dataclass(frozen=True)
class SensorChannel:
    """What one field of ``joint_states`` adds to the exact value, per joint.

    A measurement is ``resolution * round((x + bias + noise * e) / resolution)`` with ``e``
    standard normal (without rounding when ``resolution`` is 0). Units: those of the field for
    the joint (rad, rad/s, N m for a revolute joint; m, m/s, N for a prismatic one).

    Attributes
    ----------
    noise : tuple of float, length n
        Standard deviation of the additive Gaussian noise.
    bias : tuple of float, length n
        Constant offset.
    resolution : tuple of float, length n
        Quantization step (0: none).
    """

    noise: tuple[float, ...]
    bias: tuple[float, ...]
    resolution: tuple[float, ...]


@dataclass(frozen=True)
class JointSensors:
    """``sensors.joint_states``: the joint state a controller is given.

    Attributes
    ----------
    channels : tuple of SensorChannel
        One per field of :data:`SENSOR_FIELDS` (position, velocity, effort).
    delay : float
        Age of the measured state, s (a whole number of ticks at the run's rate).
    seed : int
        Seed of the noise (numpy ``Generator`` on PCG64): the same seed gives the same stream.
    """

    channels: tuple[SensorChannel, SensorChannel, SensorChannel]
    delay: float = 0.0
    seed: int = 0


@dataclass(frozen=True)
class Plant:
    """The plant keys of a scene.

    Attributes
    ----------
    actuators : tuple of ActuatorDynamics
        One per actuator of the model, in its order (empty: unit gears, no dynamics).
    sensors : JointSensors or None
        None: the node publishes the exact state on ``joint_states``.
    source : str
        File path or built-in name, for errors.
    """

    actuators: tuple[ActuatorDynamics, ...] = ()
    sensors: JointSensors | None = None
    source: str = ""


def delay_ticks(delay: float, rate: float, source: str, key: str) -> int:
    """A delay in ticks of ``1 / rate``.

    Parameters
    ----------
    delay : float
        s, >= 0.
    rate : float
        Control ticks per second, Hz.
    source, key : str
        File and key path named in the error.

    Raises
    ------
    ConfigurationError
        ``delay`` is not a whole number of ticks at ``rate``.
    """
    ticks = delay * rate
    whole = round(ticks)
    if abs(ticks - whole) > WHOLE_TICK_TOLERANCE * max(1.0, ticks) or not math.isfinite(ticks):
        where = f"{source}: {key}" if source else key
        raise ConfigurationError(
            f"{where}: expected a whole number of ticks of {1.0 / rate:g} s (rate {rate:g} Hz), "
            f"found {delay:g} s = {ticks:g} ticks")
    return int(whole)
