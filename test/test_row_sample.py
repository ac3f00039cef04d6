"""The tick loop's reusable sample (realtime/row_sample.py) against the block's own copies.

Oracle: ``SampleBlock.sample(0)``, the copying path the recorders get; over consecutive ticks, so
a field the refresh left at an earlier tick's value would show.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from vjm_ros.realtime.row_sample import RowSample
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator


def test_refreshed_row_equals_the_copied_sample_tick_after_tick():
    scene = load_scene("three_chain")
    sim = Simulator(scene.model, SimulationSettings(), scene.gains)
    assert sim.blocks_compiled()
    block = SampleBlock(scene.model, 1)
    row = RowSample(block)
    for k in range(4):
        sim.set_efforts([(k + 1) * 0.1 * a.effort for a in scene.model.actuators])
        sim.advance_block(block, 1)
        view, copy = row.refresh(), block.sample(0)
        for f in dataclasses.fields(copy):
            a, b = getattr(view, f.name), getattr(copy, f.name)
            if f.name == "sigma_min":
                assert math.isnan(a) and math.isnan(b)
            else:
                np.testing.assert_array_equal(a, b, err_msg=f.name)
        assert view.t == sim.t and np.array_equal(view.effort, sim.tau)
