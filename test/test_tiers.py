"""Tiered start (:mod:`vjm_ros.jit.tiers`): plain Python while numba compiles in the background.

Oracle: the compiled kernels themselves. The plain copies are the same source run by CPython, and
numba compiles without fast-math, so every operation rounds the same way: the outputs must be
bit-identical (tolerance 0; a difference means some expression rounds differently in the two,
such as ``x ** 2``, which CPython computes with ``pow``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import FIXED_STEP_SETTINGS
from test_compile_server import reap, servers_of

from vjm_ros.core import pipeline
from vjm_ros.jit import tiers
from vjm_ros.scene.generated import star_scene
from vjm_ros.scene.loader import load_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator

pytest.importorskip("numba")

SCENES = ["four_bar", "six_bar", "double_slider", "five_bar", "three_chain", "star_6"]
"""The thesis scenes, and six chains on one pin (the hub solves)."""
METHODS = FIXED_STEP_SETTINGS
TICKS = 45
"""Three calls of :data:`vjm_ros.core.mechanism.PLAIN_PART_TICKS` ticks (the last one short)."""


class _Only(tiers.Tiered):
    """An entry point always compiled (``ready``) or always plain Python."""

    def __init__(self, compiled, ready: bool):
        self.compiled = compiled
        self._always = ready
        self._request = None
        self.function = compiled if ready else tiers.interpreted(compiled)

    @property
    def ready(self) -> bool:
        return self._always

    def __call__(self, *args):
        return self.function(*args)


def _simulator(sc, settings) -> Simulator:
    sim = Simulator(sc.model, SimulationSettings(check_stiffness=False, **settings), sc.gains)
    if sc.model.actuators:
        sim.set_efforts([a.effort for a in sc.model.actuators])
    return sim


@pytest.mark.parametrize("settings", METHODS, ids=lambda s: "-".join(map(str, s.values())))
@pytest.mark.parametrize("scene", SCENES)
def test_plain_copy_computes_the_same_bits(scene, settings, monkeypatch):
    monkeypatch.setenv(tiers.ENVIRONMENT, "0")  # no compile server: compiled here if need be
    sc = star_scene(6) if scene == "star_6" else load_scene(scene)
    compiled, plain = _simulator(sc, settings), _simulator(sc, settings)
    for sim, ready in ((compiled, True), (plain, False)):
        mech = sim.mechanism
        step, advance = mech.entry_points
        mech._advance_ticks = _Only(advance, ready)
        mech._step = _Only(step, ready)
        assert sim.blocks_compiled()
    blocks = [SampleBlock(sc.model, TICKS) for _ in range(2)]
    compiled.advance_block(blocks[0], TICKS)
    plain.advance_block(blocks[1], TICKS)
    assert blocks[0].rows == blocks[1].rows == TICKS
    for a, b in zip(blocks[0].arrays, blocks[1].arrays, strict=True):
        np.testing.assert_array_equal(a, b)
    # the tick-by-tick entry point too: one evaluation at the last state
    q, qd = blocks[0].q[-1], blocks[0].qd[-1]
    np.testing.assert_array_equal(compiled.mechanism.accelerations(q, qd, compiled.tau),
                                  plain.mechanism.accelerations(q, qd, plain.tau))


def test_plain_copy_reaches_every_compiled_callee():
    """Nothing in the plain copy of the pipeline calls a compiled function (which would compile
    it in this process, the very wait the plain tier is there to avoid), whether the copy was
    made before numba was imported (the callees deferred) or after (numba's dispatchers)."""
    from vjm_ros.jit.deferred import is_compiled

    seen, todo = set(), [tiers.interpreted(pipeline.advance_ticks_with_hub)]
    copies = {id(f) for f in tiers._PLAIN.values()}
    while todo:
        fn = todo.pop()
        if id(fn) in seen:
            continue
        seen.add(id(fn))
        for name in fn.__code__.co_names:
            value = fn.__globals__.get(name)
            assert not is_compiled(value), f"{fn.__qualname__} calls compiled {name}"
            if isinstance(value, tiers._Namespace):
                for attr in value._names.values():
                    assert not is_compiled(attr)
                    if id(attr) in copies:
                        todo.append(attr)
            elif id(value) in copies:
                todo.append(value)
    assert len(seen) > 10  # step, terms, the solves, ...


def _vjm(args, cache: Path | None, **env):
    environ = dict(os.environ, **env)
    environ.pop(tiers.ENVIRONMENT, None)  # other tests' studies switch the tier off
    if cache is not None:
        environ["NUMBA_CACHE_DIR"] = str(cache)
    return subprocess.run([sys.executable, "-m", "vjm_ros.app.cli", *args], env=environ,
                          capture_output=True, text=True, timeout=600, check=True)


@pytest.fixture(scope="module")
def warm_run(tmp_path_factory) -> tuple[Path, str]:
    """``vjm run five_bar --duration 0.1 --out DIR`` with numba's cache as the suite has it
    (filled by this run where it is cold: the kernels, the pipeline and the CSV writer): its
    output folder and its stderr. Shared by the tests that only read it or need the cache
    filled."""
    out = tmp_path_factory.mktemp("tiers") / "warm"
    said = _vjm(["run", "five_bar", "--duration", "0.1", "--out", str(out)], None).stderr
    return out, said


def test_cold_run_writes_what_a_compiled_run_writes(tmp_path, warm_run):
    """An empty numba cache: ``vjm run`` starts as plain Python with a compile server beside it,
    writes the same files as with the kernels compiled, and leaves the server compiling in a
    session of its own, which it names on stderr (reaped here: the slow
    ``test_compile_server.py`` test lets one finish)."""
    cache = tmp_path / "cache"
    cache.mkdir()
    cold = tmp_path / "cold"
    try:
        said = _vjm(["run", "five_bar", "--duration", "0.1", "--out", str(cold)], cache).stderr
        assert "not in numba's cache yet" in said  # the user is told why the run is slow
        (pid,) = servers_of(cache)  # the run has ended; its server has not
        assert os.getsid(pid) == pid
        assert said.count(f"compiling the kernels goes on in the background (pid {pid}") == 1
    finally:
        reap(cache)
    warm, said = warm_run  # the same run with the suite's cache
    assert "numba" not in said
    assert (cold / "trajectory.csv").read_bytes() == (warm / "trajectory.csv").read_bytes()
    keys = ("max_closure_error", "energy_drift", "finite", "samples")
    a, b = (json.loads((d / "summary.json").read_text()) for d in (cold, warm))
    assert {k: a.get(k) for k in keys} == {k: b.get(k) for k in keys}


def test_switched_off_by_the_environment(monkeypatch):
    """``VJM_TIERED=0`` (and :func:`~vjm_ros.jit.tiers.compile_first`, which the benchmarks
    call) compiles before the first call."""
    monkeypatch.delenv(tiers.ENVIRONMENT, raising=False)
    assert tiers.enabled()
    monkeypatch.setenv(tiers.ENVIRONMENT, "0")
    assert not tiers.enabled()
    monkeypatch.setenv(tiers.ENVIRONMENT, "1")
    tiers.compile_first()
    assert not tiers.enabled()


def _evaluate_args(scene: str) -> tuple:
    """Arguments of one evaluation by :func:`vjm_ros.core.kernels.step` of ``scene`` at rest."""
    from vjm_ros.core import kernels
    from vjm_ros.core.mechanism import Mechanism

    m = Mechanism.reader(load_scene(scene).model)
    q, qd = m.model.initial_state()
    return (kernels.EVALUATE, q, qd, np.zeros(m.n), 0.0, 1, 0.0, tuple(m.packed),
            tuple(m.new_data()), np.empty(m.n), np.empty(m.n), kernels.NO_KNOWN, -1)


def test_the_first_calls_run_plain_without_loading_the_compiled_code(monkeypatch):
    """``plain_calls``: the first calls run the plain copy and load nothing; the next one loads
    the compiled code; the outputs are the same bits. :meth:`~vjm_ros.jit.tiers.Tiered.eager`
    ends the plain calls at once, and with the tiers switched off there are none."""
    from vjm_ros.core import kernels

    args = _evaluate_args("five_bar")
    kernels.step(*args)  # compiled in this process (or loaded): loading below finds it at once
    expected = [a.copy() for a in args[-4:-2]]
    loads = []
    real = tiers.load_cached
    monkeypatch.setattr(tiers, "load_cached", lambda d, a: loads.append(d) or real(d, a))
    monkeypatch.setenv(tiers.ENVIRONMENT, "1")

    def outputs_of(entry):
        entry(*args)
        return [a.copy() for a in args[-4:-2]]

    entry = tiers.Tiered(kernels, "step", plain_calls=2)
    for _ in range(2):
        assert [o.tobytes() for o in outputs_of(entry)] == [o.tobytes() for o in expected]
        assert loads == [] and entry.tier == "new"
    assert [o.tobytes() for o in outputs_of(entry)] == [o.tobytes() for o in expected]
    assert loads == [kernels.step] and entry.tier == "compiled"

    eager = tiers.Tiered(kernels, "step", plain_calls=2)
    eager.eager()
    outputs_of(eager)
    assert eager.tier == "compiled" and len(loads) == 2
    monkeypatch.setenv(tiers.ENVIRONMENT, "0")
    off = tiers.Tiered(kernels, "step", plain_calls=2)
    outputs_of(off)
    assert off.tier == "compiled" and off._plain is None  # the compiled code ran at once


def test_a_run_in_blocks_never_loads_the_kernel(tmp_path):
    """A tiered ``vjm run`` builds its simulator and ticks without loading the kernel from
    numba's cache (0.05-0.1 s of its start): its few evaluations outside the block pipeline run
    as plain Python. The pipeline itself is loaded, or compiled in the background."""
    script = (
        "from vjm_ros.core import kernels\n"
        "from vjm_ros.scene.loader import load_scene\n"
        "from vjm_ros.sim.settings import resolve_settings\n"
        "from vjm_ros.sim.simulator import SampleBlock, Simulator\n"
        "sc = load_scene('four_bar')\n"
        "sim = Simulator(sc.model, resolve_settings(sc.defaults, sc.gains), sc.gains)\n"
        "sim.blocks_compiled()\n"
        "block = SampleBlock(sc.model, 10)\n"
        "sim.advance_block(block, 10)\n"
        "sim.sample()\n"
        "print(len(kernels.step.overloads), sim.mechanism._step.tier)\n")
    env = {**os.environ, tiers.ENVIRONMENT: "1"}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=600, env=env, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["0", "new"]


def test_a_short_run_never_imports_numba(tmp_path, warm_run):
    """numba's cache filled: a run shorter than the pipeline's first call as plain Python (and its
    CSV shorter than :data:`~vjm_ros.sim.trajectory.CSV_PLAIN_ROWS`) ends without importing numba
    (0.3-0.4 s with the loading of the pipeline), and writes the same files as the same run
    compiled first; a longer run imports it after its first ticks and runs compiled."""
    from vjm_ros.core.mechanism import PLAIN_PART_TICKS

    script = (
        "import sys\n"
        "from vjm_ros.app.cli import main\n"
        "code = main(['run', 'five_bar', '--duration', sys.argv[2], '--out', sys.argv[1]])\n"
        "from vjm_ros.jit import deferred as jit\n"
        "print(code, 'numba' in sys.modules, jit.active())\n")

    def run(folder: Path, seconds: float, tiered: str) -> list[str]:
        env = {**os.environ, tiers.ENVIRONMENT: tiered}
        done = subprocess.run([sys.executable, "-c", script, str(folder), str(seconds)],
                              capture_output=True, text=True, timeout=600, env=env)
        assert done.returncode == 0, done.stderr[-2000:]
        return done.stdout.split()[-3:]

    # warm_run has filled the cache where it was cold
    short = (PLAIN_PART_TICKS // 2) / 1000.0  # five_bar runs at 1 kHz
    assert run(tmp_path / "plain", short, "1") == ["0", "False", "False"]
    assert run(tmp_path / "compiled", short, "0") == ["0", "True", "True"]
    assert run(tmp_path / "longer", 0.1, "1") == ["0", "True", "True"]
    for name in ("trajectory.csv", "summary.json"):
        plain, compiled = ((tmp_path / d / name).read_bytes() for d in ("plain", "compiled"))
        if name == "summary.json":  # the run's cost differs; everything else is the same
            cost = ("wall_time", "cpu_time", "outputs_wait_time", "realtime_factor")
            plain, compiled = ({k: v for k, v in json.loads(x).items() if k not in cost}
                               for x in (plain, compiled))
        assert plain == compiled, name


def test_with_the_tiers_off_the_csv_writer_is_loaded_before_the_run(warm_run):
    """``VJM_TIERED=0`` (what the benchmarks set): preparing an entry point loads its compiled
    code from numba's cache then and there, as with the tiers on. Before, it only marked it
    ready, and ``vjm run --out`` loaded the CSV writer at its first table, in the CSV's thread
    and inside the run's ``wall_time`` (150 ms of a 10 s four-bar run with all three logs)."""
    # warm_run (a run with --out) has put the CSV writer in numba's cache where it was cold
    script = ("from vjm_ros.sim import float_text, trajectory\n"
              "trajectory.prepare_csv_writer(10**6)\n"
              "print(len(float_text._csv.overloads))\n")
    environ = dict(os.environ, **{tiers.ENVIRONMENT: "0"})
    done = subprocess.run([sys.executable, "-c", script], env=environ, capture_output=True,
                          text=True, timeout=600, check=True)
    assert done.stdout.split()[-1] == "1", done.stdout + done.stderr  # loaded, none called


def test_with_numbas_jit_disabled_a_run_is_plain_python(tmp_path):
    """``NUMBA_DISABLE_JIT=1`` (numba's switch for debugging kernels in Python): the compiled
    functions are the plain ones once numba is imported, the tiers load nothing, and the run
    writes what the compiled run writes."""
    plain, compiled = tmp_path / "plain", tmp_path / "compiled"
    args = ["run", "four_bar", "--duration", "0.05", "--out"]
    _vjm([*args, str(plain)], None, NUMBA_DISABLE_JIT="1")
    _vjm([*args, str(compiled)], None)
    assert (plain / "trajectory.csv").read_bytes() == (compiled / "trajectory.csv").read_bytes()


@pytest.mark.slow
def test_cold_run_switches_to_compiled_code(tmp_path):
    """A cold run long enough for the compile server to finish (600 simulated s: the compile
    takes 30-60 s here, during which plain Python covers 45-90 s of them): the kernel and the
    pipeline land in numba's cache, and the run ends as a compiled run does."""
    cache = tmp_path / "cache"
    cache.mkdir()
    args = ["run", "four_bar", "--duration", "600", "--json"]
    cold = json.loads(_vjm(args, cache).stdout.strip().splitlines()[-1])
    names = " ".join(p.name for p in cache.rglob("*.nbi"))
    assert "kernels.step-" in names and "pipeline.advance_ticks-" in names
    warm = json.loads(_vjm(args, None).stdout.strip().splitlines()[-1])
    for key in ("max_closure_error", "rms_closure_error", "energy_drift", "finite", "samples"):
        assert cold.get(key) == warm.get(key), key
