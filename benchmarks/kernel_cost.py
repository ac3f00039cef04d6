"""Cost of one evaluation of the compiled kernel (forward dynamics with its closures).

``python -m benchmarks.kernel_cost [--scenes four_bar three_chain] [--steps 20000]
[--repeats 15] [--json]`` times, for each scene, fixed steps in one compiled call
(:meth:`~vjm_ros.core.mechanism.Mechanism.advance_fixed`: nothing observed or stored, no
Python between the steps) and divides by the evaluations they make:

* **penalty**: ``semi_implicit_euler`` with the scene's penalty gains, one evaluation per step;
* **exact**: ``rk4`` with exact closure, four evaluations per step.

Each evaluation computes the kinematics, ``M``, ``b``, the closure rows and their Jacobian, and
solves for the accelerations (with the multipliers under exact closure); the figure includes the
integrator's own arithmetic. The step is 0.1 ms, efforts as the scene sets them, the best of
``repeats``. Issue target: at most 0.67 µs per evaluation on four_bar. Times vary 2-4x with the
machine's load: compare figures of one run.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from vjm_ros.core import kernels as K
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.settings import resolve_settings
from vjm_ros.sim.simulator import Simulator

METHODS = (("penalty", "semi_implicit_euler", K.SEMI_IMPLICIT_EULER, 1),
           ("exact", "rk4", K.RK4, 4))
"""(closure, integrator, kernel method, evaluations per step) timed for each scene."""

STEP = 1e-4
"""Step of the timed runs, s."""


def evaluation_cost(scene: str, closure: str, steps: int, repeats: int) -> float:
    """Best time of one kernel evaluation, s (see the module docstring).

    Parameters
    ----------
    scene : str
        Built-in scene name or scene file.
    closure : str
        ``"penalty"`` or ``"exact"``.
    steps, repeats : int
        Steps per timed call, and timed calls.

    Returns
    -------
    float
    """
    _, integrator, method, evaluations = next(m for m in METHODS if m[0] == closure)
    sc = load_scene(scene)
    settings = resolve_settings(sc.defaults, sc.gains, closure=closure, integrator=integrator)
    sim = Simulator(sc.model, settings, sc.gains)
    mech, q, qd, tau = sim.mechanism, sim.q, sim.qd, sim.tau
    mech.advance_fixed(method, q, qd, tau, STEP, 10)  # loads the compiled kernel
    best = np.inf
    for _ in range(max(repeats, 1)):
        t0 = time.perf_counter()
        mech.advance_fixed(method, q, qd, tau, STEP, steps)
        best = min(best, (time.perf_counter() - t0) / (steps * evaluations))
    return float(best)


def main(argv: list[str] | None = None) -> int:
    """Print the cost per evaluation of each scene and closure method, µs."""
    from vjm_ros.jit import tiers

    tiers.compile_first()  # times compiled code, never the plain-Python tier
    parser = argparse.ArgumentParser(prog="python -m benchmarks.kernel_cost",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=["four_bar", "three_chain"])
    parser.add_argument("--steps", type=int, default=20000, help="steps per timed call")
    parser.add_argument("--repeats", type=int, default=15, help="timed calls; the best counts")
    parser.add_argument("--json", action="store_true", help="the figures as JSON, last line")
    args = parser.parse_args(argv)
    rows = {}
    for scene in args.scenes:
        for closure, *_ in METHODS:
            cost = evaluation_cost(scene, closure, args.steps, args.repeats)
            rows[f"{scene} {closure}"] = cost
            print(f"{scene:>14} {closure:>8}: {cost * 1e6:.3f} us per evaluation "
                  f"(target <= 0.67 us on four_bar)")
    if args.json:
        print(json.dumps({k: v * 1e6 for k, v in rows.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
