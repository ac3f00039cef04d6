"""Rerun recording of a simulation: the mechanism in 2D and time series on ``sim_time``.

Entities (all times on the ``sim_time`` duration timeline, simulated seconds since the start of
the recording, monotonic across resets as in :class:`vjm_ros.logs.Timebase`):

============================== ============== ===============================================
entity                         archetype      content
============================== ============== ===============================================
``mechanism/links``            LineStrips2D   every link, start to end, m
``mechanism/joints``           Points2D       link origins (the joints), m
``mechanism/points``           Points2D       named points (chain tips), labelled, m
``mechanism/forces``           Arrows2D       constraint force of each closure at its point,
                                              then of each stop at its joint, times
                                              ``messages.FORCE_SCALE`` m/N, labelled
``mechanism/traces``           Points2D       named points again, shown over all past time:
                                              the tip paths
``mechanism/cyclograph``       LineStrips2D   links every :data:`CYCLOGRAPH_PERIOD`, shown over
                                              all past time: the chrono-cyclograph
``series/joints/position``     Scalars        one series per joint, rad or m
``series/joints/velocity``     Scalars        rad/s or m/s
``series/constraint_forces``   Scalars        ``<closure>.x``, ``.y`` (N) or ``.z`` (N m);
                                              ``<joint>_stop.*`` alike
``series/energy``              Scalars        kinetic, potential, constraint, total, J
``series/closure_error``       Scalars        ``|C|`` per closure, m or rad
``series/measured/position``   Scalars        with sensors: what they measure, rad or m (the
``series/measured/velocity``                  ``series/joints/*`` stay exact), rad/s or m/s,
``series/measured/effort``                    N m or N
``events``                     TextLog        resets
``run/settings``, ``run/scene`` TextDocument  run settings (JSON), scene YAML (static)
============================== ============== ===============================================

Cost. Samples are buffered and sent every ``batch`` ticks (or every ``batch_seconds`` of wall
time), one chunk per entity and all of them in one ``rr.send_chunks``; geometry is kept only
every ``geometry_every`` ticks. The columns are arrow arrays built from whole numpy arrays (the
series' buffers are handed over, not copied), so no Python runs per row or per strip, and the
four-bar's 10 s run at 1 kHz (10001 samples, 2.7 MB of columns) goes out in two sends, one of
them mid-run. Its writes and close cost 6 ms in the writing thread and 11 ms in rerun's threads
with one send at the close (medians of 40 runs, blocks replayed), against 16 and 15 ms with
rerun's archetype builders and ``send_columns`` per entity. What is left is mostly rerun's: a chunk's
rows cost in ``Chunk.from_columns``, and its file writer encodes and lz4-compresses every byte
(rerun 0.41 has no public setting for that compression). Opening (the blueprint and the static
entities, sent on at once) costs some 10 ms more, before the run.

Rerun's 2D views draw y downwards; the ``mechanism`` entity carries a static transform that
flips y so that the mechanism appears with y up (the logged coordinates stay the world's).
"""

from __future__ import annotations

import json
import time
import uuid
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb
from rerun.chunk import Chunk

from vjm_ros.core.model import ANGLE, GROUND, Model
from vjm_ros.logs import (
    Recorder,
    Timebase,
    atomic,
    messages,
    package_versions,
    tick_of,
)
from vjm_ros.logs.storage import VIEWER_SCHEMES

if TYPE_CHECKING:
    from vjm_ros.sim.samples import SampleBlock

TIMELINE = "sim_time"
ROOT = "mechanism"
SERIES = {
    "position": "series/joints/position",
    "velocity": "series/joints/velocity",
    "forces": "series/constraint_forces",
    "energy": "series/energy",
    "error": "series/closure_error",
}
MEASURED = ("series/measured/position", "series/measured/velocity", "series/measured/effort")
"""Entities of the sensors' measurements (a scene with sensors), position, velocity, effort."""
CYCLOGRAPH_PERIOD = 0.1
"""Simulated time between two poses of the chrono-cyclograph, s."""
_VEC2 = pa.list_(pa.field("item", pa.float32(), nullable=False), 2)
"""Arrow type of rerun's ``Position2D`` and ``Vector2D`` components: two float32, m."""
_STRIP = pa.list_(pa.field("item", _VEC2, nullable=False))
"""Arrow type of rerun's ``LineStrip2D`` component: a list of ``_VEC2`` points."""
_LINK_COLORS = np.array(
    [[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189], [140, 86, 75]],
    dtype=np.uint8,
)


def _offsets(rows: int, width: int) -> np.ndarray:
    """Offsets of ``rows`` lists of ``width`` items each, int32, shape (rows + 1,)."""
    return np.arange(rows + 1, dtype=np.int32) * np.int32(width)


def _vec2(xy: np.ndarray) -> pa.FixedSizeListArray:
    """2D points or vectors as rerun stores them: float32 (rounded to nearest, as rerun's own
    conversion does), from ``xy`` of shape (..., 2), m."""
    flat = np.ascontiguousarray(xy, dtype=np.float32).reshape(-1)
    return pa.FixedSizeListArray.from_arrays(pa.array(flat), type=_VEC2)


def _column(descriptor: rr.ComponentDescriptor, batch: type, values: pa.Array,
            rows: int) -> rr.ComponentColumn:
    """A component column of ``rows`` times, each with an equal share of ``values``: what the
    archetypes' ``columns(...).partition(...)`` make, without a Python loop per row or strip.

    Parameters
    ----------
    descriptor : rerun.ComponentDescriptor
        E.g. ``rr.Scalars.descriptor_scalars()``.
    batch : type
        The component's batch class (``rr.components.ScalarBatch``, ...); ``values`` must have
        its arrow type.
    values : pyarrow.Array, shape (rows * width,)
        Shares memory with numpy arrays that are not written to afterwards.
    rows : int
        Number of times, at least 1.
    """
    return rr.ComponentColumn(descriptor, batch(values),
                              offsets=_offsets(rows, len(values) // rows))


def _scalars(values: np.ndarray) -> rr.ComponentColumn:
    """``Scalars:scalars`` of ``values``, shape (rows, width), one row per time."""
    flat = pa.array(values.reshape(-1), pa.float64())
    return _column(rr.Scalars.descriptor_scalars(), rr.components.ScalarBatch, flat, len(values))


def _points(xy: np.ndarray, descriptor: rr.ComponentDescriptor | None = None,
            batch: type = rr.components.Position2DBatch) -> rr.ComponentColumn:
    """``Points2D:positions`` (or ``descriptor``) of ``xy``, shape (rows, count, 2), m."""
    return _column(descriptor or rr.Points2D.descriptor_positions(), batch, _vec2(xy), len(xy))


def _strips(segments: np.ndarray) -> rr.ComponentColumn:
    """``LineStrips2D:strips``: per time, one two-point strip per link, from ``segments`` of
    shape (rows, n, 2, 2) (start and end of each link, m)."""
    strips = pa.ListArray.from_arrays(pa.array(_offsets(segments[..., 0, 0].size, 2)),
                                      _vec2(segments), type=_STRIP)
    return _column(rr.LineStrips2D.descriptor_strips(), rr.components.LineStrip2DBatch,
                   strips, len(segments))


def force_components(model: Model) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Which constraint-force components are meaningful, per entry of ``model.force_names``.

    Hinge and slider closures and the stops of prismatic joints report a force ``(x, y)`` N;
    angle closures and the stops of revolute joints a moment ``z`` N m.

    Returns
    -------
    rows, cols : ndarray of int, shape (m,)
        Index into ``Sample.closure_force`` (k + s, 3).
    names : list of str
        ``"<closure>.x"`` etc.
    """
    rows, cols, names = [], [], []
    for i, (name, moment) in enumerate(zip(model.force_names, model.force_is_moment, strict=True)):
        for j, axis in ((2, "z"),) if moment else ((0, "x"), (1, "y")):
            rows.append(i)
            cols.append(j)
            names.append(f"{name}.{axis}")
    return np.array(rows, dtype=int), np.array(cols, dtype=int), names


def default_blueprint(model: Model, measured: bool = False) -> rrb.Blueprint:
    """Mechanism view on the left, one plot per series group on the right (and one of the
    sensors' measurements when ``measured``)."""
    infinite = rrb.VisibleTimeRanges(timeline=TIMELINE, start=rrb.TimeRangeBoundary.infinite(),
                                     end=rrb.TimeRangeBoundary.cursor_relative())
    mechanism = rrb.Spatial2DView(
        name=f"{model.name}: mechanism", origin="/", contents=f"+ /{ROOT}/**",
        overrides={f"/{ROOT}/traces": infinite, f"/{ROOT}/cyclograph": infinite})
    plots = [rrb.TimeSeriesView(name=name, origin=f"/{SERIES[key]}") for key, name in (
        ("position", "Joint positions (rad, m)"), ("velocity", "Joint velocities (rad/s, m/s)"),
        ("forces", "Constraint forces (N, N m)"), ("energy", "Energy (J)"),
        ("error", "Closure error (m, rad)"))]
    if measured:
        plots.append(rrb.TimeSeriesView(name="Measured joint states", origin="/series/measured"))
    left = rrb.Vertical(mechanism, rrb.TextLogView(name="Events", origin="/events"),
                        row_shares=[5, 1])
    return rrb.Blueprint(
        rrb.Horizontal(left, rrb.Vertical(*plots), column_shares=[3, 2]),
        rrb.TimePanel(timeline=TIMELINE),
        collapse_panels=True,
    )


class RerunRecorder(Recorder):
    """Log simulation samples to rerun.

    Parameters
    ----------
    target : str or Path
        A ``.rrd`` file path, ``"spawn"`` (start a viewer), ``"connect"`` (the viewer at the
        default address) or a ``rerun+http://...`` address.
    model : Model
    settings : dict
        Run settings (``Simulator.describe()``), stored as ``run/settings``; ``dt`` or ``rate``
        sets the gap between episodes after a reset.
    geometry_every : int
        Keep the mechanism drawing of every ``geometry_every``-th sample (and the first).
    batch : int, optional
        Send buffered samples every ``batch`` ticks: 100 for a viewer, 5000 for a file (each
        chunk has a fixed cost in this thread and in rerun's, and rerun's file writer encodes
        what it is sent in one thread: a send mid-run leaves it less to do once the physics has
        ended; ``vjm run four_bar`` with all logs, 10 s at 1 kHz, best of 20 interleaved fresh
        runs: 53.9 ms at 5000 against 61.3 ms at 20000, one send at the close;
        ``batch_seconds`` bounds the wait in real time).
    batch_seconds : float, optional
        ... or when this much wall time has passed since the last send, s (0.2 for a viewer, 1
        for a file).
    scene_text : str
        Scene YAML for ``run/scene`` (``model.source_text`` when empty).
    recording_id : str, optional
        A fresh UUID when omitted.
    total_samples : int, optional
        The samples the run will write, when known (``vjm run``): the batch then becomes an
        equal share of them, for the number of sends nearest to ``total_samples / batch``, and
        the last send ends with the run (10 001 samples at a batch of 5000: two sends of 5001,
        not a third of one sample at the close, whose chunks, one per entity, cost about as
        much to build and encode as full ones and fall after the physics has ended). ``vjm run
        four_bar --out --mcap --rrd``, rk4 at 1 kHz, 10 s, fresh processes, two series of 50
        rounds paired with a batch of 5000: ``wall_time`` shorter in 29 and 28, geometric mean
        of the ratios 0.971 and 0.985, median ``cpu_time`` 123.5 against 130.1 ms and 120.2
        against 128.3 ms.

    A scene with sensors (``settings["sensors"]``) also logs the measured joint states
    (:data:`MEASURED`) from the samples' ``measured``.
    """

    def __init__(
        self,
        target: str | Path,
        model: Model,
        settings: dict,
        geometry_every: int = 10,
        batch: int | None = None,
        batch_seconds: float | None = None,
        scene_text: str = "",
        recording_id: str | None = None,
        total_samples: int | None = None,
    ):
        self.model = model
        self.settings = dict(settings)
        self.geometry_every = max(int(geometry_every), 1)
        live = str(target) in ("spawn", "connect") or str(target).startswith(VIEWER_SCHEMES)
        self.batch = max(int(batch if batch is not None else (100 if live else 5000)), 1)
        if total_samples is not None and total_samples > 0:
            sends = max(round(total_samples / self.batch), 1)
            self.batch = -(-int(total_samples) // sends)  # the shares, rounded up
        self.batch_seconds = float(
            batch_seconds if batch_seconds is not None else (0.2 if live else 1.0)
        )
        self.cyclograph_ns = int(CYCLOGRAPH_PERIOD * 1e9)
        self.timebase = Timebase(tick_of(settings))
        self.samples = 0
        self._closed = False
        self.measured = bool(settings.get("sensors"))
        self._force_rows, self._force_cols, self._force_names = force_components(model)
        self._is_angle = np.array(model.force_is_moment, dtype=bool)
        self.rec = rr.RecordingStream("vjm_ros", recording_id=recording_id or uuid.uuid4())
        self._connect(target, default_blueprint(model, self.measured))
        self._log_static(scene_text or model.source_text)
        self.rec.flush(timeout_sec=0.0)  # the static entities go out while the run is set up
        self._allocate_series()
        self._geo: list[tuple] = []  # (times, segments, points, closure points, forces)
        self._cyc: list[tuple] = []  # (times, segments)
        self._last_send = time.monotonic()
        self._next_cyclograph_ns = 0

    # ------------------------------------------------------------------ set-up
    def _connect(self, target: str | Path, blueprint: rrb.Blueprint) -> None:
        t = str(target)
        if t == "spawn":
            self.rec.spawn(default_blueprint=blueprint)
        elif t == "connect":
            self.rec.connect_grpc(default_blueprint=blueprint)
        elif t.startswith(VIEWER_SCHEMES):
            self.rec.connect_grpc(t, default_blueprint=blueprint)
        else:
            self.rec.save(t, default_blueprint=blueprint)
        self.target = t

    def _log_static(self, scene_text: str) -> None:
        log, model = self.rec.log, self.model
        self.rec.send_recording_name(model.name)
        run = {"scene": model.name, **self.settings, "package_versions": package_versions()}
        settings = json.dumps(run, indent=2, default=str)
        ground = [c.origin for c in model.chains]
        ground += [
            c.target.local for c in model.closures if c.target.link == GROUND and c.kind != ANGLE
        ]
        colors = _LINK_COLORS[model.chain_of % len(_LINK_COLORS)]
        static = [
            ("run/settings", rr.TextDocument(settings, media_type="text/plain")),
            ("run/scene", rr.TextDocument(scene_text, media_type="text/plain")),
            (ROOT, rr.Transform3D(mat3x3=np.diag([1.0, -1.0, 1.0]))),
            (f"{ROOT}/links", rr.LineStrips2D.from_fields(colors=colors, radii=0.008)),
            (f"{ROOT}/joints", rr.Points2D.from_fields(colors=[40, 40, 40], radii=0.015)),
            (f"{ROOT}/points", rr.Points2D.from_fields(labels=[p.name for p in model.points],
                                                       colors=[0, 0, 0], radii=0.012)),
            (f"{ROOT}/traces", rr.Points2D.from_fields(colors=[120, 120, 120], radii=0.003)),
            (f"{ROOT}/cyclograph",
             rr.LineStrips2D.from_fields(colors=[170, 170, 200, 90], radii=0.002)),
            (f"{ROOT}/forces", rr.Arrows2D.from_fields(labels=model.force_names,
                                                       colors=[220, 40, 30], radii=0.006)),
            (f"{ROOT}/ground", rr.Points2D(np.array(ground, dtype=float).reshape(-1, 2),
                                           colors=[0, 0, 0], radii=0.025)),
        ]
        series = {"position": model.joint_names, "velocity": model.joint_names,
                  "forces": self._force_names, "energy": list(messages.ENERGY_LABELS),
                  "error": model.closure_names}
        static += [(SERIES[key], rr.SeriesLines(names=labels)) for key, labels in series.items()]
        static += [(entity, rr.SeriesLines(names=model.joint_names))
                   for entity in (MEASURED if self.measured else ())]
        for entity, archetype in static:
            log(entity, archetype, static=True)

    def reserve(self, block_ticks: int) -> None:
        """Touch the pages of the series' buffers now (see :meth:`Recorder.reserve`)."""
        for buffer in (self._t, self._q, self._qd, self._force, self._energy, self._error,
                       self._measured):
            if buffer is not None:
                buffer.fill(0)

    def _allocate_series(self) -> None:
        """Fresh buffers of the series (the sent ones belong to rerun)."""
        b, n, k = self.batch, self.model.n, len(self.model.closures)
        self._t = np.empty(b, dtype=np.int64)
        self._q = np.empty((b, n))
        self._qd = np.empty((b, n))
        self._force = np.empty((b, len(self.model.force_names), 3))
        self._energy = np.empty((b, 4))
        self._error = np.empty((b, k))
        self._measured = np.empty((b, 3, n)) if self.measured else None
        self._count = 0

    # ------------------------------------------------------------------ writing
    @atomic
    def write_block(self, block: SampleBlock) -> None:
        """Buffer every row of a :class:`~vjm_ros.sim.samples.SampleBlock` by array slices.

        Logs what :meth:`write` of each row would (the same buffers, sends and geometry), except
        that the wall-time condition of a send is checked once per block.
        """
        self._check_open()
        rows = len(block)
        ns = self.timebase.to_ns_array(block.t[:rows])
        first = self.samples
        done = 0
        while done < rows:
            i = self._count
            take = min(self.batch - i, rows - done)
            part = slice(done, done + take)
            self._t[i : i + take] = ns[part]
            self._q[i : i + take] = block.q[part]
            self._qd[i : i + take] = block.qd[part]
            self._force[i : i + take] = block.force[part]
            self._energy[i : i + take] = block.energy[part]
            self._error[i : i + take] = block.error[part]
            if self.measured:
                self._measured[i : i + take] = block.measured[part]
            self._count = i + take
            self._keep_geometry(block, ns, first, part)
            done += take
            if self._count == self.batch:
                self.send()
        self.samples = first + rows
        if time.monotonic() - self._last_send >= self.batch_seconds:
            self.send()

    def _keep_geometry(self, block, ns: np.ndarray, first: int, rows: slice) -> None:
        """The drawing of every ``geometry_every``-th sample among ``rows`` of a block (copies:
        blocks are refilled), and the chrono-cyclograph's poses among them; ``first`` is the
        number of samples written before the block."""
        start = rows.start + (-(first + rows.start) % self.geometry_every)
        kept = np.arange(start, rows.stop, self.geometry_every)
        if len(kept) == 0:
            return
        times, segments = ns[kept], block.segments[kept]  # fancy indexing copies
        self._geo.append((times, segments, block.points[kept], block.cpoints[kept],
                          block.force[kept]))
        poses, due = [], self._next_cyclograph_ns
        for at, ns_at in enumerate(times.tolist()):  # each pose at least a period after the last
            if ns_at >= due:
                poses.append(at)
                due = ns_at + self.cyclograph_ns
        self._next_cyclograph_ns = due
        if poses:
            self._cyc.append((times[poses], segments[poses]))

    def send(self) -> None:
        """Send everything buffered so far: one chunk per entity, all in one call."""
        parts = self._series() + self._geometry()
        if parts:
            rr.send_chunks([Chunk.from_columns(*part) for part in parts], recording=self.rec)
        self._last_send = time.monotonic()

    def _series(self) -> list[tuple]:
        """``(entity, times, columns)`` of the buffered series.

        The buffers go to rerun as they are (the arrow arrays share their memory, which rerun's
        threads read after the call), and fresh ones take their place.
        """
        c = self._count
        if not c:
            return []
        t, q, qd, force = self._t[:c], self._q[:c], self._qd[:c], self._force[:c]
        energy, error = self._energy[:c], self._error[:c]
        measured = self._measured[:c] if self.measured else None
        self._allocate_series()
        series = [(SERIES["position"], q), (SERIES["velocity"], qd)]
        if len(self._force_names):
            series += [(SERIES["forces"], force[:, self._force_rows, self._force_cols]),
                       (SERIES["error"], error)]
        series.append((SERIES["energy"], energy))
        if measured is not None:
            series += [(entity, measured[:, f]) for f, entity in enumerate(MEASURED)]
        idx = [rr.TimeColumn(TIMELINE, duration=t.view("timedelta64[ns]"))]
        return [(entity, idx, [_scalars(values)]) for entity, values in series]

    def _geometry(self) -> list[tuple]:
        """``(entity, times, columns)`` of the kept drawings and chrono-cyclograph poses."""
        if not self._geo:
            return []
        ns, seg, pts, cpts, cf = (np.concatenate(part) for part in zip(*self._geo, strict=True))
        self._geo = []
        g = len(ns)
        idx = [rr.TimeColumn(TIMELINE, duration=ns.view("timedelta64[ns]"))]
        parts = [(f"{ROOT}/links", idx, [_strips(seg)]),
                 (f"{ROOT}/joints", idx, [_points(seg[:, :, 0, :])])]
        if len(self.model.points):
            points = [_points(pts)]
            parts += [(f"{ROOT}/points", idx, points), (f"{ROOT}/traces", idx, points)]
        k = len(self.model.force_names)
        if k:
            vectors = self._arrow_vectors(cf.reshape(g * k, 3)).reshape(g, k, 2)
            parts.append((f"{ROOT}/forces", idx, [
                _points(cpts, rr.Arrows2D.descriptor_origins()),
                _points(vectors, rr.Arrows2D.descriptor_vectors(), rr.components.Vector2DBatch)]))
        if self._cyc:
            cns, cseg = (np.concatenate(part) for part in zip(*self._cyc, strict=True))
            self._cyc = []
            cidx = [rr.TimeColumn(TIMELINE, duration=cns.view("timedelta64[ns]"))]
            parts.append((f"{ROOT}/cyclograph", cidx, [_strips(cseg)]))
        return parts

    def _arrow_vectors(self, forces: np.ndarray) -> np.ndarray:
        """Arrow vectors, m: ``messages.FORCE_SCALE * (fx, fy)``; a moment ``mz`` is drawn along +y."""
        vec = forces[:, :2].copy()
        moment = np.tile(self._is_angle, len(forces) // len(self._is_angle))
        vec[moment, 1] = forces[moment, 2]
        return messages.FORCE_SCALE * vec

    @atomic
    def note(self, text: str, level: str = "INFO", t: float | None = None) -> None:
        """Log ``text`` on ``events``.

        Parameters
        ----------
        text : str
        level : str
            Rerun text-log level (``"INFO"``, ``"WARN"``, ...).
        t : float, optional
            Simulator time of the current episode, s; the latest recording time when omitted.
        """
        self._check_open()
        self.send()
        ns = self.timebase.to_ns(t) if t is not None else (self.timebase.last_ns or 0)
        self.rec.set_time(TIMELINE, duration=np.timedelta64(ns, "ns"))
        self.rec.log("events", rr.TextLog(text, level=level))

    @atomic
    def note_reset(self, t: float | None = None, tick: float | None = None) -> None:
        """Mark a simulator reset (see :meth:`vjm_ros.logs.McapRecorder.note_reset`)."""
        self._check_open()
        self.send()
        ns, text = self._reset_event(t, tick)
        self._next_cyclograph_ns = ns
        self.rec.set_time(TIMELINE, duration=np.timedelta64(ns, "ns"))
        self.rec.log("events", rr.TextLog(text, level="INFO"))

    # ------------------------------------------------------------------ closing
    def _finalize(self) -> None:
        """Send what is buffered, flush and close the sink."""
        try:
            self.send()
            self.rec.flush()
        finally:
            self.rec.disconnect()
