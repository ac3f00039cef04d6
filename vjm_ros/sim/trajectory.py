"""In-memory trajectory of a run, its CSV table and its summary measures (docs/design.md section 6).

The columns of ``trajectory.csv`` are a contract (docs/design.md section 5): ``t``; per joint
``q.<joint>``, ``qd.<joint>``, ``qdd.<joint>``, ``effort.<joint>``; per link ``theta.<link>``; per
named point ``x.<point>``, ``y.<point>``; per closure ``f.<closure>.x``, ``f.<closure>.y`` (or
``f.<closure>.z`` for a torque); ``energy.kinetic``, ``energy.potential``, ``energy.constraint``,
``energy.total``, ``closure_error``; and, for a scene with sensors, per joint
``measured.q.<joint>``, ``measured.qd.<joint>``, ``measured.effort.<joint>`` (what the node
publishes on ``joint_states``; the columns before them are the exact state).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from vjm_ros.core.model import Model
from vjm_ros.core.pipeline import OBSERVABLES, observable_shapes
from vjm_ros.jit import tiers
from vjm_ros.sim import float_text
from vjm_ros.sim.samples import BLOCK_FIELDS, Sample, SampleBlock

ENERGY_NAMES = ("kinetic", "potential", "constraint", "total")


_STORED = ("q", "qd", "qdd", "theta", "points", "force", "error", "energy", "power",
           "dissipation", "loss", "segments")
"""Arrays of a :class:`~vjm_ros.sim.samples.SampleBlock` the trajectory keeps (all but the
closures' points of application), with the block's names."""

_SAMPLE_FIELDS = (("t", "t"), ("effort", "effort")) + tuple(
    (key, attr) for key, attr in BLOCK_FIELDS if key in _STORED)
"""Columns of the trajectory buffer and the :class:`~vjm_ros.sim.samples.Sample` field each
one takes."""


class Trajectory:
    """Samples of one run, stored as growing arrays.

    Parameters
    ----------
    model : Model
    capacity : int
        Initial number of rows reserved (grows as needed).
    measured : bool
        Also keep the sensors' measurements (:attr:`~vjm_ros.sim.samples.Sample.measured`)
        and write them as the ``measured.*`` columns.
    """

    def __init__(self, model: Model, capacity: int = 1024, measured: bool = False):
        self.model = model
        self._rows = 0
        shapes = dict(zip(OBSERVABLES, observable_shapes(model), strict=True))
        shapes.update(t=(), effort=(model.n,), measured=(3, model.n))
        self._fields = _SAMPLE_FIELDS + ((("measured", "measured"),) if measured else ())
        self._buf = {key: np.zeros((capacity,) + shapes[key]) for key, _ in self._fields}

    def __len__(self) -> int:
        return self._rows

    def _reserve(self, rows: int) -> None:
        """Room for ``rows`` more samples (capacity doubles as needed)."""
        while self._rows + rows > len(self._buf["t"]):
            for key, arr in self._buf.items():
                self._buf[key] = np.concatenate((arr, np.zeros_like(arr)), axis=0)

    def append(self, s: Sample) -> None:
        """Store one sample."""
        self._reserve(1)
        i = self._rows
        b = self._buf
        for key, attr in self._fields:
            b[key][i] = getattr(s, attr)
        self._rows += 1

    def extend(self, block: SampleBlock) -> None:
        """Store every row of a :class:`~vjm_ros.sim.samples.SampleBlock` (copied; the block's
        arrays carry the trajectory's column names)."""
        rows = len(block)
        self._reserve(rows)
        i, b = self._rows, self._buf
        for key, _ in self._fields:
            if key == "effort":  # held over the block, or one row per tick
                b[key][i : i + rows] = block.effort[:rows] if block.effort.ndim == 2 else block.effort
            else:
                b[key][i : i + rows] = getattr(block, key)[:rows]
        self._rows += rows

    def __getitem__(self, key: str) -> np.ndarray:
        """Stored array by name (``t``, ``q``, ``qd``, ``qdd``, ``effort``, ``theta``, ``points``,
        ``force``, ``error``, ``energy``, ``power``, ``dissipation``, ``segments``; ``measured``,
        shape (rows, 3, n), when kept)."""
        return self._buf[key][: self._rows]

    # ------------------------------------------------------------------ measures
    def closure_error(self) -> np.ndarray:
        """Largest closure residual per sample, m (rad for angle closures).

        Returns
        -------
        ndarray, shape (rows,)
        """
        err = self["error"]
        return err.max(axis=1) if err.shape[1] else np.zeros(len(self))

    def energy_drift(self) -> float:
        """``max |(T+V)(t) - (T+V)(0)| / max T`` (dimensionless; docs/design.md section 5)."""
        e = self["energy"]
        if len(e) == 0:
            return 0.0
        tv = e[:, 0] + e[:, 1]
        scale = float(np.max(e[:, 0]))
        if scale <= 0:
            return 0.0 if np.allclose(tv, tv[0]) else float("inf")
        return float(np.max(np.abs(tv - tv[0])) / scale)

    def energy_balance_residual(self) -> float:
        """Largest deviation from the energy ledger of docs/design.md section 2, J.

        ``E(t) - E(0) - integral(tau . qd - dissipation) dt + sum of joint_loss`` with the
        trapezoid rule over the samples, where ``E = T + V + sum 1/2 Kp C^2``; the energy the
        joints' sticking friction and stops took (``loss``) is summed per tick as it was taken.
        """
        if len(self) < 2:
            return 0.0
        t = self["t"]
        rate = self["power"] - self["dissipation"]
        work = np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t)
                                                - self["loss"][1:])))
        total = self["energy"][:, 3]
        return float(np.max(np.abs(total - total[0] - work)))

    def summary(self, extra: dict | None = None) -> dict:
        """The run's measures (closure error, energy drift, ledger residual, finiteness).

        Parameters
        ----------
        extra : dict, optional
            Entries merged in first (settings, timing).

        Returns
        -------
        dict
            JSON-serializable.
        """
        out = dict(extra or {})
        err = self.closure_error()
        finite = bool(
            len(self) > 0
            and np.all(np.isfinite(self["q"]))
            and np.all(np.isfinite(self["qd"]))
            and np.all(np.isfinite(self["energy"]))
        )
        out.update(
            {
                "sim_time": float(self["t"][-1]) if len(self) else 0.0,
                "max_closure_error": float(err.max()) if err.size else 0.0,
                "rms_closure_error": float(np.sqrt(np.mean(err**2))) if err.size else 0.0,
                "energy_drift": self.energy_drift(),
                "energy_balance_residual": self.energy_balance_residual(),
                "finite": finite,
            }
        )
        return out

    # ------------------------------------------------------------------ CSV
    def columns(self) -> list[str]:
        """Column names of the CSV table, in order."""
        m = self.model
        cols = ["t"]
        for j in m.joint_names:
            cols += [f"q.{j}", f"qd.{j}", f"qdd.{j}", f"effort.{j}"]
        cols += [f"theta.{lk}" for lk in m.link_names]
        for p in m.points:
            cols += [f"x.{p.name}", f"y.{p.name}"]
        for name, moment in zip(m.force_names, m.force_is_moment, strict=True):
            cols += [f"f.{name}.z"] if moment else [f"f.{name}.x", f"f.{name}.y"]
        cols += [f"energy.{e}" for e in ENERGY_NAMES] + ["closure_error"]
        if "measured" in self._buf:
            for j in m.joint_names:
                cols += [f"measured.q.{j}", f"measured.qd.{j}", f"measured.effort.{j}"]
        return cols

    def table(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """The columns of rows ``start .. stop - 1`` (all rows by default) as one array.

        Returns
        -------
        ndarray, shape (stop - start, len(columns()))
        """
        m = self.model
        rows = slice(start, len(self) if stop is None else stop)
        t, q, qd = self["t"][rows], self["q"][rows], self["qd"][rows]
        count = len(t)
        parts = [t[:, None]]
        per_joint = np.stack((q, qd, self["qdd"][rows], self["effort"][rows]), axis=2)
        parts.append(per_joint.reshape(count, -1))
        parts.append(self["theta"][rows])
        parts.append(self["points"][rows].reshape(count, -1))
        force = self["force"][rows]
        for k, moment in enumerate(m.force_is_moment):
            parts.append(force[:, k, 2:3] if moment else force[:, k, :2])
        parts.append(self["energy"][rows])
        err = self["error"][rows]
        parts.append((err.max(axis=1) if err.shape[1] else np.zeros(count))[:, None])
        if "measured" in self._buf:  # (rows, 3, n) -> per joint: q, qd, effort
            parts.append(self["measured"][rows].transpose(0, 2, 1).reshape(count, -1))
        return np.concatenate(parts, axis=1)


class CsvStream:
    """``trajectory.csv`` written while the trajectory grows: the header at once, then the rows
    stored since the last :meth:`catch_up` at each call. Every value is written as
    ``repr(float(value))`` (the shortest text that reads back to the same double), rows end with
    ``\\r\\n`` as :mod:`csv` writes them (test/test_trajectory_csv.py).

    The compiled writer formats every batch into one buffer the stream keeps
    (:func:`vjm_ros.sim.float_text.csv_into`), which the file takes as it is: no fresh memory
    (and no page faults) per batch, no copy into ``bytes``.

    Parameters
    ----------
    trajectory : Trajectory
        Read only by :meth:`catch_up` and :meth:`close` (call them from the thread that extends
        it).
    path : str or Path
        Created or overwritten.
    """

    def __init__(self, trajectory: Trajectory, path: str | Path):
        self.trajectory = trajectory
        self.path = Path(path)
        self.written = 0
        self._text = np.empty(0, dtype=np.uint8)
        self._fh = self.path.open("w", newline="")
        try:
            csv.writer(self._fh).writerow(trajectory.columns())
            self._fh.flush()
        except BaseException:
            self._fh.close()
            raise

    def catch_up(self) -> None:
        """Write the rows stored since the last call, :data:`CSV_BATCH_ROWS` at a time."""
        total = len(self.trajectory)
        while self.written < total:
            stop = min(self.written + CSV_BATCH_ROWS, total)
            table = self.trajectory.table(self.written, stop)
            if _compiled_writer(len(table)):
                size = float_text.buffer_size(*table.shape)
                if len(self._text) < size:  # room for a whole batch: its pages fault once
                    self._text = np.empty(float_text.buffer_size(CSV_BATCH_ROWS, table.shape[1]),
                                          dtype=np.uint8)
                count = float_text.csv_into(table, self._text)
                self._fh.buffer.write(memoryview(self._text)[:count])
            else:
                self._fh.buffer.write(_repr_bytes(table))
            self.written = stop

    def close(self) -> None:
        """Write the remaining rows and close the file; later calls do nothing."""
        if self._fh.closed:
            return
        try:
            self.catch_up()
        finally:
            self._fh.close()
            self._text = np.empty(0, dtype=np.uint8)

    def __enter__(self) -> CsvStream:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


CSV_BATCH_ROWS = 4096
"""Rows of ``trajectory.csv`` formatted at once (bounds the text held in memory, ~2 MB)."""


CSV_PLAIN_ROWS = 500
"""Tables of fewer rows are written by ``repr`` until the compiled writer is in use, where entry
points start as plain Python (:mod:`vjm_ros.jit.tiers`): 500 rows of the thesis scenes take a
few ms so, importing numba and loading the writer 0.3-0.4 s; a short run never imports numba."""


def _writer_arguments() -> tuple[np.ndarray, np.ndarray]:
    """Arguments of the types the compiled writer takes (``float_text._csv``): a table's bits
    and the text buffer."""
    return (np.zeros((1, 1), dtype=np.uint64),
            np.zeros(float_text.buffer_size(1, 1), dtype=np.uint8))


def prepare_csv_writer(rows: int) -> None:
    """Load the compiled CSV writer now (from numba's cache) if a table of ``rows`` rows would
    load it. ``vjm run`` does so before its clock starts: loading compiled code is start-up,
    which its ``wall_time`` leaves out (the block pipeline's loading too), and in the CSV's thread,
    competing with the physics and the logs for the interpreter, the load took some 150 ms of
    a fresh run's wall time with all three outputs, for 60-100 ms of loading alone."""
    _compiled_writer(rows)


def _compiled_writer(rows: int) -> bool:
    """Whether the compiled writer formats a table of ``rows`` rows: once it is in use, or
    loaded now for a table of :data:`CSV_PLAIN_ROWS` rows or more (with the tiers on; at once
    with them off), unless numba is still compiling it in the background
    (:mod:`vjm_ros.jit.tiers`)."""
    if not float_text.COMPILED:
        return False
    compiled = tiers.entry(float_text, "_csv")
    if not compiled.ready and (rows >= CSV_PLAIN_ROWS or not tiers.enabled()):
        compiled.prepare(*_writer_arguments())
    return compiled.ready


def _repr_bytes(table: np.ndarray) -> bytes:
    """The CSV rows of ``table`` from the nested list's ``repr``, split at ``"], ["`` and
    ``", "`` (float reprs such as ``1.5``, ``-0.0``, ``1e-05``, ``nan``, ``inf`` hold no comma,
    bracket or space): the compiled writer's text, without it."""
    text = repr(np.asarray(table, dtype=float).tolist())
    return (text[2:-2].replace("], [", "\r\n").replace(", ", ",") + "\r\n").encode("ascii")
