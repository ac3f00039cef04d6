"""The outputs of ``vjm run`` (the trajectory and ``trajectory.csv``, the MCAP and rerun logs),
opened and written in threads of their own while the physics runs (:mod:`vjm_ros.logs.background`).

One thread extends the trajectory and writes its CSV as it grows, and writes the rerun log
(:data:`OWN_THREAD` names the logs that get a thread of their own: the MCAP log); a log's
consumer opens the log, writes the run's first sample and every block, and finalizes the log.
The files are the ones written in the calling thread one block after the other, byte for byte
(clocks aside).
"""

from __future__ import annotations

import importlib
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

from vjm_ros.logs.background import BlockFanOut, Consumer
from vjm_ros.logs.storage import LogWriters
from vjm_ros.sim.samples import Sample, SampleBlock
from vjm_ros.sim.trajectory import CsvStream, Trajectory

LIBRARIES = {
    "csv": ("vjm_ros.sim.float_text",),
    "mcap": ("vjm_ros.logs.mcap_recorder",),
    "rrd": ("vjm_ros.logs.rerun_recorder",),
}
"""Modules each output imports when it opens: the compiled CSV writer, the MCAP writer with the
message encoders, the rerun SDK (0.2-0.6 s on its own)."""


def preload_libraries(outputs: Sequence[str]) -> threading.Thread:
    """Import the libraries of the outputs asked for, in a thread, while the run is set up.

    A fresh ``vjm run`` spends most of what its logs cost importing their libraries; started
    before the scene is loaded and the kernels are read from numba's cache, the imports overlap
    them instead of following them. The logs' package versions (read from the installed
    packages' metadata, 15-30 ms) are read here too. An import that fails here fails again,
    with its message, where the output opens.

    Parameters
    ----------
    outputs : sequence of str
        Keys of :data:`LIBRARIES` (``"csv"``, ``"mcap"``, ``"rrd"``).

    Returns
    -------
    threading.Thread
        Started; join it before the run's clock starts.
    """
    names = [name for key in outputs for name in LIBRARIES[key]]

    def load() -> None:
        for name in names:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001 (reported where the output opens)
                pass
        if "mcap" in outputs or "rrd" in outputs:  # read once, stored by every log
            from vjm_ros.logs import package_versions

            package_versions()

    thread = threading.Thread(target=load, name="vjm-preload", daemon=True)
    thread.start()
    return thread


MCAP_CHUNK_SECONDS = 1.0
"""Chunks of ``vjm run``'s MCAP log, s of simulated time (or of wall time, where the run is slower
than real time): 0.73 MB before compression at 1 kHz on the four-bar, about the chunk size of
the C++ MCAP writer that rosbag2's MCAP storage uses (768 KiB by default). A run faster than
real time crosses a second of simulated time in milliseconds, so a killed ``vjm run`` loses at
most its last second of simulated time, where the node, live, keeps the recorder's 0.25 s. A
quarter of the chunks takes a quarter of their fixed costs (indexes, records, calls to the
file): the four-bar's 10 s log, written in one thread alone, 19.3 and 20.4 ms against 22.1 and
25.4 ms (medians of 20, two runs each); ``vjm run four_bar --integrator rk4 --closure exact
--duration 10 --out --mcap --rrd``, fresh processes, 50 rounds paired with 0.25 s chunks:
``wall_time`` shorter in 33, geometric mean of the ratios 0.94, median ``cpu_time`` ratio 0.94."""


OWN_THREAD = ("--mcap", "--bag")
"""Logs written in a thread of their own (the MCAP log, as a file or in a rosbag2 directory); the
others share the trajectory's thread. The MCAP log's Python work (record images, indexes, chunk
compression) is the largest; the trajectory and the rerun log leave much of theirs to compiled
code and rerun's threads. ``vjm run four_bar --out --mcap --rrd`` (rk4, exact closure, 10 s at
1 kHz), fresh processes, paired rounds against one thread per output: median ``wall_time`` 0.93,
0.94 and 0.95 times (25, 30 and 25 rounds; a first 10-round measure: 1.03), median ``cpu_time``
106 against 125 ms and 125 against 132 ms; with ``--out --rrd`` alone, one thread against two:
1.01 (20 rounds)."""


class RunOutputs:
    """Where the blocks of a run go.

    Parameters
    ----------
    traj : Trajectory
        Holds the first sample already; extended block by block (read it after :meth:`close`).
    first : Sample
        The run's first sample (t = 0), the first record of every log.
    openers : sequence of (str, callable)
        Per log, its option and the function that opens it
        (:func:`vjm_ros.logs.opening.recorder_openers`); called in the log's thread.
    on_failure : callable
        ``on_failure(path, error_text)`` for a log given up during the run (:class:`LogWriters`).
    csv_path : Path, optional
        ``trajectory.csv``, created once every log has opened (not at all if one cannot be).
    block_ticks : int
        Rows of each block.

    Attributes
    ----------
    logs : LogWriters
        The open logs (after :meth:`close`: those still working, and what failed).
    recorders : dict
        The recorder opened for each option (``--mcap``...).
    """

    def __init__(self, traj: Trajectory, first: Sample,
                 openers: Sequence[tuple[str, Callable[[], object]]],
                 on_failure: Callable[[str, str], None], csv_path: Path | None,
                 block_ticks: int):
        self.traj = traj
        self.logs = LogWriters([], on_failure)
        self.recorders: dict[str, object] = {}
        self._first = first
        self._csv_path = csv_path
        self._csv: CsvStream | None = None
        self._block_ticks = block_ticks
        logs = [(key, self._log_consumer(key, opener)) for key, opener in openers]
        shared = [Consumer("vjm-trajectory", self._extend, self._close_csv)]
        shared += [consumer for key, consumer in logs if key not in OWN_THREAD]
        alone = [consumer for key, consumer in logs if key in OWN_THREAD]
        self._fan = BlockFanOut(lambda: SampleBlock(traj.model, block_ticks), [shared, *alone],
                                depth=8)

    def wait_opened(self) -> None:
        """Wait until every log has opened or failed to open (a failure is raised by
        :meth:`put` or :meth:`close`)."""
        self._fan.wait_started()

    def take(self) -> SampleBlock:
        """A block to fill (see :meth:`BlockFanOut.take`)."""
        return self._fan.take()

    def put(self, block: SampleBlock) -> None:
        """Hand a filled block over; raises what an output raised (a log that could not be
        opened: :class:`~vjm_ros.core.errors.ConfigurationError`)."""
        self._fan.put(block)

    def close(self) -> None:
        """Write every block handed over, close the CSV and finalize the logs; raise what an
        output raised."""
        self._fan.close()

    # ------------------------------------------------------------------ consumers
    def _extend(self, block: SampleBlock) -> None:
        self.traj.extend(block)
        if self._fan.all_started:  # the CSV is created only once every log has opened
            self._open_csv()
        if self._csv is not None:
            self._csv.catch_up()

    def _open_csv(self) -> None:
        if self._csv is None and self._csv_path is not None:
            self._csv = CsvStream(self.traj, self._csv_path)

    def _close_csv(self) -> None:
        if self._fan.wait_started():  # also a run without blocks has its first row
            self._open_csv()
        if self._csv is not None:
            self._csv.close()

    def _log_consumer(self, key: str, opener: Callable[[], object]) -> Consumer:
        logs = self.logs
        slot: list = []

        def start() -> None:
            rec = opener()
            slot.append(rec)
            self.recorders[key] = rec
            logs.active.append(rec)
            logs.write_to(rec, self._first)
            rec.reserve(self._block_ticks)

        return Consumer(f"vjm-log {key}", lambda block: logs.write_block_to(slot[0], block),
                        lambda: logs.close_one(slot[0]), start)
