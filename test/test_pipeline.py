"""Blocks of ticks in one compiled call (:func:`vjm_ros.core.pipeline.advance_ticks`).

Oracle: the tick-by-tick path (``Simulator.advance`` then ``Simulator.sample``), whose physics the
rest of the suite checks against closed forms, energy and the numpy reference. The block path
calls the same compiled step with the same arguments and sums the observables in the same order,
so the comparison is exact (tolerance 0): any difference means the two paths no longer compute
the same thing.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import FIXED_STEP_SETTINGS

from vjm_ros.core.errors import DivergenceError
from vjm_ros.scene.generated import star_scene
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator
from vjm_ros.sim.trajectory import Trajectory

pytest.importorskip("numba")

SCENES = ["four_bar", "six_bar", "double_slider", "five_bar", "three_chain", "rrr_platform",
          "star_6"]
"""Built-in scenes, and six two-link chains on one pin (``star_6``: the hub solves of
:mod:`vjm_ros.core.hub_linalg`, which no built-in scene takes)."""
METHODS = FIXED_STEP_SETTINGS
FIELDS = ("q", "qd", "qdd", "effort", "theta", "points", "closure_force", "closure_error",
          "closure_points", "energy", "power_in", "dissipation", "joint_loss", "segments")


def _pair(scene: str, **settings):
    sc = star_scene(6) if scene == "star_6" else load_scene(scene)
    sims = [Simulator(sc.model, SimulationSettings(check_stiffness=False, **settings), sc.gains)
            for _ in range(2)]
    if sc.model.actuators:
        for sim in sims:
            sim.set_efforts([a.effort for a in sc.model.actuators])
    return sc, sims


@pytest.mark.parametrize("settings", METHODS, ids=lambda s: "-".join(map(str, s.values())))
@pytest.mark.parametrize("scene", SCENES)
def test_block_equals_tick_by_tick(scene, settings):
    sc, (one, many) = _pair(scene, **settings)
    ticks = 120
    expected = []
    for _ in range(ticks):
        one.advance()
        expected.append(one.sample())
    block = SampleBlock(sc.model, 50)
    got = []
    while many.ticks < ticks:  # blocks of 50, 50 and 20: the state carries across calls
        many.advance_block(block, min(50, ticks - many.ticks))
        got += [block.sample(i) for i in range(len(block))]
    assert len(got) == ticks
    for e, g in zip(expected, got, strict=True):
        assert g.t == e.t
        for f in FIELDS:
            np.testing.assert_array_equal(getattr(g, f), getattr(e, f), err_msg=f)
    np.testing.assert_array_equal(many.q, one.q)
    assert many.t == one.t and many.ticks == one.ticks
    # each tick's first evaluation is the sample before, except on a block's first tick
    reused = ticks - 3
    assert many.mechanism.evaluations == one.mechanism.evaluations - reused


@pytest.mark.parametrize("settings", [{"integrator": "rk45"}, {"integrator": "dop853"}])
def test_block_falls_back_to_ticks_where_nothing_is_compiled(settings):
    """Adaptive integrators fill the block tick by tick."""
    sc, (one, many) = _pair("four_bar", closure="exact", **settings)
    block = SampleBlock(sc.model, 20)
    many.advance_block(block, 20)
    for i in range(20):
        one.advance()
        np.testing.assert_array_equal(block.sample(i).q, one.sample().q)


def test_divergence_inside_a_block_raises_the_tick_by_tick_diagnosis():
    """explicit_euler with Kp 1e8 and the check off diverges within 50 ms: the block keeps the
    ticks before the failing one and raises the error the tick-by-tick path raises."""
    settings = {"integrator": "explicit_euler", "kp": 1e8, "kv": 0.0}
    sc, (one, many) = _pair("four_bar", **settings)
    with pytest.raises(DivergenceError) as expected:
        for _ in range(1000):
            one.advance()
    block = SampleBlock(sc.model, 1000)
    with pytest.raises(DivergenceError) as got:
        many.advance_block(block, 1000)
    assert str(got.value) == str(expected.value)
    assert got.value.closure == expected.value.closure == "tip_pin"
    assert many.ticks == one.ticks  # the failing tick counted, as tick by tick
    assert len(block) == many.ticks - 1  # the good ticks before it
    assert many.t == one.t
    np.testing.assert_array_equal(many.q, one.q)
    assert np.all(np.isfinite(block.q[: len(block)]))


@pytest.mark.parametrize("blocks", [[1, 1, 1], [50, 50, 20], [7, 40, 3, 70], [120], [33, 1, 32]])
def test_block_keeps_the_states_tick_by_tick_keeps(blocks):
    """The states kept for a divergence's diagnosis (the last 32 that a tick started from, with
    their times) are the tick-by-tick path's, whatever the blocks: bit for bit."""
    sc, (one, many) = _pair("four_bar", integrator="rk4", closure="exact")
    for _ in range(sum(blocks)):
        one.advance()
    block = SampleBlock(sc.model, max(blocks))
    for ticks in blocks:
        many.advance_block(block, ticks)
    expected, got = list(one._history), list(many._history)
    assert len(got) == len(expected) == min(sum(blocks), 32)
    for (te, qe, qde), (tg, qg, qdg) in zip(expected, got, strict=True):
        assert tg == te
        np.testing.assert_array_equal(qg, qe)
        np.testing.assert_array_equal(qdg, qde)
    assert one._history[-1][0] == many._history[-1][0]


def test_state_history_keeps_the_last_states_as_a_bounded_deque():
    """StateHistory against collections.deque(maxlen) fed the same states one at a time."""
    import collections

    from vjm_ros.sim.history import StateHistory

    rng = np.random.default_rng(3)
    history, reference = StateHistory(5), collections.deque(maxlen=5)
    tick = 0
    for rows in [1, 3, 0, 7, 1, 1, 2, 6, 4, 1]:
        if rows == 1 and rng.random() < 0.5:
            q, qd = rng.standard_normal(2), rng.standard_normal(2)
            history.append(tick * 0.1, q, qd)
            reference.append((tick * 0.1, q, qd))
        else:
            qs, qds = rng.standard_normal((rows, 2)), rng.standard_normal((rows, 2))
            history.extend(tick, 0.1, qs, qds)
            reference.extend(((tick + i) * 0.1, qs[i], qds[i]) for i in range(rows))
        tick += rows
        assert len(history) == len(reference)
        for (t, q, qd), (tr, qr, qdr) in zip(history, reference, strict=True):
            assert t == tr
            np.testing.assert_array_equal(q, qr)
            np.testing.assert_array_equal(qd, qdr)
    assert len(history._parts) <= 5  # whole parts older than the last 5 states are dropped
    with pytest.raises(ValueError, match="maxlen"):
        StateHistory(0)


def test_trajectory_extend_equals_append():
    sc, (one, many) = _pair("five_bar", integrator="rk4", closure="penalty")
    a, b = Trajectory(sc.model, capacity=4), Trajectory(sc.model, capacity=4)  # both must grow
    for _ in range(30):
        one.advance()
        a.append(one.sample())
    block = SampleBlock(sc.model, 30)
    many.advance_block(block, 30)
    b.extend(block)
    np.testing.assert_array_equal(a.table(), b.table())
    assert a.summary() == b.summary()


@pytest.mark.parametrize("scene", ["five_bar", "three_chain", "double_slider"])
def test_block_observables_match_the_independent_geometry_and_energy(scene):
    """Every row's link angles, link origins, named points and kinetic and potential energy
    against test/chains.py, which rewrites the geometry of docs/design.md section 1 as plain
    loops (an oracle independent of the kernels). Geometry and potential: the same formulas in
    another summation order, 1e-12 m, rad and J (relative to the largest energy). Kinetic energy:
    the oracle takes velocities by central differences of step 1e-5 (truncation ~h^2/6, round-off
    ~eps/h, both ~1e-11 relative), so 1e-8 relative."""
    import chains

    sc, (_, sim) = _pair(scene, integrator="rk4", closure="exact")
    model = sc.model
    block = SampleBlock(model, 40)
    sim.advance_block(block, 40)
    for i in range(len(block)):
        q, qd = block.q[i], block.qd[i]
        origins, angles = chains.frames(model, q)
        np.testing.assert_allclose(block.theta[i], angles, rtol=0, atol=1e-12)
        np.testing.assert_allclose(block.segments[i][:, 0], origins, rtol=0, atol=1e-12)
        for p, point in enumerate(model.points):
            np.testing.assert_allclose(
                block.points[i][p], chains.point_on_link(model, q, point.ref.link, point.ref.local),
                rtol=0, atol=1e-12)
        kinetic, potential = chains.kinetic(model, q, qd), chains.potential(model, q)
        scale = max(1.0, abs(kinetic), abs(potential))
        assert block.energy[i][0] == pytest.approx(kinetic, abs=1e-8 * scale)
        assert block.energy[i][1] == pytest.approx(potential, abs=1e-12 * scale)


_NO_ALLOCATION = """
from numba.core.runtime import rtsys
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator
from vjm_ros.sim.samples import SampleBlock
sc = load_scene("three_chain")
for integ, closure in (("rk4", "exact"), ("semi_implicit_euler", "penalty"),
                       ("implicit_euler", "penalty")):
    sim = Simulator(sc.model, SimulationSettings(integrator=integ, closure=closure), sc.gains)
    big, one = SampleBlock(sc.model, 200), SampleBlock(sc.model, 1)
    sim.blocks_compiled()
    sim.advance_block(big, 200)
    before = rtsys.get_allocation_stats()
    for _ in range(3):
        sim.advance_block(big, 200)
    for _ in range(20):
        sim.advance_block(one, 1)
    after = rtsys.get_allocation_stats()
    print(integ, after.alloc - before.alloc, after.mi_alloc - before.mi_alloc)
"""


def test_compiled_ticks_allocate_nothing():
    """No allocation per step: numba's own allocation counters (NUMBA_NRT_STATS, read in a
    fresh interpreter, where they can be switched on) do not move over 620 ticks in blocks of
    200 (vjm run) and of one (the node). They count every array numba creates, and every
    array it wraps when Python hands one over, so a kernel that allocated scratch per call, or
    a caller that passed freshly made arrays, would show here (the pipeline before its state
    vectors were preallocated made 49 per call)."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_NRT_STATS="1")
    out = subprocess.run([sys.executable, "-c", _NO_ALLOCATION], env=env, capture_output=True,
                         text=True, timeout=300, check=True).stdout.split("\n")
    rows = [line.split() for line in out if line.strip()]
    assert [r[0] for r in rows] == ["rk4", "semi_implicit_euler", "implicit_euler"]
    assert all(r[1:] == ["0", "0"] for r in rows), rows
