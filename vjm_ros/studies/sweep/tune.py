"""Penalty gain tuning: the (omega_n, zeta) that keep a scene's closures tightest for an integrator
and step, within the stability bound, from a sweep (``vjm tune``).

The thesis leaves the choice of penalty gains open. For one integrator, tick rate and substeps
the sweep runs a grid of natural frequencies (log-spaced) and damping ratios; the stiffness
check refuses the gains the method cannot carry (``omega_n h`` beyond its stability bound, on
the coupled closure modes), and those rows are kept as refused. The runs last the scene's own
duration by default: the closure modes stiffen as the pose changes, so gains that pass the
check at the start pose and hold for one second may still diverge later.

The *stability edge* of a damping ratio is the smallest natural frequency refused or diverged
above one that ran (gains too soft to hold the closures, below, diverge too, for another
reason); damping lowers the edge of the explicit methods, so each ratio has its own. The chosen
gains keep a margin from it: ``omega_n <= edge / MARGIN``, so that a longer run, another pose or
a change of load does not take them over. Among those rows, the chosen gains give the smallest
largest closure error; the Pareto front of closure error against cost (wall time per simulated
second) shows what cheaper settings give up.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from vjm_ros.scene import load_scene
from vjm_ros.studies.bench.analysis import lowest_front
from vjm_ros.studies.sweep.spec import SweepSpec
from vjm_ros.studies.sweep.summary import readable_axis

if TYPE_CHECKING:
    from matplotlib.figure import Figure

OMEGA_N = tuple(float(w) for w in np.geomspace(10.0, 3000.0, 12).round(1))
"""Natural frequencies tried, rad/s (10 to 3000, log-spaced)."""
ZETA = (0.5, 0.7, 1.0, 1.5, 2.0)
"""Damping ratios tried."""
MARGIN = 2.0
"""Factor between the stability edge and the largest natural frequency chosen: the grid's step
is a factor 1.68, so the chosen gains are at least one grid step below any that failed (a factor
4 in stiffness)."""
FAILED_STATUSES = ("diverged", "refused (stiffness)")


def tuning_spec(scene: str, integrator: str, rate: float, substeps: int,
                duration: float | None = None) -> SweepSpec:
    """The sweep of penalty gains for one scene, integrator and step (``duration`` s per run;
    None: the scene's own)."""
    if duration is None:
        duration = float(load_scene(scene).defaults.get("duration", 10.0))
    return SweepSpec(
        name=f"tune_{Path(scene).stem}",
        scenes=[scene],
        settings={"closure": "penalty", "integrator": integrator, "rate": rate,
                  "substeps": substeps},
        axes={"omega_n": list(OMEGA_N), "zeta": list(ZETA)},
        duration=duration,
        reference=False,
        source=f"vjm tune {scene}",
    )


def read_rows(table: str | Path) -> list[dict]:
    """Rows of a results table, numbers as floats (empty cells None)."""
    out = []
    with Path(table).open(newline="") as f:
        for row in csv.DictReader(f):
            parsed = {}
            for k, v in row.items():
                if v == "":
                    parsed[k] = None
                else:
                    try:
                        parsed[k] = float(v)
                    except ValueError:
                        parsed[k] = v
            out.append(parsed)
    return out


def pareto_front(rows: list[dict]) -> list[dict]:
    """Rows no other row beats on both wall time and largest closure error, cheapest first."""
    return lowest_front([r for r in rows if r.get("status") == "ok"],
                        lambda r: r.get("wall_time"), lambda r: r.get("max_closure_error"))


def stability_edge(rows: list[dict]) -> dict[float, float | None]:
    """Per damping ratio, the smallest natural frequency (rad/s) refused or diverged above the
    smallest that ran; None where none failed above it (or none ran)."""
    edges: dict[float, float | None] = {}
    for zeta in sorted({r["zeta"] for r in rows}):
        mine = [r for r in rows if r["zeta"] == zeta]
        ran = [r["omega_n"] for r in mine if r.get("status") == "ok"]
        failed = [r["omega_n"] for r in mine
                  if r.get("status") in FAILED_STATUSES and ran and r["omega_n"] > min(ran)]
        edges[zeta] = min(failed) if failed else None
    return edges


def choose(rows: list[dict], edges: dict[float, float | None] | None = None) -> dict | None:
    """The row with the smallest largest closure error (then the cheapest) among those that ran
    with ``omega_n <= edge / MARGIN`` (``edges`` per damping ratio, :func:`stability_edge`;
    None: no margin), or None."""
    def limit(zeta: float) -> float:
        edge = (edges or {}).get(zeta)
        return math.inf if edge is None else edge / MARGIN

    ok = [r for r in rows if r.get("status") == "ok" and r.get("max_closure_error") is not None
          and r["omega_n"] <= limit(r["zeta"])]
    return min(ok, key=lambda r: (r["max_closure_error"], r.get("wall_time") or 0.0)) if ok else None


def gains_snippet(row: dict, scene: str, integrator: str, rate: float, substeps: int,
                  edge: float | None = None) -> str:
    """The chosen gains as a scene-file snippet, with what they were tuned for."""
    doc = {"closure_method": {"method": "penalty", "omega_n": float(row["omega_n"]),
                              "zeta": float(row["zeta"])}}
    limit = ("no gains of the grid failed" if edge is None else
             f"a factor {edge / float(row['omega_n']):.3g} below the stability edge "
             f"(omega_n {edge:g} rad/s refused or diverged)")
    note = (f"# tuned by vjm tune for {scene} with {integrator} at {rate:g} Hz x{substeps}: "
            f"largest closure error {row['max_closure_error']:.3g} m over "
            f"{row['duration']:g} s; {limit}\n")
    return note + yaml.safe_dump(doc, sort_keys=False)


def plot_tuning(rows: list[dict], front: list[dict], chosen: dict | None, path: str | Path,
                title: str) -> Path:
    """Closure error against cost of every row that ran, the front and the choice (PNG)."""
    import matplotlib.pyplot as plt

    fig = tuning_figure(rows, front, chosen, title)
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def tuning_figure(rows: list[dict], front: list[dict], chosen: dict | None,
                  title: str) -> Figure:
    """The figure of :func:`plot_tuning` (a matplotlib Figure, Agg canvas)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if r.get("status") == "ok" and r.get("wall_time")]
    fig, ax = plt.subplots(figsize=(7.0, 4.6), dpi=110)
    if ok:
        sc = ax.scatter([r["wall_time"] / r["duration"] * 1e3 for r in ok],
                        [r["max_closure_error"] for r in ok],
                        c=[math.log10(r["omega_n"]) for r in ok], cmap="viridis", s=22)
        fig.colorbar(sc, ax=ax, label="log10 omega_n (rad/s)")
    if front:
        ax.plot([r["wall_time"] / r["duration"] * 1e3 for r in front],
                [r["max_closure_error"] for r in front], "k-", lw=1.0, label="Pareto front")
    if chosen is not None:
        ax.plot(chosen["wall_time"] / chosen["duration"] * 1e3, chosen["max_closure_error"], "r*",
                ms=14, label=f"chosen: omega_n {chosen['omega_n']:g}, zeta {chosen['zeta']:g}")
    refused = sum(1 for r in rows if str(r.get("status", "")).startswith("refused"))
    diverged = sum(1 for r in rows if r.get("status") == "diverged")
    costs = [r["wall_time"] / r["duration"] * 1e3 for r in ok]
    readable_axis(ax.xaxis, ax.set_xscale, costs)
    readable_axis(ax.yaxis, ax.set_yscale, [r["max_closure_error"] for r in ok])
    ax.set_xlabel("cost: wall time per simulated second (ms)")
    ax.set_ylabel("largest closure error (m)")
    edge_note = f"; chosen a factor {MARGIN:g} below the stability edge"
    ax.set_title(f"{title}\n{len(ok)} ran, {refused} beyond the stability bound, "
                 f"{diverged} diverged{edge_note}", fontsize=9)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return fig
