"""Logs of a simulation: MCAP (ROS 2 profile) and rerun recordings, usable without ROS.

Both recorders share one API: ``write(sample)`` after every tick (or ``write_block(block)`` after
a :class:`~vjm_ros.sim.samples.SampleBlock` of ticks: the same log, encoded in bulk),
``note_reset(t, tick)`` when the simulator is reset, ``close()`` (idempotent) or use as a context
manager::

    from vjm_ros.logs import McapRecorder, finalize_on_signals

    with finalize_on_signals(), McapRecorder("run.mcap", sim.model, sim.describe(), scene.text) as rec:
        for _ in range(n):
            sim.advance()
            rec.write(sim.sample())

Recording time. Log times are simulated time. The simulator's clock restarts at 0 on a reset; the
recorders keep their time axis monotonic by shifting every later episode so that it starts one
tick after the last time written (:class:`Timebase`).

The heavy dependencies (``mcap``, ``rerun``) are imported only when a recorder class is used.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

import numpy as np

from vjm_ros.logs import events
from vjm_ros.logs.signals import StopSignals, atomic, finalize_on_signals
from vjm_ros.sim.samples import SampleBlock

if TYPE_CHECKING:
    from vjm_ros.logs.mcap_recorder import McapRecorder
    from vjm_ros.logs.rerun_recorder import RerunRecorder
    from vjm_ros.sim.samples import Sample

__all__ = [
    "McapRecorder",
    "RerunRecorder",
    "StopSignals",
    "Timebase",
    "atomic",
    "finalize_on_signals",
    "package_versions",
]


def __getattr__(name: str) -> Any:
    if name == "McapRecorder":
        from vjm_ros.logs.mcap_recorder import McapRecorder

        return McapRecorder
    if name == "RerunRecorder":
        from vjm_ros.logs.rerun_recorder import RerunRecorder

        return RerunRecorder
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class Recorder:
    """Shared life cycle of the recorders: idempotent :meth:`close` and context management.

    Subclasses set ``self._closed = False`` when opened and implement :meth:`_finalize`.
    """

    _closed: bool = True

    def _check_open(self) -> None:
        """Refuse a write after :meth:`close`."""
        if self._closed:
            where = getattr(self, "path", None) or getattr(self, "target", None)
            raise ValueError(f"write to a closed recorder ({where})")

    def _finalize(self) -> None:
        """Write what is pending and release the sink (called once by :meth:`close`)."""
        raise NotImplementedError

    _one = None  # the block of one row that write() fills

    @atomic
    def write(self, sample: Sample) -> None:
        """Log one tick's :class:`~vjm_ros.sim.samples.Sample`: a block of one row
        (``write_block``, which the subclasses implement)."""
        if self._one is None:
            self._one = SampleBlock(self.model, 1)
        one = self._one
        one.put(0, sample)
        one.effort = sample.effort
        one.measured = None if sample.measured is None else sample.measured[None]
        one.rows = 1
        self.write_block(one)

    def reserve(self, block_ticks: int) -> None:
        """Make ready, now, the memory that writing blocks of ``block_ticks`` rows will use
        (``vjm run`` calls it as the log opens, before the run's clock starts). Without it the
        first blocks allocate that memory, and the operating system maps and clears its pages
        while the physics runs."""

    def _reset_event(self, t: float | None, tick: float | None) -> tuple[int, str]:
        """Start a new episode of ``self.timebase`` (:meth:`Timebase.reset`); its start, ns,
        and the reset event's text (:func:`~vjm_ros.logs.events.reset_line`)."""
        ns = self.timebase.reset(t, tick)
        ended = self.timebase.last_ns if self.timebase.last_ns is not None else ns
        self.timebase.last_ns = max(self.timebase.last_ns or 0, ns)
        return ns, events.reset_line(ended * 1e-9, ns * 1e-9)

    def close(self) -> None:
        """Finalize the log; later calls do nothing."""
        if self._closed:
            return
        self._closed = True
        self._finalize()

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()


class Timebase:
    """Monotonic recording time (ns) from the simulator's time, which restarts at each reset.

    Parameters
    ----------
    tick : float
        Control period, s. After a reset the next episode starts ``tick`` after the last time
        written, so no two episodes share a time stamp.
    """

    def __init__(self, tick: float = 0.0):
        self.tick_ns = max(int(round(tick * 1e9)), 0)
        self.offset_ns = 0
        self.last_ns: int | None = None

    def to_ns(self, t: float) -> int:
        """Recording time of simulator time ``t`` (s) in the current episode, ns."""
        ns = self.offset_ns + int(round(t * 1e9))
        if self.last_ns is None or ns > self.last_ns:
            self.last_ns = ns
        return ns

    def to_ns_array(self, t: np.ndarray) -> np.ndarray:
        """:meth:`to_ns` of consecutive times ``t`` (s, increasing) at once.

        Returns
        -------
        ndarray of int64, shape (T,)
            The same values as ``to_ns`` one by one (``rint`` rounds half to even, as ``round``).
        """
        ns = self.offset_ns + np.rint(np.asarray(t, dtype=float) * 1e9).astype(np.int64)
        if len(ns) and (self.last_ns is None or ns[-1] > self.last_ns):
            self.last_ns = int(ns[-1])
        return ns

    def reset(self, t: float | None = None, tick: float | None = None) -> int:
        """Start a new episode.

        Parameters
        ----------
        t : float, optional
            Simulator time at which the ending episode stopped, s; the last time written when
            omitted or earlier.
        tick : float, optional
            The new episode's control period, s, when it changed (a node's ``rate_hz`` takes
            effect at a reset): the episode starts one new tick after the last.

        Returns
        -------
        int
            Recording time at which the new episode starts (its ``t = 0``), ns.
        """
        if tick is not None:
            self.tick_ns = max(int(round(tick * 1e9)), 0)
        if self.last_ns is None and t is None:
            return self.offset_ns
        end = self.last_ns if self.last_ns is not None else 0
        if t is not None:
            end = max(end, self.offset_ns + int(round(t * 1e9)))
        self.offset_ns = end + self.tick_ns
        self.last_ns = end
        return self.offset_ns


def tick_of(settings: dict) -> float:
    """Control period (s) from run settings: ``dt``, else ``1 / rate``, else 0."""
    if settings.get("dt"):
        return float(settings["dt"])
    if settings.get("rate"):
        return 1.0 / float(settings["rate"])
    return 0.0


def package_versions() -> dict:
    """Installed versions of Python and of the packages that shape a log (``"not installed"``
    when absent).

    Read once per process (each log of a run stores them; reading the package metadata takes
    milliseconds).
    """
    return dict(_package_versions())


@functools.cache
def _package_versions() -> dict:
    import platform
    from importlib import metadata

    out = {"python": platform.python_version()}
    for name in ("vjm_ros", "numpy", "scipy", "mcap", "rerun-sdk"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out
