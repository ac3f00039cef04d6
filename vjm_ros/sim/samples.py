"""What a run observes: one tick's :class:`Sample`, and a :class:`SampleBlock` of consecutive
ticks (the compiled pipeline's outputs, :mod:`vjm_ros.core.pipeline`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vjm_ros.core import pipeline
from vjm_ros.core.model import Model


@dataclass
class Sample:
    """Everything observable at the end of a tick.

    Attributes
    ----------
    t : float
        Simulated time, s.
    q, qd, qdd, effort : ndarray, shape (n,)
        Joint coordinates, rates, accelerations and applied efforts (N m or N).
    theta : ndarray, shape (n,)
        Absolute link angles, rad.
    points : ndarray, shape (n_points, 2), or None
        Named point positions, m (None when the sample was taken without geometry).
    closure_force : ndarray, shape (k + s, 3)
        World-frame force of each closure on its point ``(Fx, Fy, Mz)``, N / N m, then of each
        joint's stop (``Model.force_names``, :mod:`vjm_ros.core.pipeline`).
    closure_error : ndarray, shape (k,)
        ``|C|`` per closure, m (rad for angle closures).
    closure_points : ndarray, shape (k + s, 2)
        Point of application of each closure force, then each stopped joint, m.
    energy : ndarray, shape (4,)
        Kinetic, potential, constraint, total, J.
    power_in : float
        ``tau . qd``, W.
    dissipation : float
        ``sum Kv Cdot^2`` (penalty), joint damping and smooth friction, W.
    joint_loss : float
        Energy the joints' sticking friction and stops (their impacts included) took over the
        tick that ended here, J (0 without them; a power would miss an impact's energy, which
        it takes at once).
    segments : ndarray, shape (n, 2, 2), or None
        Link start/end points for drawing, m (None when taken without geometry).
    sigma_min : float
        Smallest singular value of the closure Jacobian (nan when not computed).
    measured : ndarray, shape (3, n), or None
        Position, velocity and effort as the scene's sensors measure them
        (:mod:`vjm_ros.sim.sensors`); None without sensors.
    """

    t: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    effort: np.ndarray
    theta: np.ndarray
    points: np.ndarray | None
    closure_force: np.ndarray
    closure_error: np.ndarray
    closure_points: np.ndarray
    energy: np.ndarray
    power_in: float
    dissipation: float
    joint_loss: float
    segments: np.ndarray | None
    sigma_min: float = field(default=np.nan)
    measured: np.ndarray | None = None

    @property
    def max_closure_error(self) -> float:
        """Largest closure residual, m (0 without closures)."""
        return float(self.closure_error.max()) if self.closure_error.size else 0.0


BLOCK_FIELDS = tuple(zip(pipeline.OBSERVABLES, (
    "q", "qd", "qdd", "theta", "points", "closure_force", "closure_error", "closure_points",
    "energy", "power_in", "dissipation", "joint_loss", "segments"), strict=True))
"""Arrays of a :class:`SampleBlock` (the compiled pipeline's outputs) and the :class:`Sample`
field each row of them gives."""


RUN_BLOCK_TICKS = 1000
"""Ticks per block of ``vjm run`` and of the bench's timed runs: a few ms of computing (2.5 ms
for the four-bar with rk4 and exact closure, 60 ms for sixteen chains on one pin), which a
signal or the progress bar waits at most. Each block has a fixed cost in every output (encoding
calls, GIL hand-overs between the physics and the writer threads, the compiled call's argument
unboxing): against blocks of 200 ticks, a run with all three logs takes about a sixth less CPU
(four_bar, 10 s: 106 -> 88 ms)."""

FIRST_BLOCK_TICKS = 100
"""Ticks of the first block of ``vjm run``; each block after it has half as many ticks more,
up to :data:`RUN_BLOCK_TICKS` (100, 150, 225, 337, 505, 757, then 1000). Until a block is filled,
the writer threads have nothing of it to write: with 1000-tick blocks from the start the second
core idled through the first block and, the logs taking longer per tick than the physics, again
through part of the next ones, a gap the logs then carried past the last tick. With the blocks
growing as the logs' work on the last one grows, the second core's idle time over the ticks of
``vjm run four_bar --out --mcap --rrd`` (10 s, rk4, exact closure) went from 10.9 to 5.9 ms
(median of 8 interleaved fresh runs each, on a busy 2-core machine)."""


class SampleBlock:
    """The samples at the end of consecutive ticks, one row per tick (``len`` rows).

    Attributes
    ----------
    t : ndarray, shape (T,)
        Simulated time, s.
    effort : ndarray, shape (n,) or (T, n)
        Efforts held over the block, N m or N; or one row per tick, for rows collected from
        ticks with efforts of their own (:class:`vjm_ros.logs.rows.LogRows`).
    q, qd, qdd, theta, points, force, error, cpoints, energy, power, dissipation, loss, segments
        As the fields of :class:`Sample`, with a leading tick axis (the layout of
        :mod:`vjm_ros.core.pipeline`).
    measured : ndarray, shape (T, 3, n), or None
        As :attr:`Sample.measured`, one row per tick (None without sensors).
    """

    def __init__(self, model: Model, capacity: int):
        self.arrays = pipeline.new_outputs(capacity, model)
        for (key, _), arr in zip(BLOCK_FIELDS, self.arrays, strict=True):
            setattr(self, key, arr)
        self.t = np.zeros(capacity)
        self.effort = np.zeros(model.n)
        self.measured: np.ndarray | None = None
        self.rows = 0

    def __len__(self) -> int:
        return self.rows

    def put(self, i: int, s: Sample) -> None:
        """Store sample ``s`` as row ``i``."""
        self.t[i] = s.t
        for key, attr in BLOCK_FIELDS:
            getattr(self, key)[i] = getattr(s, attr)

    def sample(self, i: int) -> Sample:
        """Row ``i`` as a :class:`Sample` of its own (copies: the block is refilled later)."""
        effort = self.effort[i] if self.effort.ndim == 2 else self.effort
        measured = None if self.measured is None else self.measured[i].copy()
        return Sample(t=float(self.t[i]), effort=effort.copy(), measured=measured,
                      **{attr: getattr(self, key)[i].copy() for key, attr in BLOCK_FIELDS})
