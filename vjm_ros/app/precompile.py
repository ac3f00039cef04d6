"""Compile every entry point of the kernels into numba's cache now: ``python -m vjm_ros.app.precompile``.

What ``scripts/setup`` runs, and what an installer or a container image build can run, so that
no later run starts on the plain-Python tier (:mod:`vjm_ros.jit.tiers`): the kernel, the
block pipeline and the observation of one state (:func:`vjm_ros.core.kernels.step`,
:func:`vjm_ros.core.pipeline.advance_ticks`, :func:`~vjm_ros.core.pipeline.observe_state`)
and their copies with the hub solves (mechanisms with four chains or more on one pin), the CSV
writer, and the controllers' compiled model. Compiled in this process (``VJM_TIERED=0``), one
after the other: 1-2 minutes on a 2-core machine, seconds when the cache holds them already.

Run it after ``pip install`` or ``colcon build`` (numba's cache is empty then), and after an edit
of a compiled source (:data:`vjm_ros.jit.sources.COMPILED_SOURCES`: ``vjm_ros/core/`` and the
like). It holds the compile lock
(:func:`vjm_ros.jit.compile_server.holding_lock`): where a run's compile server is busy in the
background, it waits for it first, then loads what that compiled.
"""

from __future__ import annotations

import contextlib
import io
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path


def precompile(log: Callable[[str], object] = print) -> float:
    """Compile (or load) every entry point; returns the wall time taken, s."""
    from vjm_ros.jit import compile_server, tiers

    tiers.compile_first()
    start = time.perf_counter()
    with compile_server.holding_lock(log):
        from vjm_ros.app.cli import main
        from vjm_ros.scene.generated import star_scene
        from vjm_ros.sim.samples import SampleBlock
        from vjm_ros.sim.simulator import SimulationSettings, Simulator

        with tempfile.TemporaryDirectory() as scratch, contextlib.redirect_stdout(io.StringIO()):
            main(["run", "four_bar", "--duration", "0.002", "--out", str(Path(scratch) / "run")])
        log(f"kernels, block pipeline, CSV writer: {time.perf_counter() - start:.1f} s")
        star = star_scene(6)  # the copies with the hub solves
        sim = Simulator(star.model, SimulationSettings(closure="exact"), star.gains)
        sim.blocks_compiled()
        sim.advance_block(SampleBlock(star.model, 2), 2)
        sim.sample()
        log(f"... with the hub solves: {time.perf_counter() - start:.1f} s")
        with contextlib.redirect_stdout(io.StringIO()):  # the controllers' compiled algebra
            main(["model", "five_bar"])
        log(f"... the controllers' model: {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    precompile(lambda text: print(text, file=sys.stderr))
