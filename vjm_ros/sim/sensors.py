"""Joint sensors: the joint state a controller is given, from the exact one.

Per field of ``joint_states`` (position, velocity, effort) and joint (docs/design.md section 4),
the measurement taken at tick ``k`` is::

    y[k] = r * round((x[k - D] + bias + noise * e[k]) / r)        (no rounding when r = 0)

with ``x`` the exact value (the applied effort for ``effort``), ``D`` the sensor delay in whole
ticks (the start state stands for the ticks before the start), ``r`` the resolution (encoder
quantization, round half to even) and ``e`` standard normal draws of a numpy ``Generator`` on
PCG64 seeded with the scene's ``seed``. Draws are taken in time order, one per tick for each
field and joint with ``noise > 0`` (field-major, joints in scene order), and the stream restarts
from the seed at every reset: the same seed gives the same measurements, whether the ticks are
measured one at a time (the node) or in blocks (``vjm run``). The start state is measured too
(row ``t = 0``).
"""

from __future__ import annotations

import numpy as np

from vjm_ros.scene.plant import JointSensors, delay_ticks

FIELDS = 3
"""Position, velocity, effort."""


class SensorModel:
    """Measurements of the joint state, tick by tick or a block at a time.

    Parameters
    ----------
    spec : JointSensors
        The scene's ``sensors.joint_states``.
    dt : float
        Tick length, s.
    source : str
        Scene file or name, for errors.

    Raises
    ------
    ConfigurationError
        The delay is not a whole number of ticks at ``1 / dt``.
    """

    def __init__(self, spec: JointSensors, dt: float, source: str = ""):
        self.spec = spec
        self.delay = delay_ticks(spec.delay, 1.0 / dt, source, "sensors.joint_states.delay")
        """Age of a measurement, ticks."""
        self.noise = np.array([ch.noise for ch in spec.channels], dtype=float)
        self.bias = np.array([ch.bias for ch in spec.channels], dtype=float)
        self.resolution = np.array([ch.resolution for ch in spec.channels], dtype=float)
        self._noisy = self.noise > 0
        self._quantized = self.resolution > 0
        self._step = np.where(self._quantized, self.resolution, 1.0)
        self.rng = np.random.Generator(np.random.PCG64(spec.seed))
        self._past = np.zeros((0,) + self.noise.shape)

    def reset(self, exact: np.ndarray) -> np.ndarray:
        """Restart the stream from the seed at a start state; its measurement.

        Parameters
        ----------
        exact : ndarray, shape (3, n)
            Position, velocity and applied effort at the start.

        Returns
        -------
        ndarray, shape (3, n)
        """
        self.rng = np.random.Generator(np.random.PCG64(self.spec.seed))
        self._past = np.repeat(np.asarray(exact, dtype=float)[None], self.delay, axis=0)
        return self.measure(exact[None])[0]

    def measure(self, exact: np.ndarray) -> np.ndarray:
        """Measurements of consecutive ticks.

        Parameters
        ----------
        exact : ndarray, shape (rows, 3, n)
            The exact state at the end of each tick, in time order.

        Returns
        -------
        ndarray, shape (rows, 3, n)
        """
        rows = len(exact)
        if self.delay:
            stream = np.concatenate((self._past, exact))
            value, self._past = stream[:rows].copy(), stream[rows:].copy()
        else:
            value = np.array(exact, dtype=float)
        value += self.bias
        if self._noisy.any():
            draws = self.rng.standard_normal((rows, int(self._noisy.sum())))
            value[:, self._noisy] += self.noise[self._noisy] * draws
        if self._quantized.any():
            value = np.where(self._quantized, np.round(value / self._step) * self._step, value)
        return value
