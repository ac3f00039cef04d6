"""Task-space paths for the example controllers: a circle and a figure-eight through a start point.

Both start at rest at ``start`` (the tracked point's position when the controller starts): the
path parameter's rate rises smoothly (quintic) from 0 to its cruise value over ``approach`` s,
so position, velocity and acceleration are continuous from t = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def _phase(t: float, rate: float, approach: float) -> tuple[float, float, float]:
    """Path parameter, its rate and acceleration at ``t`` (rad, rad/s, rad/s^2)."""
    if approach <= 0.0 or t >= approach:
        offset = 0.5 * rate * approach if approach > 0 else 0.0
        return offset + rate * (t - max(approach, 0.0)), rate, 0.0
    if t <= 0.0:
        return 0.0, 0.0, 0.0
    s = t / approach
    ramp = 10 * s**3 - 15 * s**4 + 6 * s**5
    dramp = (30 * s**2 - 60 * s**3 + 30 * s**4) / approach
    integral = (2.5 * s**4 - 3 * s**5 + s**6) * approach
    return rate * integral, rate * ramp, rate * dramp


@dataclass(frozen=True)
class TaskPath:
    """A planar path of the tracked point from ``start`` (m), of size ``size`` (m), one cycle
    per ``period`` s after ``approach`` s; subclasses give its shape as a function of the path
    parameter."""

    start: tuple[float, float]
    size: float = 0.05
    period: float = 2.0
    approach: float = 1.0

    def shape(self, p: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Offset from ``start`` (m) and its first and second derivatives in ``p``."""
        raise NotImplementedError

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position (m), velocity (m/s) and acceleration (m/s^2) at ``t`` s, each shape (2,)."""
        p, dp, ddp = _phase(t, 2 * math.pi / self.period, self.approach)
        x, d1, d2 = self.shape(p)
        return np.asarray(self.start, dtype=float) + x, d1 * dp, d2 * dp**2 + d1 * ddp


class Circle(TaskPath):
    """A circle of radius ``size`` through ``start``, centre ``start - (size, 0)``,
    counter-clockwise."""

    def shape(self, p: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r, c, s = self.size, math.cos(p), math.sin(p)
        return r * np.array([c - 1.0, s]), r * np.array([-s, c]), r * np.array([-c, -s])


class FigureEight(TaskPath):
    """A figure-eight (lemniscate of Gerono) of half-width ``size`` centred on ``start``:
    ``start + size (sin p, sin p cos p)``."""

    def shape(self, p: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a = self.size
        return (a * np.array([math.sin(p), 0.5 * math.sin(2 * p)]),
                a * np.array([math.cos(p), math.cos(2 * p)]),
                a * np.array([-math.sin(p), -2 * math.sin(2 * p)]))


PATHS = {"circle": Circle, "figure8": FigureEight}
"""Path kinds by name."""
