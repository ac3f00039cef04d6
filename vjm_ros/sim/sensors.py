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
        noise, resolution = self.noise.reshape(-1), self.resolution.reshape(-1)
        self._noisy = np.flatnonzero(noise > 0)
        self._sigma = noise[self._noisy]
        self._quantized = np.flatnonzero(resolution > 0)
        self._step = resolution[self._quantized]
        # the same, as Python numbers: a single tick is cheaper in scalar code than in numpy
        self._noisy_pairs = list(zip(self._noisy.tolist(), self._sigma.tolist(), strict=True))
        self._quantized_pairs = list(zip(self._quantized.tolist(), self._step.tolist(),
                                         strict=True))
        self.rng = np.random.Generator(np.random.PCG64(spec.seed))
        self._ring = np.zeros((self.delay,) + self.noise.shape)
        """The last ``delay`` exact states, the oldest at :attr:`_head`."""
        self._head = 0

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
        self._ring = np.repeat(np.asarray(exact, dtype=float)[None], self.delay, axis=0)
        self._head = 0
        return self.measure_one(exact)

    def measure_one(self, exact: np.ndarray) -> np.ndarray:
        """The measurement of one tick (the same numbers as :meth:`measure` of one row).

        Parameters
        ----------
        exact : ndarray, shape (3, n)
            The exact state at the end of the tick.

        Returns
        -------
        ndarray, shape (3, n)
        """
        if self.delay:
            value = self._ring[self._head] + self.bias
            self._ring[self._head] = exact
            self._head = (self._head + 1) % self.delay
        else:
            value = exact + self.bias
        flat = value.reshape(-1)
        if self._noisy_pairs:
            draws = self.rng.standard_normal(len(self._noisy_pairs)).tolist()
            for (k, sigma), e in zip(self._noisy_pairs, draws, strict=True):
                flat[k] += sigma * e
        for k, step in self._quantized_pairs:
            flat[k] = round(flat[k] / step) * step  # half to even, as numpy's round
        return value

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
            past = np.roll(self._ring, -self._head, axis=0)  # oldest first
            stream = np.concatenate((past, exact))
            value, self._ring, self._head = stream[:rows] + self.bias, stream[rows:].copy(), 0
        else:
            value = exact + self.bias
        flat = value.reshape(rows, -1)
        if len(self._noisy):
            flat[:, self._noisy] += self._sigma * self.rng.standard_normal((rows, len(self._noisy)))
        if len(self._quantized):
            flat[:, self._quantized] = np.round(flat[:, self._quantized] / self._step) * self._step
        return value
