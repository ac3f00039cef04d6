"""Where logs go: the checks at start, and what happens when a log cannot be written mid-run.

Policy (the same for ``vjm run`` and ``vjm_sim_node``):

* **at start** a log path must be writable and its file system must have at least
  :data:`MIN_FREE_BYTES` free (and, for a run of known length, the size the run is expected to
  write, :data:`BYTES_PER_SIM_MINUTE` per simulated minute and log); otherwise the run is refused
  with an error that names the path (exit code 2);
* **during the run** a log whose write fails (the disk filled up, an I/O error) is given up: it
  is closed as far as it can be (an MCAP keeps its complete chunks, which ``vjm recover`` turns
  into a readable file), the error is reported once with the path, and the simulation goes on
  with the other outputs. ``vjm run`` then ends with exit code 4; the node keeps running and
  reports the failure on ``~/events`` and as a warning.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from vjm_ros.core.errors import ConfigurationError

if TYPE_CHECKING:
    from vjm_ros.logs import Recorder
    from vjm_ros.sim.samples import Sample, SampleBlock

MIN_FREE_BYTES = 64 * 2**20
"""Free space required on a log's file system at start, bytes."""
BYTES_PER_SIM_MINUTE = 20 * 2**20
"""Upper estimate of one log's size per simulated minute at 1 kHz, bytes (measured: MCAP
12-18 MB, rerun 12 MB on the thesis scenes)."""


VIEWER_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")
"""Prefixes of rerun targets that are viewers, not files (as :mod:`.rerun_recorder` reads them)."""


def is_file_target(target: str | Path) -> bool:
    """Whether a log target names a file (not ``spawn``, ``connect`` or a viewer's address)."""
    t = str(target)
    return t not in ("spawn", "connect") and not t.startswith(VIEWER_SCHEMES)


def check_log_path(path: str | Path, key: str, sim_seconds: float = 0.0, rate: float = 1000.0) -> Path:
    """Refuse a log path that cannot be written or whose file system is (nearly) full.

    Parameters
    ----------
    path : str or Path
        The log file (created or overwritten).
    key : str
        The option or parameter that named it (``--mcap``, ``rrd``...), for the message.
    sim_seconds : float
        Simulated length of the run, s (0: unknown, only :data:`MIN_FREE_BYTES` is required).
    rate : float
        Tick rate, Hz (the expected size scales with it).

    Returns
    -------
    Path

    Raises
    ------
    ConfigurationError
        Naming the path and what is wrong with it.
    """
    p = Path(path)
    if p.is_dir():
        raise ConfigurationError(f"{key} {p}: expected a file path, found a directory")
    try:
        with open(p, "ab"):
            pass
    except OSError as exc:
        raise ConfigurationError(
            f"{key} {p}: cannot write the log ({exc.strerror or exc})"
        ) from None
    free = shutil.disk_usage(p.resolve().parent).free
    needed = max(MIN_FREE_BYTES, BYTES_PER_SIM_MINUTE * sim_seconds / 60.0 * rate / 1000.0)
    if free < needed:
        raise ConfigurationError(
            f"{key} {p}: only {free / 2**20:.0f} MB free on its file system, expected at least "
            f"{needed / 2**20:.0f} MB for this log; free some space or log elsewhere"
        )
    return p


class LogWriters:
    """Writes each sample to every recorder still working; gives up a recorder whose write fails.

    Parameters
    ----------
    recorders : sequence
        Objects with ``write(sample)``, ``note_reset(t, tick)``, ``close()`` and a ``path`` (or
        ``target``).
    on_failure : callable
        ``on_failure(path, error_text)``, called once per recorder given up.
    """

    def __init__(self, recorders: Sequence, on_failure: Callable[[str, str], None]):
        self.active = list(recorders)
        self.failed: list[tuple[str, str]] = []
        self._on_failure = on_failure

    def write_to(self, rec: Recorder, sample: Sample) -> None:
        """Write ``sample`` to one recorder (nothing if it was given up)."""
        if rec not in self.active:
            return
        try:
            rec.write(sample)
        except OSError as exc:
            self._give_up(rec, exc)

    def write_block(self, block: SampleBlock) -> None:
        """Write every row of a :class:`~vjm_ros.sim.samples.SampleBlock` to every working
        recorder: in bulk where the recorder has ``write_block``, else sample by sample."""
        for rec in list(self.active):
            self.write_block_to(rec, block)

    def write_block_to(self, rec: Recorder, block: SampleBlock) -> None:
        """:meth:`write_block` for one recorder (nothing if it was given up). Recorders may be
        written by threads of their own, one thread per recorder."""
        if rec not in self.active:
            return
        try:
            if hasattr(rec, "write_block"):
                rec.write_block(block)
            else:
                for i in range(len(block)):
                    rec.write(block.sample(i))
        except OSError as exc:
            self._give_up(rec, exc)

    def note_reset(self, t: float, tick: float | None = None) -> None:
        """Tell every working recorder about a simulator reset at ``t`` (s), after which the
        control period is ``tick`` (s; unchanged when None)."""
        for rec in list(self.active):
            try:
                rec.note_reset(t, tick)
            except OSError as exc:
                self._give_up(rec, exc)

    def _give_up(self, rec, exc: OSError, close: bool = True) -> None:
        """Stop writing to ``rec`` after ``exc``, closing it unless ``exc`` came from its close;
        report it as a failed log."""
        self.active.remove(rec)
        try:
            if close:
                rec.close()
        except (OSError, ValueError):
            pass  # what reached the disk stays; an MCAP's complete chunks can be recovered
        text = exc.strerror or str(exc)
        self.failed.append((_where(rec), text))
        self._on_failure(_where(rec), text)

    def close(self) -> None:
        """Close every working recorder (a failure to finalize counts as a failed log)."""
        for rec in list(self.active):
            self.close_one(rec)

    def close_one(self, rec: Recorder) -> None:
        """Close one working recorder (nothing if it was given up or closed); a failure to
        finalize counts as a failed log."""
        if rec not in self.active:
            return
        try:
            rec.close()
        except OSError as exc:
            self._give_up(rec, exc, close=False)


def _where(rec) -> str:
    """The file (or viewer) a recorder writes to."""
    return str(getattr(rec, "path", None) or getattr(rec, "target", None) or type(rec).__name__)
