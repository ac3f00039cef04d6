"""The compile server (:mod:`vjm_ros.jit.compile_server`): one at a time on a machine, detached from
the run that started it, finishing what it was asked for after that run has ended.

Oracles: the process table (``/proc``: which compile servers run with a given numba cache, their
sessions), the compile lock as the kernel holds it (``flock``), and numba's cache files. The fast
tests compile a toy function whose module waits at import for a *gate* file: the server holds
the lock for as long as the test keeps the gate shut, so that "a second run while the first
compiles" is a state the test sets up, not a race it hopes to win. Every run here has a
``NUMBA_CACHE_DIR`` of its own (an empty cache, as after an install), never the shared one.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytest.importorskip("numba")

HANG_GUARD = 120.0
"""Wall-clock limit of each wait here, s: a hang guard, not a speed assertion (the toy compiles
in about a second; numba's import in a fresh process takes one or two more)."""

TOY = textwrap.dedent('''
    import os
    import time

    from vjm_ros.jit import jit

    while not os.path.exists(os.environ["VJM_TEST_GATE"]):  # the test opens the gate
        time.sleep(0.02)


    @jit
    def twice(x):
        return 2.0 * x
''')

RUN = textwrap.dedent('''
    import sys, time
    from vjm_ros.jit import compile_server
    server = compile_server.server()
    server.request("toy", "twice", (1.0,))
    print(server.pid, flush=True)
    time.sleep(float(sys.argv[1]))
''')
"""A run as far as the compile server sees one: it asks for the toy, prints its server's pid
(``None``: another process holds the lock), lives ``argv[1]`` s more, and exits."""


def servers_of(cache: Path) -> list[int]:
    """Compile servers running with numba's cache in ``cache``."""
    found = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes()
            env = (proc / "environ").read_bytes()
        except OSError:
            continue
        if b"vjm_ros.jit.compile_server" in cmd and f"NUMBA_CACHE_DIR={cache}\0".encode() in env:
            found.append(int(proc.name))
    return found


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie counts as gone)."""
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def wait_until(condition, what: str) -> None:
    deadline = time.monotonic() + HANG_GUARD  # hang guard
    while not condition():
        assert time.monotonic() < deadline, f"gave up waiting: {what}"
        time.sleep(0.05)


def reap(cache: Path) -> None:
    """Stop the compile servers this test started (by pid) and wait until they are gone."""
    for pid in servers_of(cache):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    wait_until(lambda: not servers_of(cache), "compile servers killed")


@pytest.fixture
def toy(tmp_path):
    """Environment of a run with an empty numba cache and the gated toy importable; yields
    ``(env, cache, gate)`` and reaps the servers left at the end."""
    (tmp_path / "toy.py").write_text(TOY)
    cache, gate = tmp_path / "cache", tmp_path / "gate"
    cache.mkdir()
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "VJM_TEST_GATE": str(gate),
           "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}
    env.pop("VJM_TIERED", None)
    try:
        yield env, cache, gate
    finally:
        gate.touch()
        reap(cache)


def start_run(env: dict, lives: float = 0.0) -> subprocess.Popen:
    """:data:`RUN` in a session of its own (so that its group can be signalled)."""
    return subprocess.Popen([sys.executable, "-c", RUN, str(lives)], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)


def lock_of(cache: Path):
    from vjm_ros.jit.compile_server import LOCK_NAME, CompileLock

    (path,) = cache.glob(f"*/{LOCK_NAME}")
    return CompileLock(path)


def test_two_runs_at_once_start_one_server_that_outlives_them(toy):
    env, cache, gate = toy
    # each lives a second after its request: the pid the lock file names is written by then
    runs = [start_run(env, lives=1.0), start_run(env, lives=1.0)]
    said = [run.communicate(timeout=HANG_GUARD) for run in runs]  # hang guard
    assert [run.returncode for run in runs] == [0, 0], said
    pids = sorted(out.split()[-1] for out, _ in said)
    server = servers_of(cache)
    assert len(server) == 1, said  # one compiler for the two runs
    (pid,) = server
    assert pids == sorted(["None", str(pid)])  # the second run found the lock held and started none
    assert os.getsid(pid) == pid and os.getpgid(pid) == pid  # a session and group of its own
    notes = sorted(line for _, err in said for line in err.splitlines() if "vjm:" in line)
    assert len(notes) == 2, said  # once each
    assert notes[0].startswith(f"vjm: another process (pid {pid}) is compiling the kernels")
    assert notes[1].startswith(f"vjm: compiling the kernels goes on in the background (pid {pid}")
    assert all("`python -m vjm_ros.app.precompile` compiles them now" in n for n in notes)
    acquired, fd = lock_of(cache).try_acquire()
    assert not acquired and fd is None  # it holds the lock while it compiles

    gate.touch()  # both runs have ended: the server finishes the toy, then exits
    wait_until(lambda: not alive(pid), "the server's exit")
    assert list(cache.rglob("toy.twice-*.nbi")), "the toy is in numba's cache"
    acquired, fd = lock_of(cache).try_acquire()
    assert acquired and fd is not None  # and the lock is free
    os.close(fd)
    log = (lock_of(cache).path.parent / "vjm-compile.log").read_text()
    assert "toy.twice: ok" in log and "done" in log


@pytest.mark.slow  # two rounds of a run and a compile (about 9 s)
def test_signals_to_the_runs_group_leave_the_server_compiling(toy):
    """Ctrl-C or SIGTERM to the run's process group (a terminal, a launcher) ends the run and not
    the server, which compiles what it was asked for after the run has gone."""
    env, cache, gate = toy
    for number in (signal.SIGINT, signal.SIGTERM):
        run = start_run(env, lives=HANG_GUARD)
        pid = int(run.stdout.readline())
        os.killpg(run.pid, number)
        run.communicate(timeout=HANG_GUARD)  # hang guard
        assert run.returncode == -number  # killed by it (the script does not handle it)
        time.sleep(0.3)  # a server that died with the run would be gone by now
        assert alive(pid) and servers_of(cache) == [pid]
        gate.touch()
        wait_until(lambda: not alive(pid), "the server's exit")  # noqa: B023
        gate.unlink()
        assert list(cache.rglob("toy.twice-*.nbi"))
        for path in cache.rglob("toy.twice-*"):
            path.unlink()  # the next round compiles again


@pytest.mark.slow  # two servers, one killed mid-compile (about 3 s)
def test_a_killed_server_leaves_no_stale_lock(toy):
    """The lock is the kernel's ``flock``: a server killed while it compiles holds it no longer,
    and the next run starts a server of its own at once, whatever the lock file still says."""
    env, cache, gate = toy
    run = start_run(env)
    out, _ = run.communicate(timeout=HANG_GUARD)  # hang guard
    first = int(out.split()[-1])
    os.kill(first, signal.SIGKILL)
    wait_until(lambda: not alive(first), "the killed server's exit")
    assert lock_of(cache).holder() == first  # the file still names it
    run = start_run(env)
    out, err = run.communicate(timeout=HANG_GUARD)  # hang guard
    second = int(out.split()[-1])
    assert second != first and alive(second), err
    gate.touch()
    wait_until(lambda: not alive(second), "the second server's exit")
    assert list(cache.rglob("toy.twice-*.nbi"))


def test_a_foreground_compile_waits_for_the_server(toy):
    """``holding_lock`` (what ``python -m vjm_ros.app.precompile`` compiles under) waits for a
    server that compiles, says so, and holds the lock itself afterwards."""
    env, cache, gate = toy
    out, _ = start_run(env).communicate(timeout=HANG_GUARD)  # hang guard
    pid = int(out.split()[-1])
    script = ("import os\nfrom vjm_ros.jit import compile_server\n"
              "with compile_server.holding_lock(lambda text: print(text, flush=True)):\n"
              "    print('held', os.getpid(), flush=True)\n"
              "    input()\n")
    foreground = subprocess.Popen([sys.executable, "-c", script], env=env, text=True,
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        said = foreground.stdout.readline()
        assert said.startswith(f"waiting for the compile in the background (pid {pid}")
        gate.touch()
        assert foreground.stdout.readline().split() == ["held", str(foreground.pid)]
        wait_until(lambda: not alive(pid), "the server's exit")  # it let go as it exited
        assert lock_of(cache).holder() == foreground.pid
        assert lock_of(cache).try_acquire() == (False, None)
        foreground.communicate("\n", timeout=HANG_GUARD)  # hang guard
    finally:
        foreground.kill()
        foreground.wait()
    assert foreground.returncode == 0


def test_compile_server_reports_a_failure(tmp_path, monkeypatch):
    """A request the server cannot compile is answered with the reason, not left waiting."""
    from vjm_ros.jit.compile_server import CompileServer

    monkeypatch.setattr("vjm_ros.jit.compile_server.CompileLock.here",
                        classmethod(lambda cls: cls(tmp_path / "lock")))
    server = CompileServer()
    try:
        number = server.request("vjm_ros.core.kernels", "no_such_kernel", (1.0,))
        assert server.wait(number, timeout=HANG_GUARD)  # hang guard
        assert server._answers[number].startswith(f"error {number} AttributeError")
    finally:
        server.stop()
    assert server._process.poll() is not None
    assert "no_such_kernel: error" in (tmp_path / "vjm-compile.log").read_text()


@pytest.mark.slow  # a real vjm run and a cold compile (about 6 s)
def test_a_stopped_vjm_run_leaves_its_server_compiling(tmp_path):
    """``vjm run`` stopped by SIGTERM to its process group (exit 143, outputs written) while its
    server compiles: the server goes on, in a session of its own, and the run names it, once."""
    cache = tmp_path / "cache"
    cache.mkdir()
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env.pop("VJM_TIERED", None)
    run = subprocess.Popen([sys.executable, "-m", "vjm_ros.app.cli", "run", "five_bar",
                            "--duration", "600", "--out", str(tmp_path / "out")], env=env,
                           text=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                           start_new_session=True)
    try:
        first = run.stderr.readline()  # said after its request went to the server
        assert "not in numba's cache yet" in first
        os.killpg(run.pid, signal.SIGTERM)
        _, said = run.communicate(timeout=HANG_GUARD)  # hang guard
        assert run.returncode == 143, said
        (pid,) = servers_of(cache)
        assert alive(pid) and os.getsid(pid) == pid
        assert said.count(f"compiling the kernels goes on in the background (pid {pid}") == 1
        assert (tmp_path / "out" / "summary.json").exists()
    finally:
        run.kill()
        run.wait()
        reap(cache)


def _vjm(args, cache: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env.pop("VJM_TIERED", None)
    return subprocess.run([sys.executable, "-m", "vjm_ros.app.cli", *args], env=env,
                          capture_output=True, text=True, timeout=600, check=True)


@pytest.mark.slow  # the compile of the four-bar's block pipeline: 20-60 s on this machine
def test_a_short_run_leaves_the_cache_filled_for_the_next(tmp_path):
    """An empty cache (after a pip or colcon install): a one-second run ends long before the
    compile, and leaves its server compiling; once that is done, the next run loads the compiled
    code (no note of plain Python, no server) and writes what the first run wrote."""
    cache = tmp_path / "cache"
    cache.mkdir()
    args = ["run", "four_bar", "--duration", "1", "--out"]
    try:
        first = _vjm([*args, str(tmp_path / "first")], cache)
        assert "not in numba's cache yet" in first.stderr
        (pid,) = servers_of(cache)
        assert f"goes on in the background (pid {pid}" in first.stderr
        deadline = time.monotonic() + 600.0  # hang guard
        while alive(pid):
            assert time.monotonic() < deadline
            time.sleep(0.5)
        names = " ".join(p.name for p in cache.rglob("*.nbi"))
        assert "pipeline.advance_ticks-" in names and "float_text._csv-" in names
        second = _vjm([*args, str(tmp_path / "second")], cache)
        assert "numba" not in second.stderr and "background" not in second.stderr
        assert servers_of(cache) == []
        assert ((tmp_path / "first" / "trajectory.csv").read_bytes()
                == (tmp_path / "second" / "trajectory.csv").read_bytes())
    finally:
        reap(cache)
