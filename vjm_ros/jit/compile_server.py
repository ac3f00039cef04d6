"""The compile server: a process that compiles entry points into numba's cache, one at a time on
a machine, and finishes what it was asked for after the run that asked has ended.

:mod:`vjm_ros.jit.tiers` hands it the entry points numba's cache lacks (a first run after a pip
or colcon install, an edit of a compiled source, a new ``NUMBA_CACHE_DIR``) while the run goes on
as plain Python. The process (``python -m vjm_ros.jit.compile_server``) is detached from the
run: a session and process group of its own (Ctrl-C or SIGTERM to the run's group does not reach
it; it ignores SIGINT and SIGHUP), working directory the folder the package is imported from,
stdin and stdout private pipes to the run (requests and answers), stderr the log file
:data:`LOG_NAME` in numba's cache directory. When the run ends, or is killed, before the compile
is done, the process compiles every request it has received and then exits, and the run says so
on stderr: a run shorter than the compile leaves the cache filled for the runs after it (before,
each short run started the compile and stopped it again at its end: five one-second runs of the
four-bar in a row all ran as plain Python, and the cache filled only once runs added up to a
whole compile).

One at a time: the process holds an exclusive ``flock`` on :data:`LOCK_NAME` in numba's cache
directory while it compiles (and lets go while it waits for requests). A run that finds the lock
held starts no compiler: its requests wait and its calls run as plain Python, and it tries the
lock again every :data:`RETRY_SECONDS`. Once the lock is free (the other compiler is done, or has
been killed: the kernel releases the lock of a process that has gone, so a stale lock never
blocks), it starts its own, which loads from the cache what the other one compiled and compiles
what is still missing. ``python -m vjm_ros.app.precompile`` waits for the lock too
(:func:`holding_lock`). Where ``fcntl`` is missing (not POSIX), runs compile without the lock.
"""

from __future__ import annotations

import atexit
import contextlib
import importlib
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

from vjm_ros.jit import deferred, numba_internals

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no lock
    fcntl = None

LOCK_NAME = "vjm-compile.lock"
"""File in numba's cache directory that the compiling process holds an exclusive ``flock`` on; it
holds that process's pid (for messages only: the lock is the ``flock``, not the file)."""

LOG_NAME = "vjm-compile.log"
"""File in numba's cache directory that the compile server writes its progress to (appended)."""

LOG_LIMIT = 1 << 20
"""Size of the log, bytes, beyond which a new compile server starts it afresh."""

RETRY_SECONDS = 0.5
"""Interval at which a run that waits for another process's compile tries the lock again, s."""

NICENESS = 10
"""Niceness added to the compile server: the run itself keeps the core it needs."""

PRECOMPILE = "python -m vjm_ros.app.precompile"
"""The command that compiles every entry point at once, in the foreground."""

_FRAME = struct.Struct("<Q")

_IMPORT_ROOT = Path(__file__).resolve().parents[2]
"""The folder the package is imported from: the server's working directory, so that it imports
the same package whatever the run's working directory was and whatever becomes of it."""


# ---------------------------------------------------------------------------- the lock
def cache_directory() -> Path | None:
    """numba's cache directory of the package's compiled functions (``NUMBA_CACHE_DIR``, or next to
    the package, or the user's cache directory where the package is read-only), as numba itself
    chooses it; None where nothing is cached (numba missing, ``NUMBA_DISABLE_JIT``). Imports numba if it was not."""
    if not deferred.activate():
        return None
    return numba_internals.cache_directory()


class CompileLock:
    """The lock one compiler at a time holds: an exclusive ``flock`` on ``path``.

    Parameters
    ----------
    path : Path
        The lock file (created where missing).
    """

    def __init__(self, path: Path):
        self.path = Path(path)

    @classmethod
    def here(cls) -> CompileLock | None:
        """The lock in numba's cache directory (:func:`cache_directory`); None where there is
        none (no cache, or no ``fcntl``)."""
        directory = cache_directory() if fcntl is not None else None
        return None if directory is None else cls(directory / LOCK_NAME)

    def _open(self) -> int | None:
        try:
            return os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
        except OSError:  # a directory numba can write and this process cannot open in
            return None

    def try_acquire(self) -> tuple[bool, int | None]:
        """Take the lock if no other process holds it.

        Returns
        -------
        acquired : bool
            False where another process holds it.
        fd : int or None
            The open file that holds the lock (closing every copy of it releases the lock);
            None where the file cannot be opened (then ``acquired`` is True: go on unlocked).
        """
        fd = self._open()
        if fd is None:
            return True, None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            return False, None
        return True, fd

    def acquire(self) -> int | None:
        """Take the lock, waiting for the process that holds it; returns the open file (None
        where it cannot be opened)."""
        fd = self._open()
        if fd is not None:
            fcntl.flock(fd, fcntl.LOCK_EX)
        return fd

    @staticmethod
    def note(fd: int | None, pid: int) -> None:
        """Write ``pid`` (the process now holding the lock) into the lock file open as ``fd``."""
        if fd is None:
            return
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{pid}\n".encode(), 0)

    def holder(self) -> int | None:
        """The pid the lock file names (the last process that held the lock), if any."""
        try:
            return int(self.path.read_text().split()[0])
        except (OSError, ValueError, IndexError):
            return None


@contextlib.contextmanager
def holding_lock(log: Callable[[str], object] | None = None) -> Iterator[None]:
    """Hold the compile lock for the ``with`` block, waiting first for a compile server that
    holds it (said through ``log``, a callable taking a line of text). For a process that
    compiles in the foreground (:mod:`vjm_ros.app.precompile`)."""
    lock = CompileLock.here()
    if lock is None:
        yield
        return
    acquired, fd = lock.try_acquire()
    if not acquired:
        if log is not None:
            log(f"waiting for the compile in the background (pid {lock.holder()}, log "
                f"{lock.path.parent / LOG_NAME}) to finish")
        fd = lock.acquire()
    CompileLock.note(fd, os.getpid())
    try:
        yield
    finally:
        if fd is not None:
            os.close(fd)


# ---------------------------------------------------------------------------- the run's side
class CompileServer:
    """A run's link to its compile server, which compiles entry points in request order.

    Requests are pickled ``(number, module, name, args)`` frames on the server's stdin; it
    answers one line per request on its stdout (``ok <number>`` or ``error <number> <why>``),
    which a thread of this process reads. The server starts with the first request, if no other
    process holds the compile lock; otherwise requests wait in this process until the lock is
    free (tried again by :meth:`done` and :meth:`wait`). At this process's exit the server is
    left to finish the requests it has (:meth:`detach`).
    """

    def __init__(self):
        self._lock = threading.Lock()
        self._answers: dict[int, str] = {}
        self._events: dict[int, threading.Event] = {}
        self._process: subprocess.Popen | None = None
        self._queued: list[bytes] = []
        self._count = 0
        self._retry_at = 0.0
        self._closed = False
        self._at_exit = False
        self.lock: CompileLock | None = None

    @property
    def pid(self) -> int | None:
        """The server's pid, once started."""
        return None if self._process is None else self._process.pid

    def request(self, module: str, name: str, args: tuple) -> int:
        """Ask for ``module.name`` compiled for ``args``; returns the request's number."""
        with self._lock:
            self._count += 1
            number = self._count
            self._events[number] = threading.Event()
            frame = pickle.dumps((number, module, name, args), protocol=pickle.HIGHEST_PROTOCOL)
            self._queued.append(_FRAME.pack(len(frame)) + frame)
            if not self._at_exit:
                atexit.register(self.detach)
                self._at_exit = True
            self._send()
        return number

    def done(self, number: int) -> bool:
        """Whether request ``number`` has been answered (compiled, or failed)."""
        event = self._events[number]
        if not event.is_set() and self._queued:  # waiting for another process's compile
            with self._lock:
                self._send()
        return event.is_set()

    def wait(self, number: int, timeout: float | None = None) -> bool:
        """Wait for request ``number``; False on timeout."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self.done(number):
            left = RETRY_SECONDS if deadline is None else min(deadline - time.monotonic(),
                                                              RETRY_SECONDS)
            if left <= 0:
                return False
            self._events[number].wait(left)
        return True

    def _fail(self, why: str) -> None:
        """Answer every open request with ``why`` (the caller then compiles, and raises, itself)."""
        for number, event in self._events.items():
            if not event.is_set():
                self._answers[number] = f"error {number} {why}"
                event.set()

    def _send(self) -> None:
        """Start the server if need be and the lock is free, and hand it the queued requests
        (with ``self._lock`` held)."""
        if not self._queued:
            return
        try:
            process = self._start()
            if process is None:
                return  # another process compiles: tried again later
            for frame in self._queued:
                process.stdin.write(frame)
            process.stdin.flush()
        except (OSError, ValueError) as exc:  # the server could not start or has gone
            self._fail(f"compile server unavailable: {exc}")
        self._queued.clear()

    def _start(self) -> subprocess.Popen | None:
        if self._process is not None:
            return self._process
        now = time.monotonic()
        if self._closed or now < self._retry_at:
            return None
        self._retry_at = now + RETRY_SECONDS
        if self.lock is None:
            self.lock = CompileLock.here()
        acquired, fd = (True, None) if self.lock is None else self.lock.try_acquire()
        if not acquired:
            return None
        try:
            log = self._open_log()
            command = [sys.executable, "-m", "vjm_ros.jit.compile_server"]
            try:
                self._process = subprocess.Popen(
                    [*command, *([] if fd is None else ["--lock-fd", str(fd)])],
                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log,
                    start_new_session=True, pass_fds=() if fd is None else (fd,),
                    cwd=_IMPORT_ROOT)
            finally:
                if log is not subprocess.DEVNULL:
                    log.close()
            CompileLock.note(fd, self._process.pid)
        finally:  # the server holds the lock from here on (its copy of the open file)
            if fd is not None:
                os.close(fd)
        threading.Thread(target=self._read, args=(self._process,), name="vjm-compile-answers",
                         daemon=True).start()
        return self._process

    @property
    def log_path(self) -> Path | None:
        """The server's log file, where there is a cache directory."""
        return None if self.lock is None else self.lock.path.parent / LOG_NAME

    def _open_log(self):
        path = self.log_path
        if path is None:
            return subprocess.DEVNULL
        try:
            fresh = path.exists() and path.stat().st_size > LOG_LIMIT
            return open(path, "wb" if fresh else "ab")  # noqa: SIM115 - closed after Popen
        except OSError:
            return subprocess.DEVNULL

    def _read(self, process: subprocess.Popen) -> None:
        for raw in process.stdout:
            line = raw.decode("utf-8", "replace").strip()
            parts = line.split(" ", 2)
            if len(parts) >= 2 and parts[1].isdigit():
                number = int(parts[1])
                with self._lock:
                    self._answers[number] = line
                    event = self._events.get(number)
                if event is not None:
                    event.set()
        with self._lock:  # the server has gone: every open request fails (compiled here then)
            self._fail("compile server exited")

    def pending(self) -> bool:
        """Whether some request is not answered yet."""
        return any(not event.is_set() for event in self._events.values())

    def detach(self) -> None:
        """Leave the server to finish the requests it has and exit (at this process's exit):
        its stdin is closed, which it reads as the end of the requests; said on stderr when
        it still has some."""
        with self._lock:
            self._closed = True
            process, pending = self._process, self.pending()
        if process is not None:
            with contextlib.suppress(OSError, ValueError):
                process.stdin.close()
            if not pending or process.poll() is not None:
                return
            where = f"pid {process.pid}" + (f", log {self.log_path}" if self.log_path else "")
            said = f"compiling the kernels goes on in the background ({where})"
        elif pending and self.lock is not None:
            holder = self.lock.holder()
            said = ("another process" + (f" (pid {holder})" if holder else "")
                    + " is compiling the kernels in the background")
        else:
            return
        with contextlib.suppress(OSError, ValueError):  # stderr closed: nothing to tell
            print(f"vjm: {said}; later runs will be fast once it is done; `{PRECOMPILE}` "
                  "compiles them now, in the foreground", file=sys.stderr, flush=True)

    def stop(self) -> None:
        """Stop the server now, whatever it still has to compile."""
        with self._lock:
            self._closed = True
            process = self._process
        if process is None or process.poll() is not None:
            return
        with contextlib.suppress(OSError, ValueError):
            process.stdin.close()
        process.terminate()
        try:
            process.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


_SERVER: CompileServer | None = None
_SERVER_LOCK = threading.Lock()


def server() -> CompileServer:
    """This process's compile server (started with the first request)."""
    global _SERVER
    with _SERVER_LOCK:
        if _SERVER is None:
            _SERVER = CompileServer()
        return _SERVER


# ---------------------------------------------------------------------------- the server
def _read_exactly(fd: int, size: int) -> bytes:
    data = bytearray()
    while len(data) < size:
        chunk = os.read(fd, size - len(data))
        if not chunk:
            break
        data += chunk
    return bytes(data)


def _read_frame(fd: int) -> bytes | None:
    """The next request frame from ``fd``; None at the end of the requests (a frame cut short by
    a run killed while it wrote one counts as the end)."""
    head = _read_exactly(fd, _FRAME.size)
    if len(head) < _FRAME.size:
        return None
    (size,) = _FRAME.unpack(head)
    frame = _read_exactly(fd, size)
    return frame if len(frame) == size else None


def _say(text: str) -> None:
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S')} [{os.getpid()}] {text}", file=sys.stderr,
          flush=True)


def _compile(module: str, name: str, args: tuple) -> None:
    deferred.activate()
    dispatcher = deferred.compiled(getattr(importlib.import_module(module), name))
    dispatcher.compile(numba_internals.argument_types(dispatcher, args))


def serve(lock_fd: int | None = None) -> int:
    """The compile server's loop: requests from stdin, answers to stdout, until stdin ends.

    ``lock_fd`` is the open compile lock handed over, held, by the run that started the server;
    the server lets go of it while it waits for a request (after its first) and takes it again,
    waiting for whoever holds it then, before it compiles.
    """
    for number in (signal.SIGINT, signal.SIGHUP):  # the run's Ctrl-C, the terminal's hang-up
        signal.signal(number, signal.SIG_IGN)
    with contextlib.suppress(OSError):
        os.nice(NICENESS)
    from vjm_ros.jit import tiers

    tiers.compile_first()  # anything this process calls compiles here
    _say(f"compile server started, numba cache {os.environ.get('NUMBA_CACHE_DIR', '(default)')}")
    stdin, answers, held, first = 0, 1, lock_fd is not None, True
    while True:
        if held and not first and not select.select([stdin], [], [], 0)[0]:
            fcntl.flock(lock_fd, fcntl.LOCK_UN)  # idle: another run's server may compile
            held = False
        frame = _read_frame(stdin)
        if frame is None:
            break
        if lock_fd is not None and not held:
            fcntl.flock(lock_fd, fcntl.LOCK_EX)
            CompileLock.note(lock_fd, os.getpid())
            held = True
        first = False
        number, module, name, args = pickle.loads(frame)
        start = time.perf_counter()
        try:
            _compile(module, name, args)
            answer = f"ok {number}"
        except Exception as exc:  # noqa: BLE001 - reported; the run compiles it itself
            answer = f"error {number} {type(exc).__name__}: {exc}".replace("\n", " ")
        _say(f"{module}.{name}: {answer.split(' ', 2)[0]} in {time.perf_counter() - start:.1f} s"
             + ("" if answer.startswith("ok") else f" ({answer.split(' ', 2)[-1]})"))
        if answers is not None:
            try:
                os.write(answers, answer.encode() + b"\n")  # one short line: written whole
            except OSError:  # the run has ended: what it asked for is compiled all the same
                answers = None
    _say("done")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m vjm_ros.jit.compile_server [--lock-fd N]`` (started by :class:`CompileServer`)."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m vjm_ros.jit.compile_server")
    parser.add_argument("--lock-fd", type=int, default=None)
    return serve(parser.parse_args(argv).lock_fd)


if __name__ == "__main__":
    sys.exit(main())
