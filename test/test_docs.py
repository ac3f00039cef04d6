"""Every fenced code block of the docs runs, so that a doc that goes stale fails the suite.

Each fence in ``README.md``, ``CONTRIBUTING.md`` and ``docs/*.md`` carries an info string that
says what it holds (CONTRIBUTING.md, "Code blocks in the docs"), and is handled accordingly:

* ``python``: a program, run as a script in a fresh directory;
* ``bash``: commands, each run with ``bash -c`` in a fresh directory (one per block) holding links
  to the checkout's ``.venv``, ``config`` and ``examples``, with ``.venv/bin`` first on ``PATH``,
  ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and this process's own ``ROS_DOMAIN_ID``
  (``conftest.py``); ``export NAME=VALUE`` carries on to the block's later commands, and
  ``COMMAND &`` runs beside the command after it;
* ``console``: the same for its ``$ `` lines; the other lines are their output, compared with
  numbers masked;
* ``yaml scene`` and ``yaml sweep-spec``: loaded and validated by the project's own loaders;
* ``text check:NAME``: program output (or a control law) that ``CHECKS[NAME]`` produces for real
  and compares with the block;
* ``text paths``: a package map or diagram: every path it names exists.

A command that cannot run as written here (it never ends, takes minutes, or needs what this
machine lacks) is declared in ``COMMANDS`` (a program in ``PROGRAMS``) with what runs instead and
why; everything else runs as written. A fence without one of these info strings fails, and so
does a declaration or a check that no block uses any more. Every wall-clock timeout here is a
hang guard, never a speed requirement.
"""

from __future__ import annotations

import ast
import importlib.util
import json
import re
import shlex
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from doc_blocks import (
    HANG_GUARD,
    ROOT,
    SETUP_GUARD,
    VENV_BIN,
    Block,
    background,
    command_env,
    commands,
    console_commands,
    doc_blocks,
    finish,
    foreground,
    key,
    masked,
    named_paths,
    start,
    stop,
)
from doc_checks import CHECKS

BLOCKS = doc_blocks()


def of_kind(*kinds: str) -> list[Block]:
    return [b for b in BLOCKS if b.kind in kinds]


def params(blocks: list[Block]) -> list:
    return [pytest.param(b, id=b.id) for b in blocks]


# ------------------------------------------------------------------------------ declarations
@dataclass(frozen=True)
class Run:
    """How one documented command runs here.

    ``command`` runs instead of the doc's (``None``: the doc's, as written; ``{scheduler}`` is
    replaced by the address of a Dask scheduler started for it), for the reason ``why``.
    ``where``: ``tmp`` (the block's fresh directory), ``repo`` (the checkout: commands that act
    on it and write nothing into it) or ``clone`` (a fresh ``git clone`` of the checkout's last
    commit). ``before`` sets the stage in the same directory (a shell command, or a function of
    the directory); ``after(directory, output)`` checks what the command did; ``until_sigint``:
    the command runs until SIGINT and gets it once the command beside it has ended.
    """

    command: str | None = None
    why: str = ""
    slow: bool = False
    where: str = "tmp"
    before: str | Callable[[Path], None] | None = None
    after: Callable[[Path, str], None] | None = None
    until_sigint: bool = False
    timeout: float = HANG_GUARD


@dataclass(frozen=True)
class SyntaxOnly:
    """A command that must not run here, for the reason ``why``: ``bash -n`` checks it, and
    the programs it calls (``tools``) must exist."""

    why: str
    tools: tuple[str, ...]


def outputs_of_quick_start(cwd: Path, out: str) -> None:
    run = cwd / "runs" / "four_bar"
    summary = json.loads((run / "summary.json").read_text())
    assert summary["scene"] == "four_bar" and summary["finite"], summary
    assert (run / "trajectory.csv").stat().st_size > 0
    assert list(run.glob("*.png")), f"no figures in {run}: {sorted(run.iterdir())}"


def file_written(name: str) -> Callable[[Path, str], None]:
    def check(cwd: Path, out: str) -> None:
        assert (cwd / name).is_file() and (cwd / name).stat().st_size > 0, out
    return check


def prints_the_topics(cwd: Path, out: str) -> None:
    counts = ast.literal_eval(out.strip().splitlines()[-1])
    assert counts["/joint_states"] > 0 and counts["/clock"] > 0, out


def results_rows(out_dir: str) -> Callable[[Path, str], None]:
    def check(cwd: Path, out: str) -> None:
        rows = (cwd / out_dir / "results.csv").read_text().splitlines()
        assert len(rows) > 1, out
    return check


def sweep_spec_of_the_docs(cwd: Path) -> None:
    """``spec.yaml``: the spec that docs/sweeps.md shows."""
    (block,) = [b for b in BLOCKS if b.kind == "yaml sweep-spec"]
    (cwd / "spec.yaml").write_text(block.text)


FULL_SUITE = ("collection only: the default suite runs this very command in CI and takes minutes; "
              "collecting checks the command, the configuration and every test module's imports")
NODE_DURATION = "the node runs until SIGINT without a duration: 1 s of simulated time here"
SIGINT_END = "runs until SIGINT: stopped with SIGINT once the simulator it drives has ended"
NO_VIEWERS = ("robot_state_publisher, RViz and foxglove_bridge come with a ROS 2 install, not "
              "with the ROS 2 wheels of .venv (rclpy and message packages only), and the viewers "
              "need a display")
SET_UP = "set-up from nothing, in a fresh clone (never the shared .venv); minutes of downloads"

COMMANDS: dict[str, tuple[Run | SyntaxOnly, ...]] = {
    # README.md
    "bash scripts/setup && ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST .venv/bin/vjm run four_bar "
    "--out runs/four_bar --plots": (
        Run("ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST .venv/bin/vjm run four_bar --out runs/four_bar "
            "--plots --duration 0.5",
            why="the set-up is the slow case below; 0.5 s of the scene's 10 s",
            after=outputs_of_quick_start),
        Run(why=SET_UP, slow=True, where="clone", after=outputs_of_quick_start,
            timeout=SETUP_GUARD),
    ),
    "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST .venv/bin/python -m pytest -q": (
        Run("ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST .venv/bin/python -m pytest -q "
            "--collect-only", why=FULL_SUITE, slow=True, where="repo", timeout=600.0),
    ),
    ".venv/bin/vjm_sim_node --ros-args -p scene:=five_bar -p duration:=5.0": (
        Run(".venv/bin/vjm_sim_node --ros-args -p scene:=five_bar -p duration:=0.2",
            why="0.2 s of the 5 s run; slow: the default suite starts and ends the node with the "
                "params file's run below", slow=True),
    ),
    ".venv/bin/vjm_sim_node --ros-args --params-file config/sim_node.yaml -p mcap:=run.mcap": (
        Run(".venv/bin/vjm_sim_node --ros-args --params-file config/sim_node.yaml "
            "-p mcap:=run.mcap -p duration:=0.2",
            why="the file's duration 0 runs until SIGINT: 0.2 s here",
            after=file_written("run.mcap")),
    ),
    ".venv/bin/vjm_sim_node --ros-args -p scene:=five_bar -p wait_for_command:=true &": (
        Run(".venv/bin/vjm_sim_node --ros-args -p scene:=five_bar -p wait_for_command:=true "
            "-p duration:=1.0", why=NODE_DURATION, slow=True),
    ),
    ".venv/bin/vjm_pd_controller": (Run(why=SIGINT_END, slow=True, until_sigint=True),),
    ".venv/bin/vjm_sim_node --ros-args -r __ns:=/robot1 -p scene:=five_bar -p duration:=5.0 &": (
        Run(".venv/bin/vjm_sim_node --ros-args -r __ns:=/robot1 -p scene:=five_bar "
            "-p duration:=0.2", why="0.2 s of the 5 s, beside the second simulator"),
    ),
    ".venv/bin/vjm_sim_node --ros-args -r __ns:=/robot2 -p scene:=four_bar -p duration:=5.0 "
    "-p publish_clock:=false": (
        Run(".venv/bin/vjm_sim_node --ros-args -r __ns:=/robot2 -p scene:=four_bar "
            "-p duration:=0.2 -p publish_clock:=false", why="0.2 s of the 5 s"),
    ),
    ".venv/bin/vjm_sim_node --ros-args -p scene:=three_chain -p closure:=exact "
    "-p wait_for_command:=true &": (
        Run(".venv/bin/vjm_sim_node --ros-args -p scene:=three_chain -p closure:=exact "
            "-p wait_for_command:=true -p duration:=1.0", why=NODE_DURATION, slow=True),
    ),
    ".venv/bin/vjm_ct_controller --ros-args -p path:=figure8 -p size:=0.2 -p period:=4.0": (
        Run(why=SIGINT_END, slow=True, until_sigint=True),
    ),
    ".venv/bin/python -c \"from rosbags.highlevel import AnyReader; from pathlib import Path\n"
    "with AnyReader([Path('run.mcap')]) as r: print({c.topic: c.msgcount for c in "
    "r.connections})\"": (
        Run(why="run.mcap from `vjm run SCENE --mcap run.mcap`, as the section says",
            before=".venv/bin/vjm run four_bar --duration 0.02 --mcap run.mcap",
            after=prints_the_topics),
    ),
    "ros2 run robot_state_publisher robot_state_publisher --ros-args -p use_sim_time:=true "
    "-p robot_description:=\"$(cat five_bar.urdf)\"": (SyntaxOnly(NO_VIEWERS, tools=()),),
    "rviz2 --ros-args -p use_sim_time:=true": (SyntaxOnly(NO_VIEWERS, tools=()),),
    "ros2 launch foxglove_bridge foxglove_bridge_launch.xml use_sim_time:=true": (
        SyntaxOnly(NO_VIEWERS, tools=()),
    ),
    # CONTRIBUTING.md and docs/troubleshooting.md
    "bash scripts/setup": (Run(why=SET_UP, slow=True, where="clone", timeout=SETUP_GUARD),),
    ".venv/bin/python -m pytest -q": (
        Run(".venv/bin/python -m pytest -q --collect-only", why=FULL_SUITE, slow=True,
            where="repo", timeout=600.0),
    ),
    ".venv/bin/python -m pytest -q test/test_closures.py": (
        Run(why="runs in the checkout; seconds of tests, beyond this file's default share",
            slow=True, where="repo", timeout=600.0),
    ),
    ".venv/bin/ruff check .": (Run(why="checks the checkout itself", where="repo"),),
    "rm -f /dev/shm/fastdds_* /dev/shm/sem.fastdds_*": (
        SyntaxOnly("it would delete the shared memory of every Fast DDS process on this shared "
                   "machine, other people's running nodes included", tools=("rm",)),
    ),
    # docs/controllers.md
    "vjm_sim_node --ros-args -p scene:=five_bar -p closure:=exact -p wait_for_command:=true "
    "-p initial_positions.left_elbow:=1.4 -p initial_positions.right_elbow:=-1.4 &": (
        Run("vjm_sim_node --ros-args -p scene:=five_bar -p closure:=exact "
            "-p wait_for_command:=true -p initial_positions.left_elbow:=1.4 "
            "-p initial_positions.right_elbow:=-1.4 -p duration:=1.0",
            why=NODE_DURATION, slow=True),
    ),
    "vjm_ct_controller --ros-args -p path:=circle -p size:=0.05 -p period:=2.0": (
        Run(why=SIGINT_END, slow=True, until_sigint=True),
    ),
    "vjm_sim_node --ros-args -p scene:=three_chain -p closure:=exact -p wait_for_command:=true &": (
        Run("vjm_sim_node --ros-args -p scene:=three_chain -p closure:=exact "
            "-p wait_for_command:=true -p duration:=1.0", why=NODE_DURATION, slow=True),
    ),
    "vjm_ct_controller --ros-args -p path:=figure8 -p size:=0.2 -p period:=4.0 "
    "-p preload:=20.0": (Run(why=SIGINT_END, slow=True, until_sigint=True),),
    "vjm_sim_node --ros-args -p scene:=five_bar_friction -p wait_for_command:=true &": (
        Run("vjm_sim_node --ros-args -p scene:=five_bar_friction -p wait_for_command:=true "
            "-p duration:=1.0", why=NODE_DURATION, slow=True),
    ),
    "vjm_ct_controller --ros-args -p path:=circle -p size:=0.05 -p period:=2.0 "
    "-p compensate_plant:=true": (Run(why=SIGINT_END, slow=True, until_sigint=True),),
    # docs/sweeps.md
    "vjm sweep examples/sweep_gains.yaml": (
        Run(why="192 runs on a local Dask cluster", slow=True, timeout=900.0,
            after=results_rows("sweep_out/gains_and_rates")),
    ),
    "vjm sweep spec.yaml --workers 2 --out runs/gains": (
        Run(why="spec.yaml: the spec shown in docs/sweeps.md; 192 runs", slow=True,
            before=sweep_spec_of_the_docs, timeout=900.0, after=results_rows("runs/gains")),
    ),
    "vjm sweep spec.yaml --cluster tcp://scheduler:8786": (
        Run("vjm sweep spec.yaml --cluster {scheduler} --out runs/on_cluster",
            why="a Dask scheduler and one worker started here stand in for a cluster's; "
                "spec.yaml as above, results apart from the local runs", slow=True,
            before=sweep_spec_of_the_docs, timeout=900.0, after=results_rows("runs/on_cluster")),
    ),
    "vjm sweep spec.yaml --out runs/gains --resume": (
        Run(why="after the run above (resumed: nothing left to do)", slow=True,
            before=sweep_spec_of_the_docs, timeout=900.0, after=results_rows("runs/gains")),
    ),
    "vjm tune five_bar --integrator semi_implicit_euler --rate 1000 --duration 1": (
        Run(why="a sweep of the gains grid on a local Dask cluster", slow=True, timeout=900.0,
            after=file_written("tune_out/five_bar/gains.yaml")),
    ),
}
"""Documented commands that do not run as written, by their words (``key``)."""

COMMANDS = {key(k): v for k, v in COMMANDS.items()}


@dataclass(frozen=True)
class Unit:
    """What runs as one test: a command, or a background command and the one beside it."""

    block: Block
    commands: tuple[str, ...]
    exports: tuple[tuple[str, str], ...]
    output: tuple[str, ...] = ()  # a console block's output lines


def command_units() -> list[Unit]:
    units = []
    for block in of_kind("bash", "console"):
        if block.kind == "bash":
            listed = [(c, []) for c in commands(block.text)]
        else:
            listed = console_commands(block.text)
        exports: list[tuple[str, str]] = []
        i = 0
        while i < len(listed):
            command, output = listed[i]
            pair = background(command) and i + 1 < len(listed)
            group = (command, listed[i + 1][0]) if pair else (command,)
            units.append(Unit(block, group, tuple(exports), tuple(output)))
            for c in group:
                words = shlex.split(c, comments=True)
                if words[:1] == ["export"]:
                    exports += [tuple(w.split("=", 1)) for w in words[1:] if "=" in w]
            i += len(group)
    return units


UNITS = command_units()


def command_cases() -> list:
    """One case per unit and way of running it, named ``FILE:LINE#K`` (the block's K-th unit,
    from 0; ``/V`` for its V-th way)."""
    cases, index = [], {}
    for unit in UNITS:
        n = index[unit.block.id] = index.get(unit.block.id, -1) + 1
        hows = [COMMANDS.get(key(c), (Run(),)) for c in unit.commands]
        if len(unit.commands) == 1:
            variants = [(how,) for how in hows[0]]
        else:
            assert all(len(h) == 1 for h in hows), f"{unit}: one way each for a pair"
            variants = [tuple(h[0] for h in hows)]
        for v, how in enumerate(variants):
            slow = any(getattr(h, "slow", False) for h in how)
            label = f"{unit.block.id}#{n}" + (f"/{v}" if len(variants) > 1 else "")
            cases.append(pytest.param(unit, how, id=label,
                                      marks=[pytest.mark.slow] if slow else []))
    return cases


# ---------------------------------------------------------------------------- workspaces
_BLOCK_DIRS: dict[str, Path] = {}


@pytest.fixture
def block_dir(tmp_path_factory):
    """A fresh directory per block (its commands share it, in the order of the doc), holding
    links to the checkout's ``.venv``, ``config`` and ``examples``."""

    def make(block: Block) -> Path:
        if block.id not in _BLOCK_DIRS:
            path = tmp_path_factory.mktemp(re.sub(r"\W", "_", block.id))
            for name in (".venv", "config", "examples"):
                (path / name).symlink_to(ROOT / name)
            _BLOCK_DIRS[block.id] = path
        return _BLOCK_DIRS[block.id]

    return make


@pytest.fixture(scope="session")
def fresh_clone(tmp_path_factory):
    """A ``git clone`` of the checkout's last commit, as CI starts from (set up by the first
    ``bash scripts/setup`` run in it)."""
    path = tmp_path_factory.mktemp("clone") / "vjm_ros"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(path)], check=True, timeout=300)
    return path


@pytest.fixture(scope="session")
def dask_scheduler(tmp_path_factory):
    """A Dask scheduler and one single-threaded worker on this host; their address."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    cwd = tmp_path_factory.mktemp("dask")
    env = command_env("tmp")
    procs = [
        start(f"exec dask scheduler --host 127.0.0.1 --port {port} --no-dashboard", cwd, env),
        start(f"exec dask worker {address} --nthreads 1 --no-dashboard", cwd, env),
    ]
    try:
        yield address
    finally:
        for proc in reversed(procs):
            stop(proc, signal.SIGTERM)
            finish(proc, 60.0, "a Dask process")


def workdir(how, unit: Unit, block_dir, request) -> Path:
    where = getattr(how, "where", "tmp")
    if where == "repo":
        return ROOT
    if where == "clone":
        return request.getfixturevalue("fresh_clone")
    return block_dir(unit.block)


# ------------------------------------------------------------------------ command tests
@pytest.mark.parametrize("unit, how", command_cases())
def test_documented_commands_run(unit, how, block_dir, request):
    cwd = workdir(how[-1], unit, block_dir, request)
    env = command_env(getattr(how[-1], "where", "tmp"), dict(unit.exports))
    if isinstance(how[0], SyntaxOnly):
        (command,) = unit.commands
        check = subprocess.run(["bash", "-n", "-c", command], capture_output=True, text=True,
                               timeout=30)
        assert check.returncode == 0, check.stderr
        for tool in how[0].tools:
            assert shutil.which(tool, path=env["PATH"]), f"{tool}: not found"
        return
    run_commands = []
    for command, h in zip(unit.commands, how, strict=True):
        if callable(h.before):
            h.before(cwd)
        elif h.before:
            prep = start(h.before, cwd, env)
            out = finish(prep, HANG_GUARD, h.before)
            assert prep.returncode == 0, f"{h.before}:\n{out}"
        text = h.command or command
        if len(unit.commands) > 1 or background(text):
            text = foreground(text)  # a last `CMD &` of a block runs as the block's end
        if "{scheduler}" in text:
            text = text.replace("{scheduler}", request.getfixturevalue("dask_scheduler"))
        run_commands.append(text)
    if len(unit.commands) == 1:
        (h,) = how
        proc = start(run_commands[0], cwd, env)
        out = finish(proc, h.timeout, run_commands[0])
        assert proc.returncode == 0, f"{run_commands[0]} exited {proc.returncode}:\n{out}"
        if unit.output:
            shown = [masked(line) for line in out.splitlines()]
            for line in unit.output:
                assert masked(line) in shown, f"{line!r} not in the output:\n{out}"
    else:
        out = run_beside(run_commands, how, cwd, env)
    if how[-1].after:
        how[-1].after(cwd, out)


def run_beside(commands_: list[str], how: tuple[Run, Run], cwd: Path, env: dict) -> str:
    """The background command and the one beside it: the first must end by itself; the second
    ends by itself too or, ``until_sigint``, gets SIGINT when the first has ended."""
    first, second = (start(c, cwd, env) for c in commands_)
    end = time.monotonic() + max(h.timeout for h in how)  # a hang guard
    try:
        while first.poll() is None and time.monotonic() < end:
            if second.poll() not in (None, 0):
                break  # the second failed: the first may wait for it forever
            time.sleep(0.05)
        hung = first.poll() is None and second.poll() is None
        stop(first)
        if how[1].until_sigint:
            stop(second)
        out_first = finish(first, 60.0, commands_[0])
        out_second = finish(second, 60.0, commands_[1])
    finally:
        for proc in (first, second):
            stop(proc, signal.SIGKILL)
    outputs = f"--- {commands_[0]}:\n{out_first}\n--- {commands_[1]}:\n{out_second}"
    assert not hung, f"hang guard: still running after {max(h.timeout for h in how):g} s\n{outputs}"
    assert first.returncode == 0 and second.returncode == 0, outputs
    return outputs


# ----------------------------------------------------------------------------- programs
@dataclass(frozen=True)
class NotHere:
    """A program that cannot run on this machine, for the reason ``why``: compiled, and each
    package it imports installed here or named for installation in the text above it."""

    why: str


PROGRAMS: dict[tuple[str, str], NotHere] = {
    ("docs/sweeps.md", "# start_cluster.py: keep it running while sweeps use it"): NotHere(
        "it starts SLURM jobs, and there is no SLURM here (test_slurm_recipe_builds_its_job "
        "checks the cluster's arguments in the slow suite)"),
}
"""Programs of the docs that do not run as written, by their file and first line."""


def program_key(block: Block) -> tuple[str, str]:
    return (block.path, block.text.strip().splitlines()[0])


def program_cases() -> list:
    return [pytest.param(b, id=b.id) for b in of_kind("python")]


@pytest.mark.parametrize("block", program_cases())
def test_documented_programs_run(block, tmp_path):
    how = PROGRAMS.get(program_key(block))
    if how is not None:
        tree = ast.parse(block.text, filename=block.id)  # a syntax error fails here
        compile(tree, block.id, "exec")
        before = block.preceding_text()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else [
                    node.module]
                for name in names:
                    root = name.split(".")[0]
                    assert importlib.util.find_spec(root) or (
                        f"`{root.replace('_', '-')}`" in before), (
                        f"{root}: neither installed here nor named for installation above the "
                        "block")
        return
    (tmp_path / "doc_block.py").write_text(block.text)
    proc = start(f"exec {shlex.quote(str(VENV_BIN / 'python'))} doc_block.py", tmp_path,
                 command_env("tmp"))
    out = finish(proc, HANG_GUARD, block.id)
    assert proc.returncode == 0, f"{block.id} exited {proc.returncode}:\n{out}"


@pytest.mark.slow
def test_slurm_recipe_builds_its_job(tmp_path):
    """The SLURM recipe's cluster, with dask-jobqueue installed apart from the .venv: its
    arguments are accepted and give the job script they ask for (submitting needs SLURM)."""
    (block,) = [b for b in of_kind("python") if program_key(b) in PROGRAMS]
    target = tmp_path / "site"
    pip = subprocess.run([str(VENV_BIN / "python"), "-m", "pip", "install", "-q", "--no-deps",
                          "--target", str(target), "dask-jobqueue"],
                         capture_output=True, text=True, timeout=600)
    assert pip.returncode == 0, pip.stderr
    tree = ast.parse(block.text)
    upto = next(i for i, node in enumerate(tree.body)
                if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call)
                and getattr(node.value.func, "id", "") == "SLURMCluster")
    program = ast.unparse(ast.Module(tree.body[: upto + 1], [])) + (
        "\nprint(cluster.job_script())\ncluster.close()\n")
    (tmp_path / "job.py").write_text(program)
    env = dict(command_env("tmp"), PYTHONPATH=str(target))
    proc = start(f"exec {shlex.quote(str(VENV_BIN / 'python'))} job.py", tmp_path, env)
    out = finish(proc, HANG_GUARD, "the SLURM recipe's cluster")
    assert proc.returncode == 0, out
    assert "#SBATCH --cpus-per-task=1" in out and "#SBATCH -t 02:00:00" in out, out


# ------------------------------------------------------------------------------- yaml
@pytest.mark.parametrize("block", params(of_kind("yaml scene")))
def test_scene_blocks_load(block, tmp_path):
    from vjm_ros.scene.loader import load_scene

    path = tmp_path / "scene.yaml"
    path.write_text(block.text)
    scene = load_scene(str(path))  # validation and assembly: a SceneError names the key
    assert scene.model.joint_names


@pytest.mark.parametrize("block", params(of_kind("yaml sweep-spec")))
def test_sweep_spec_blocks_load(block, tmp_path):
    from vjm_ros.studies.sweep.plan import plan_sweep
    from vjm_ros.studies.sweep.spec import load_spec

    path = tmp_path / "spec.yaml"
    path.write_text(block.text)
    plan_sweep(load_spec(path))  # what `vjm sweep` refuses before any run


@pytest.mark.parametrize("block", params(of_kind("text paths")))
def test_maps_name_existing_paths(block):
    missing = [f"{block.path}:{n}: {path}" for n, path, bases in named_paths(block)
               if not any(list(base.glob(path.rstrip("/"))) for base in bases)]
    assert not missing, "paths named in a map that do not exist:\n" + "\n".join(missing)
    roots = [ROOT / line.split(" ", 1)[0] for line in block.text.splitlines()
             if re.fullmatch(r"[\w-]+/", line.split(" ", 1)[0])]
    for root in roots:
        if (root / "__init__.py").is_file():  # a package: the map lists all its subpackages
            listed = {p for _, p, _ in named_paths(block)}
            absent = [p.name for p in root.iterdir() if (p / "__init__.py").is_file()
                      and f"{p.name}/" not in listed]
            assert not absent, f"{block.id}: subpackages of {root.name} not in the map: {absent}"


def check_name(block: Block) -> str:
    return block.info.split()[1].removeprefix("check:")


@pytest.mark.parametrize("block", params(of_kind("text check")))
def test_output_blocks_are_what_the_programs_print(block, tmp_path):
    assert check_name(block) in CHECKS, f"{block.id}: no check named {check_name(block)!r}"
    CHECKS[check_name(block)](block, tmp_path)


# ------------------------------------------------------------------------------ the convention
def test_every_block_has_a_handled_info_string():
    """A new block must say what it is, with an info string this file handles."""
    bad = [f"{b.id}: ```{b.info}" for b in BLOCKS if b.kind == "unhandled"]
    assert not bad, ("blocks without a handled info string (CONTRIBUTING.md, 'Code blocks in "
                     "the docs'):\n" + "\n".join(bad))


def test_every_declaration_is_used():
    """Declarations and checks that no block needs any more go (they would hide a change)."""
    used = {key(c) for unit in UNITS for c in unit.commands}
    assert not set(COMMANDS) - used, f"declared commands the docs no longer hold: " \
        f"{sorted(set(COMMANDS) - used)}"
    programs = {program_key(b) for b in of_kind("python")}
    assert not set(PROGRAMS) - programs, sorted(set(PROGRAMS) - programs)
    names = [check_name(b) for b in of_kind("text check")]
    assert sorted(names) == sorted(CHECKS), f"checks used {sorted(names)}, defined {sorted(CHECKS)}"
    for hows in COMMANDS.values():
        for how in hows:
            assert how.why or (isinstance(how, Run) and how.command is None
                               and how.where == "tmp" and not how.slow), how
