"""What ``vjm sweep`` tells a reader at the end: a few lines of counts, and a figure on request.

The lines say how many rows the table holds per status, how many ran this time and how many were
kept from before, the wall time and where the table is. The figure (``--figure Y,X``) plots one
measure against another for every row that ran, one colour per setting of the grid's first
axis that takes words (the integrator, say), else per scene.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from vjm_ros.core.errors import ConfigurationError
from vjm_ros.studies.sweep.run import MEASURES
from vjm_ros.studies.sweep.spec import SweepSpec

if TYPE_CHECKING:
    from matplotlib.axis import Axis

    from vjm_ros.studies.sweep.engine import Sweep

PLOTTABLE = tuple(m for m in MEASURES if m not in ("status", "message", "finite"))
"""Measures a figure can show."""
UNITS = {"diverged_at": "s", "max_closure_error": "m or rad", "rms_closure_error": "m or rad",
         "energy_drift": "1", "energy_balance_residual": "J", "position_deviation": "m",
         "tip_deviation": "m", "wall_time": "s"}


def readable_axis(axis: Axis, set_scale: Callable[[str], object], values: list[float]) -> None:
    """A log axis with at most a few labelled ticks, or a linear one where the values span less
    than a decade (where log ticks would all be minor ones, their labels crowding) or are not
    all positive."""
    from matplotlib.ticker import LogLocator, MaxNLocator, NullFormatter

    values = [v for v in values if math.isfinite(v)]
    if not values or min(values) <= 0 or max(values) < 10 * min(values):
        set_scale("linear")
        axis.set_major_locator(MaxNLocator(5))
        return
    set_scale("log")
    axis.set_major_locator(LogLocator(base=10, numticks=6))
    axis.set_minor_formatter(NullFormatter())


def summary_lines(result: dict) -> list[str]:
    """Human-readable lines of a sweep's result (the dict of :meth:`Sweep.run`)."""
    counts = ", ".join(f"{n} {status}" for status, n in result["statuses"].items() if n)
    total = sum(result["statuses"].values())
    lines = [f"{total} rows in {result['csv']} (and {result['parquet']}): {counts or 'none'}",
             f"{result['run']} run this time, {result['skipped']} kept from before"
             + (f", {result['retried']} 'error' rows run again" if result.get("retried") else "")
             + (f", {result['dropped']} rows no longer in the spec dropped"
                if result.get("dropped") else "")
             + (f", {result['same_as_another']} the same run as another row (filled from it, "
                "see message)" if result.get("same_as_another") else "")
             + f"; {result['wall_time']:.1f} s"]
    if result.get("figure"):
        lines.append(f"figure: {result['figure']}")
    return lines


def parse_figure(text: str) -> tuple[str, str]:
    """``Y,X`` of ``--figure``: two measures.

    Raises
    ------
    ConfigurationError
        Naming ``--figure`` and the measures it may take.
    """
    names = [t.strip() for t in text.split(",")]
    if len(names) != 2 or not all(n in PLOTTABLE for n in names):
        raise ConfigurationError(
            f"--figure: expected two measures Y,X of {', '.join(PLOTTABLE)}, found {text!r}")
    return names[0], names[1]


def _group_key(spec: SweepSpec) -> str:
    for name, values in spec.axes.items():
        if any(isinstance(v, str) for v in values):
            return name
    return "scene"


def plot_sweep(sweep: Sweep, y: str, x: str, path: str | Path) -> Path:
    """Measure ``y`` against ``x`` of every row of the table with both (PNG, log axes where the
    values are positive)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from vjm_ros.studies.sweep.tune import read_rows

    rows = [r for r in read_rows(sweep.start.path)
            if isinstance(r.get(x), float) and isinstance(r.get(y), float)
            and math.isfinite(r[x]) and math.isfinite(r[y])]
    group = _group_key(sweep.spec)
    fig, ax = plt.subplots(figsize=(7.0, 4.6), dpi=110)
    for value in dict.fromkeys(str(r.get(group)) for r in rows):
        mine = [r for r in rows if str(r.get(group)) == value]
        ax.scatter([r[x] for r in mine], [r[y] for r in mine], s=18, label=f"{group} {value}")
    readable_axis(ax.xaxis, ax.set_xscale, [r[x] for r in rows])
    readable_axis(ax.yaxis, ax.set_yscale, [r[y] for r in rows])
    ax.set_xlabel(f"{x} ({UNITS[x]})")
    ax.set_ylabel(f"{y} ({UNITS[y]})")
    ax.set_title(f"{sweep.spec.name}: {len(rows)} rows with both measures", fontsize=9)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    if rows:
        ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)
