"""Helpers of the import tests: a scene run for a while, its joint coordinates and named points.

The imported scenes place their link frames differently from scenes written by hand (one angle
per run of revolute joints, the plane's own basis), so the tests compare what does not depend on
frames: the world positions of named points and the joint coordinates up to their zero.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vjm_ros.scene.builder import Scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

MODELS = Path(__file__).resolve().parent / "models"


def run(scene: Scene, seconds: float = 1.0, efforts=None, closure: str = "exact") -> dict:
    """Joint coordinates ``q`` (ticks, n) by joint name and named points (ticks, 2) by name.

    rk4 at 1 kHz with the given closure method, constant ``efforts`` (scene actuator order).
    """
    sim = Simulator(scene.model, SimulationSettings(integrator="rk4", closure=closure),
                    scene.gains, getattr(scene, "plant", None))
    q, pts = [], []
    if efforts is not None:
        sim.set_efforts(np.asarray(efforts, dtype=float))
    for _ in range(int(round(seconds * 1000))):
        sim.advance()
        s = sim.sample()
        q.append(s.q.copy())
        pts.append(s.points.copy())
    q, pts = np.array(q), np.array(pts)
    out = {"q": {j: q[:, k] for k, j in enumerate(scene.model.joint_names)},
           "points": {p.name: pts[:, k] for k, p in enumerate(scene.model.points)}}
    return out
