"""The thesis figure set of one run, as PNG files (docs/design.md section 5, ``vjm run --plots``).

Six figures, one per file, in the order of every example of thesis chapter 4:

=========================  ===================================================================
``chrono_cyclograph.png``  the mechanism drawn at regular time intervals, tip traces, ground
``displacements.png``      absolute link angles ``theta_i`` (rad); joint slides (m) if any
``velocities.png``         absolute angular velocities (rad/s); slide rates (m/s) if any
``accelerations.png``      absolute angular accelerations (rad/s^2); slide accelerations (m/s^2)
``constraint_forces.png``  closure forces ``Fx``, ``Fy`` (N); moments ``Mz`` (N m) of angle closures
``energy.png``             kinetic, potential, constraint (penalty only) and total energy (J)
=========================  ===================================================================

The absolute angular velocity of link ``i`` is ``sum_k A[i, k] r_k qd_k`` with ``A`` the ancestor
matrix and ``r_k = 1`` for revolute joints (prismatic joints do not turn the links after them);
the acceleration uses ``qdd`` the same way.

Figures are plain :class:`matplotlib.figure.Figure` objects drawn by the Agg canvas, so no pyplot
state is touched and nothing needs a display. Time series longer than a few thousand samples are
reduced to the smallest and largest value of each of a few thousand time buckets, which keeps every
peak of the full series (and therefore the axis limits) and keeps the drawing time of long runs
nearly independent of their length.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection
from matplotlib.colors import LinearSegmentedColormap, Normalize, to_rgb
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from vjm_ros.core.model import GROUND, HINGE, SLIDER, Model
from vjm_ros.sim.trajectory import Trajectory

FIGURE_NAMES = (
    "chrono_cyclograph",
    "displacements",
    "velocities",
    "accelerations",
    "constraint_forces",
    "energy",
)
"""File stems written by :func:`write_figures`, in order."""

MAX_LINE_POINTS = 4000
"""Largest number of vertices drawn per time-series line."""

N_POSES = 32
"""Number of mechanism poses drawn in the chrono-cyclograph."""

MAX_LEGEND_ENTRIES = 24
"""Legends with more entries than this are left out (the figure would be all legend)."""

_CHAIN_STYLES = ("-", "--", ":", "-.")
_SERIES_SIZE = (8.0, 4.5)
_TWO_PANEL_SIZE = (8.0, 6.8)
_CYCLOGRAPH_SIZE = (8.0, 6.5)


# ---------------------------------------------------------------------------- public API
def write_figures(
    traj: Trajectory,
    out_dir: str | Path,
    title: str | None = None,
    dpi: int = 120,
) -> list[Path]:
    """Write the thesis figure set of a run as six PNG files.

    Parameters
    ----------
    traj : Trajectory
        The run; at least one sample.
    out_dir : str or Path
        Directory for the files (created if missing).
    title : str, optional
        Name put in front of every figure title; the scene name when omitted.
    dpi : int
        Resolution of the PNG files, dots per inch.

    Returns
    -------
    list of Path
        ``chrono_cyclograph.png``, ``displacements.png``, ``velocities.png``,
        ``accelerations.png``, ``constraint_forces.png`` and ``energy.png`` under ``out_dir``, in
        that order.

    Raises
    ------
    ValueError
        If the trajectory holds no samples or ``dpi`` is not positive.
    """
    if len(traj) == 0:
        raise ValueError("cannot plot an empty trajectory")
    if dpi <= 0:
        raise ValueError(f"dpi must be positive, got {dpi}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    name = title if title is not None else traj.model.name
    builders = (chrono_cyclograph_figure,
                *(partial(kinematics_figure, kind=kind) for kind in _KINEMATICS),
                constraint_forces_figure, energy_figure)
    paths = []
    for stem, build in zip(FIGURE_NAMES, builders, strict=True):
        with np.errstate(invalid="ignore", over="ignore"):
            fig = build(traj, name)
        path = out / f"{stem}.png"
        fig.savefig(path, dpi=dpi)
        fig.clear()
        paths.append(path)
    return paths


def absolute_rates(model: Model, rates: np.ndarray) -> np.ndarray:
    """Absolute angular rates of the links from joint rates.

    Parameters
    ----------
    model : Model
    rates : ndarray, shape (rows, n)
        Joint velocities ``qd`` (or accelerations ``qdd``); prismatic entries are ignored.

    Returns
    -------
    ndarray, shape (rows, n)
        ``omega_i = sum_k ancestors[i, k] is_revolute[k] rates_k``, rad/s (rad/s^2).
    """
    with np.errstate(invalid="ignore", over="ignore"):  # a diverged run keeps its NaN rows
        return (rates * model.is_revolute[None, :]) @ model.ancestors.T


# ---------------------------------------------------------------------------- figures
def chrono_cyclograph_figure(traj: Trajectory, name: str) -> Figure:
    """The mechanism at regular time intervals, with tip traces and ground points.

    Parameters
    ----------
    traj : Trajectory
    name : str
        Title prefix.

    Returns
    -------
    Figure
    """
    model = traj.model
    t = traj["t"]
    segments = traj["segments"]
    fig = _new_figure(_CYCLOGRAPH_SIZE)
    ax = fig.add_subplot()
    poses = _pose_rows(t, N_POSES)
    cmaps, handles = _draw_poses(ax, model, segments[poses])
    handles += _draw_traces(ax, model, traj["points"], cmaps)
    handles += _draw_ground(ax, _ground_geometry(model, segments[0]))
    ax.autoscale_view()
    ax.margins(0.08)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, lw=0.4, alpha=0.5)
    if len(poses) > 1:
        when = f"{len(poses)} poses over t = {t[0]:.3g} to {t[-1]:.3g} s"
    else:
        when = f"pose at t = {t[0]:.3g} s"
    ax.set_title(f"{name}: chrono-cyclograph, {when}")
    _legend(ax, handles, below=True)
    if len(poses) > 1:
        single = len(model.chains) == 1
        bar_map = cmaps[0] if single else _shade_map((0.0, 0.0, 0.0))
        t_end = t[-1] if t[-1] > t[0] else t[0] + 1.0
        sm = ScalarMappable(norm=Normalize(t[0], t_end), cmap=bar_map)
        bar = fig.colorbar(sm, ax=ax, shrink=0.8, pad=0.02)
        bar.set_label("pose time t (s)" + ("" if single else ", shade of each chain colour"))
    return fig


def _draw_poses(ax, model, pose_segments: np.ndarray) -> tuple[list, list]:
    """Each chain's links at the chosen poses, later poses darker; its colour maps and legend."""
    shade = np.linspace(0.0, 1.0, len(pose_segments)) if len(pose_segments) > 1 else np.ones(1)
    handles: list = []
    cmaps = []
    for c, chain in enumerate(model.chains):
        base = to_rgb(f"C{c % 10}")
        cmap = _shade_map(base)
        cmaps.append(cmap)
        style = _chain_style(c)
        if not chain.links:
            continue
        lines = _chain_polylines(pose_segments, chain.links)
        coll = LineCollection(
            list(lines),
            colors=cmap(0.15 + 0.85 * shade),
            linewidths=0.9,
            linestyles=style,
            zorder=2,
        )
        ax.add_collection(coll, autolim=True)
        last = lines[-1]
        ax.plot(last[:, 0], last[:, 1], "o", ms=3.0, color=cmap(1.0), zorder=3)
        handles.append(Line2D([], [], color=base, lw=1.5, ls=style, label=f"{chain.name} links"))
    return cmaps, handles


def _draw_traces(ax, model, points: np.ndarray, cmaps: list) -> list:
    """The path of every named point (chain tips in their chain's colour); legend handles."""
    handles = []
    tip_chain = {f"{ch.name}_tip": c for c, ch in enumerate(model.chains)}
    for p, point in enumerate(model.points):
        xy = points[:, p]
        idx = _envelope_index(xy, MAX_LINE_POINTS)
        c = tip_chain.get(point.name)
        color, ls = (cmaps[c](1.0), "-") if c is not None else ("0.35", "--")
        (line,) = ax.plot(
            xy[idx, 0],
            xy[idx, 1],
            ls=ls,
            lw=1.3,
            color=color,
            zorder=4,
            label=f"{point.name} trace",
        )
        handles.append(line)
    return handles


def _draw_ground(ax, ground) -> list:
    """Ground links, slider guides and ground pivots; legend handles."""
    handles = []
    for k, (start, end) in enumerate(ground.links):
        ax.plot(*np.transpose([start, end]), color="0.25", lw=2.5, solid_capstyle="round", zorder=1)
        if k == 0:
            handles.append(Line2D([], [], color="0.25", lw=2.5, label="ground link"))
    guide_style = {"color": "0.4", "lw": 0.8, "ls": (0, (6, 3)), "zorder": 1}
    for origin, direction in ground.guides:
        ax.axline(tuple(origin), xy2=tuple(origin + direction), **guide_style)
    if ground.guides:
        handles.append(Line2D([], [], label="slider guide", **guide_style))
    if len(ground.pivots):
        pivot_style = {"ls": "none", "marker": "^", "ms": 10, "mfc": "0.85", "mec": "k", "mew": 1.0}
        ax.plot(ground.pivots[:, 0], ground.pivots[:, 1], zorder=5, **pivot_style)
        ax.plot(ground.pivots[:, 0], ground.pivots[:, 1], "k.", ms=4, zorder=6)
        handles.append(Line2D([], [], label="ground point", **pivot_style))
    return handles


_KINEMATICS = {
    "displacements": (
        ("theta", "q"),
        (r"angular displacement $\theta$ (rad)", "slide B (m)"),
        ("absolute link angles", "prismatic joint slides"),
    ),
    "velocities": (
        (None, "qd"),
        (r"angular velocity $\omega$ (rad/s)", "slide rate (m/s)"),
        ("absolute angular velocities of the links", "prismatic joint velocities"),
    ),
    "accelerations": (
        (None, "qdd"),
        (r"angular acceleration $\alpha$ (rad/s$^2$)", "slide acceleration (m/s$^2$)"),
        ("absolute angular accelerations of the links", "prismatic joint accelerations"),
    ),
}
"""Columns, axis labels and panel titles of the three kinematic figures, in the order of
:data:`FIGURE_NAMES`."""


def kinematics_figure(traj: Trajectory, name: str, kind: str) -> Figure:
    """Angular quantity per link on top; the prismatic joints' coordinates of ``kind`` below.

    ``kind`` is a key of :data:`_KINEMATICS`: absolute link angles and joint slides
    (``"displacements"``), their rates (``"velocities"``) or accelerations
    (``"accelerations"``). Other arguments and result as :func:`chrono_cyclograph_figure`.
    """
    (angles, coords), ylabels, titles = _KINEMATICS[kind]
    model = traj.model
    joint = traj[coords]
    angular = traj[angles] if angles else absolute_rates(model, joint)
    prismatic = np.flatnonzero(~model.is_revolute)
    fig = _new_figure(_TWO_PANEL_SIZE if len(prismatic) else _SERIES_SIZE)
    fig.suptitle(f"{name}: {kind}")

    def style(i: int, label: str) -> dict:
        return {"color": _link_color(i, model.n), "ls": _chain_style(model.links[i].chain),
                "label": label}

    _fill_panels(fig, traj["t"], [
        (ylabels[0], titles[0],
         [(angular[:, i], style(i, link.name)) for i, link in enumerate(model.links)]),
        (ylabels[1], titles[1], [(joint[:, i], style(i, model.joints[i].name)) for i in prismatic]),
    ])
    return fig


def constraint_forces_figure(traj: Trajectory, name: str) -> Figure:
    """World-frame closure forces (and moments of angle closures) against time.

    Arguments and result as :func:`chrono_cyclograph_figure`.
    """
    model = traj.model
    t = traj["t"]
    force = traj["force"]
    names, moment = model.force_names, model.force_is_moment  # closures, then stops
    point_closures = [k for k, m in enumerate(moment) if not m]
    angle_closures = [k for k, m in enumerate(moment) if m]
    fig = _new_figure(_TWO_PANEL_SIZE if point_closures and angle_closures else _SERIES_SIZE)
    fig.suptitle(f"{name}: constraint forces at the closure points")
    if not moment:
        ax = fig.add_subplot()
        ax.text(
            0.5, 0.5, "no closures in this scene", ha="center", va="center", transform=ax.transAxes
        )
        ax.set_xlabel("t (s)")
        ax.set_ylabel("force (N)")
        return fig
    point_series = [
        (force[:, k, axis], {"color": f"C{j % 10}", "ls": ls, "label": f"{names[k]} F{xy}"})
        for j, k in enumerate(point_closures)
        for axis, xy, ls in ((0, "x", "-"), (1, "y", "--"))
    ]
    angle_series = [
        (force[:, k, 2], {"color": f"C{(j + len(point_closures)) % 10}", "ls": "-",
                          "label": f"{names[k]} Mz"})
        for j, k in enumerate(angle_closures)
    ]
    _fill_panels(fig, t, [
        ("force (N)", "forces on the constrained points, world frame", point_series),
        ("moment (N m)", "moments of the angle closures and the stops", angle_series),
    ])
    return fig


def energy_figure(traj: Trajectory, name: str) -> Figure:
    """Kinetic, potential, constraint (if non-zero) and total energy against time.

    Arguments and result as :func:`chrono_cyclograph_figure`.
    """
    t = traj["t"]
    energy = traj["energy"]
    series = [
        (energy[:, 0], {"color": "C0", "ls": "-", "label": "kinetic T"}),
        (energy[:, 1], {"color": "C1", "ls": "-", "label": "potential V"}),
        (energy[:, 2], {"color": "C2", "ls": ":", "label": "constraint (penalty)"}),
        (energy[:, 3], {"color": "k", "ls": "-", "lw": 1.8, "label": "total"}),
    ]
    if not np.any(energy[:, 2] != 0.0):
        del series[2]
    fig = _new_figure(_SERIES_SIZE)
    fig.suptitle(f"{name}: kinetic, potential and total energy")
    _fill_panels(fig, t, [("energy (J)", "", series)])
    return fig


# ---------------------------------------------------------------------------- helpers
def _new_figure(size: tuple[float, float]) -> Figure:
    """A pyplot-free figure with an Agg canvas and constrained layout."""
    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _fill_panels(fig: Figure, t: np.ndarray, panels: Sequence[tuple[str, str, list]]) -> None:
    """One panel per entry with series, stacked over a common time axis.

    ``panels`` holds ``(ylabel, panel title, series)`` with ``series`` a list of ``(y, style)``,
    ``y`` of shape (rows,) and ``style`` the keywords of :func:`_series`; panels without series
    are left out.
    """
    panels = [panel for panel in panels if panel[2]]
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (ylabel, title, series) in zip(axes, panels, strict=True):
        for y, style in series:
            _series(ax, t, y, **style)
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize="medium")
        _legend(ax, ax.get_lines())
    _time_axes(axes, t)


def _series(
    ax, t: np.ndarray, y: np.ndarray, *, color, ls: str, label: str, lw: float = 1.2
) -> None:
    """Plot one time series, reduced to its per-bucket extremes when long."""
    idx = _envelope_index(y, MAX_LINE_POINTS)
    ax.plot(t[idx], y[idx], color=color, ls=ls, lw=lw, label=label)


def _time_axes(axes: Sequence, t: np.ndarray) -> None:
    """Common time axis: tight limits, grid, label on the bottom panel."""
    for ax in axes:
        if t[-1] > t[0]:
            ax.set_xlim(t[0], t[-1])
        ax.grid(True, lw=0.4, alpha=0.5)
    axes[-1].set_xlabel("t (s)")


def _legend(ax, handles: Sequence, below: bool = False) -> None:
    """Legend outside the axes (kept off the curves), unless there are too many entries.

    To the right of the axes by default; under them when ``below`` (the right side then holds a
    colour bar).
    """
    handles = [h for h in handles if not str(h.get_label()).startswith("_")]
    if not handles or len(handles) > MAX_LEGEND_ENTRIES:
        return
    if below:
        place = {"loc": "upper center", "bbox_to_anchor": (0.5, -0.1), "ncol": min(len(handles), 3)}
    else:
        place = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "ncol": 1 + len(handles) // 13}
    ax.legend(handles=handles, borderaxespad=0.0, fontsize="small", frameon=False, **place)


def _envelope_index(y: np.ndarray, max_points: int) -> np.ndarray:
    """Row indices that keep the smallest and largest value of each of ``max_points // 2`` buckets.

    Parameters
    ----------
    y : ndarray, shape (rows,) or (rows, m)
        Series; for 2-D input the extremes of every column are kept (union).
    max_points : int
        Target number of indices per column.

    Returns
    -------
    ndarray of int
        Sorted unique row indices including the first and last row.
    """
    rows = len(y)
    if rows <= max_points:
        return np.arange(rows)
    buckets = max(max_points // 2, 1)
    width = rows // buckets
    body = buckets * width
    starts = np.arange(buckets) * width
    parts = [np.array([0, rows - 1])]
    for col in y.reshape(rows, -1).T:
        finite = np.isfinite(col)
        lo = np.where(finite, col, np.inf)
        hi = np.where(finite, col, -np.inf)
        parts.append(starts + np.argmin(lo[:body].reshape(buckets, width), axis=1))
        parts.append(starts + np.argmax(hi[:body].reshape(buckets, width), axis=1))
        if body < rows:
            parts.append(body + np.array([np.argmin(lo[body:]), np.argmax(hi[body:])]))
    return np.unique(np.concatenate(parts))


def _pose_rows(t: np.ndarray, count: int) -> np.ndarray:
    """Rows nearest to ``count`` equally spaced times over the run (unique, ascending)."""
    if len(t) <= count:
        return np.arange(len(t))
    times = np.linspace(t[0], t[-1], count)
    rows = np.clip(np.searchsorted(t, times), 0, len(t) - 1)
    return np.unique(rows)


def _chain_polylines(segments: np.ndarray, links: Sequence[int]) -> np.ndarray:
    """One polyline per pose through the start and end of each link of a chain.

    The pieces between the end of a link and the start of the next one are the joint slides
    (zero length for revolute joints with no slide), so the chain is drawn connected.

    Returns
    -------
    ndarray, shape (poses, 2 * len(links), 2)
    """
    return segments[:, list(links)].reshape(len(segments), 2 * len(links), 2)


@dataclass(frozen=True)
class _Ground:
    """Fixed geometry of a scene, m: pivots (n, 2), ground links and slider guide lines."""

    pivots: np.ndarray
    links: list[tuple[np.ndarray, np.ndarray]]
    guides: list[tuple[np.ndarray, np.ndarray]]


def _ground_geometry(model: Model, segments: np.ndarray) -> _Ground:
    """Ground points, ground links and slider guides of a scene.

    Each chain contributes its ground point ``O``; a ground link from ``O`` to its first joint
    when that is not at ``O``; the first joint as a fixed pivot if revolute, or the guide line
    through it along ``n(theta1)`` if prismatic. Hinge closures to the ground add their target
    point, slider closures to the ground their line.

    Parameters
    ----------
    model : Model
    segments : ndarray, shape (n, 2, 2)
        Link segments of one pose (the first joint of a revolute chain does not move).
    """
    pivots = []
    links = []
    guides = []
    for chain in model.chains:
        origin = np.asarray(chain.origin, dtype=float)
        pivots.append(origin)
        if not chain.links:
            continue
        first = chain.links[0]
        u = np.array([np.cos(chain.angle), np.sin(chain.angle)])
        if model.is_revolute[first]:
            joint = segments[first, 0]
            pivots.append(joint)
        else:
            joint = origin + chain.length * u
            guides.append((joint, np.array([-u[1], u[0]])))
        if np.linalg.norm(joint - origin) > 0:
            links.append((origin, joint))
    for c in model.closures:
        if c.target.link != GROUND:
            continue
        target = np.asarray(c.target.local, dtype=float)
        if c.kind == HINGE:
            pivots.append(target)
        elif c.kind == SLIDER and np.linalg.norm(c.direction) > 0:
            guides.append((target, np.asarray(c.direction, dtype=float)))
    unique = np.unique(np.round(np.array(pivots), 12), axis=0) if pivots else np.zeros((0, 2))
    return _Ground(unique, links, guides)


def _shade_map(base: Sequence[float]) -> LinearSegmentedColormap:
    """Colormap from a light tint of ``base`` (early poses) through ``base`` to a dark shade."""
    base = np.asarray(base, dtype=float)
    light = 0.78 + 0.22 * base
    dark = 0.55 * base
    return LinearSegmentedColormap.from_list("pose_shade", [light, base, dark])


def _link_color(i: int, n: int) -> str | tuple[float, ...]:
    """Colour of link ``i`` among ``n`` (tab10 while it suffices, then tab20)."""
    return f"C{i % 10}" if n <= 10 else colormaps["tab20"](i % 20)


def _chain_style(chain: int) -> str:
    """Line style of a chain (first chain solid, second dashed, third dotted, as in the thesis)."""
    return _CHAIN_STYLES[chain % len(_CHAIN_STYLES)]
