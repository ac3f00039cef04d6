"""External wrenches between the ROS callbacks and the tick loop, without ROS.

A user pushes on the mechanism by sending a planar wrench (a force in the world frame, N, and a
torque about z, N m) at one of the scene's named points (``~/external_wrench``,
``geometry_msgs/WrenchStamped`` with ``header.frame_id`` the point's name). :meth:`WrenchBuffer.submit`
takes it from the executor thread; the tick loop latches the wrenches at the start of each tick
(:meth:`WrenchBuffer.latch`): a wrench acts from the next tick on, one per point (a new one at
the same point replaces it), until none has arrived at that point for ``timeout`` seconds.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence

from vjm_ros.core.model import Load, NamedPoint


class WrenchBuffer:
    """The wrenches in force, by named point.

    Parameters
    ----------
    points : sequence of NamedPoint
        The scene's named points (chain tips included); a wrench names one of them.
    timeout : float
        A wrench is dropped this long after it arrived (s, wall clock); 0: kept until replaced.
    clock : callable
        Wall clock, s.
    """

    def __init__(self, points: Sequence[NamedPoint], timeout: float = 0.5,
                 clock: Callable[[], float] = time.monotonic):
        self.points = {p.name: p for p in points if p.ref.link >= 0}
        self.timeout = float(timeout)
        self._clock = clock
        self._lock = threading.Lock()
        self._held: dict[str, tuple[Load, float]] = {}
        self._changed = False
        self.accepted = 0
        self.refused = 0

    def submit(self, frame: str, force: Sequence[float], torque: float) -> str | None:
        """Take a wrench for the next tick.

        Parameters
        ----------
        frame : str
            Name of the point it acts at.
        force : sequence of 2 floats
            World-frame force, N.
        torque : float
            Torque about z, N m.

        Returns
        -------
        str or None
            Why it was refused (nothing applied), or None when it was taken.
        """
        values = [*force, torque]
        if frame not in self.points:
            self.refused += 1
            names = ", ".join(sorted(self.points)) or "none"
            return (f"header.frame_id: expected a named point of the scene on a moving link "
                    f"({names}), found {frame!r}")
        if not all(math.isfinite(v) for v in values):
            self.refused += 1
            return f"wrench: expected finite force and torque, found {values}"
        load = Load(f"external_wrench.{frame}", self.points[frame].ref,
                    (float(force[0]), float(force[1])), float(torque))
        with self._lock:
            self._held[frame] = (load, self._clock())
            self._changed = True
        self.accepted += 1
        return None

    def latch(self) -> tuple[Load, ...] | None:
        """The loads for the tick about to start when they changed (a wrench arrived or timed
        out), else None."""
        with self._lock:
            if self.timeout > 0 and self._held:
                now = self._clock()
                for frame in [f for f, (_, at) in self._held.items() if now - at > self.timeout]:
                    del self._held[frame]
                    self._changed = True
            if not self._changed:
                return None
            self._changed = False
            return tuple(load for load, _ in self._held.values())

    def clear(self) -> None:
        """Drop every wrench (a reset)."""
        with self._lock:
            self._changed = bool(self._held) or self._changed
            self._held.clear()
