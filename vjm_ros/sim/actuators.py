"""Actuator dynamics: the commands a controller sends to the efforts the joints receive.

Per actuator (docs/design.md section 4): the command ``c`` (clamped to the scene's ``limit``)
waits ``delay`` (``D`` whole ticks), is multiplied by ``gear`` ``G`` and passes a first-order lag
of time constant ``T``::

    T dy/dt + y = G c(t - D dt)

Efforts are held constant within a tick (docs/design.md section 3): the command is constant over
the tick, so the lag is solved exactly over it (zero-order hold), and the effort applied over
tick ``k`` is the mean of the lag's output over that tick::

    y[k+1] = u[k] + (y[k] - u[k]) a,        a = exp(-dt / T)
    applied[k] = u[k] + (y[k] - u[k]) b,    b = (T / dt) (1 - a)

with ``u[k] = G c[k - D]``. The impulse each tick delivers is then the continuous lag's (the
closed form of ``integral of y`` over the tick, to round-off); ``T = 0`` gives ``a = b = 0`` (no
lag), and before the first command every state is zero. Where rounding stops the recursion an
ulp short of ``u`` (``y[k+1] == y[k]``), or comes within the rounding unit of the actuator's range
(``2^-52 gear limit``, which towards ``u = 0`` saves the ~750 time constants of an underflow),
``y`` takes its exact limit ``u``: a held command is then reached exactly, within about 36 time
constants, after which a block of ticks runs in one compiled call (:meth:`Actuation.settled`). The applied effort is what ``joint_states.effort`` and the
CSV's ``effort.<joint>`` report.

An actuator with neither lag nor delay has no state: its gear is folded into the selection
matrix and a tick costs what it cost without these keys.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from vjm_ros.core.model import Model
from vjm_ros.scene.plant import ActuatorDynamics, delay_ticks


class Actuation:
    """Commands to applied joint efforts, tick by tick, for one simulator.

    Parameters
    ----------
    model : Model
    dynamics : sequence of ActuatorDynamics
        One per actuator of ``model``, or empty (unit gears, no dynamics).
    dt : float
        Tick length, s.
    source : str
        Scene file or name, for errors.

    Raises
    ------
    ConfigurationError
        A delay that is not a whole number of ticks at ``1 / dt``.

    Attributes
    ----------
    selection : ndarray, shape (n, n_actuators)
        Joint effort per unit of command (the model's selection matrix times the gears).
    dynamic : bool
        True when some actuator has a lag or a delay (:meth:`tick` must run every tick).
    """

    def __init__(self, model: Model, dynamics: Sequence[ActuatorDynamics], dt: float,
                 source: str = ""):
        m = len(model.actuators)
        dynamics = tuple(dynamics) or tuple(ActuatorDynamics() for _ in range(m))
        if len(dynamics) != m:
            raise ValueError(f"expected {m} actuator dynamics, found {len(dynamics)}")
        self.unit_selection = model.actuator_matrix()
        self.gear = np.array([d.gear for d in dynamics], dtype=float)
        self.selection = self.unit_selection * self.gear
        self.delays = np.array(
            [delay_ticks(d.delay, 1.0 / dt, source, f"{d.key}.delay" if d.key else "delay")
             for d in dynamics], dtype=int)
        tc = np.array([d.time_constant for d in dynamics], dtype=float)
        lagged = tc > 0
        ratio = np.where(lagged, dt / np.where(lagged, tc, 1.0), math.inf)
        self.decay = np.where(lagged, np.exp(-ratio), 0.0)
        """``a = exp(-dt / T)`` per actuator (0 without lag)."""
        self.carry = np.where(lagged, -np.expm1(-ratio) / ratio, 0.0)
        """``b = (T / dt)(1 - a)`` per actuator (0 without lag): the share of the lag's state in
        the tick's mean."""
        limit = np.array([a.limit for a in model.actuators], dtype=float)
        self.floor = np.where(np.isfinite(limit), np.abs(self.gear) * limit * 2.0**-52, 0.0)
        """Deviation of a lag from its input below which it has arrived, per actuator: the
        rounding unit of the largest effort it can apply (gear times limit), N m or N."""
        self.dynamic = bool(np.any(lagged) or np.any(self.delays > 0))
        self._columns = np.arange(m)
        self.reset()

    def reset(self) -> None:
        """Every command and lag state back to zero (the start of an episode)."""
        m = len(self.gear)
        self._past = np.zeros((int(self.delays.max(initial=0)) + 1, m))
        """The last ``D + 1`` commands, a ring indexed by :attr:`_head`."""
        self._head = 0
        self.lag = np.zeros(m)
        """Lag outputs ``y`` at the current tick boundary, actuator units times gear."""

    def tick(self, command: np.ndarray) -> np.ndarray:
        """The joint efforts held over the next tick, the state moved to its end.

        Parameters
        ----------
        command : ndarray, shape (n_actuators,)
            The command in force for this tick (clamped), N m or N before the gear.

        Returns
        -------
        ndarray, shape (n,)
            Applied joint efforts, N m or N.
        """
        past = self._past
        self._head = (self._head + 1) % len(past)
        past[self._head] = command
        u = self.gear * past[(self._head - self.delays) % len(past), self._columns]
        y = self.lag
        applied = u + (y - u) * self.carry
        lag = u + (y - u) * self.decay
        # Rounded, the recursion can stop an ulp short of u (y = u - ulp maps onto itself), and
        # towards 0 it would take ~750 time constants to underflow: within the rounding unit of
        # the actuator's range (floor) or stuck, the state takes the exact limit u.
        self.lag = np.where((lag == y) | (np.abs(lag - u) <= self.floor), u, lag)
        return self.unit_selection @ applied

    def settled(self, command: np.ndarray) -> bool:
        """Whether every following tick with ``command`` held applies the same efforts as a
        tick without dynamics would (the delay line holds only ``command`` and every lag has
        reached ``gear * command`` exactly), so that ticks may run as one block."""
        return bool(np.all(self._past == command)
                    and np.all(self.lag == self.gear * command))
