"""Penalty gain tuning: the (omega_n, zeta) that keep a scene's closures tightest for an integrator
and step, within the stability bound, from a sweep (``vjm tune``).

The thesis leaves the choice of penalty gains open. For one integrator, tick rate and substeps
the sweep runs a grid of natural frequencies (log-spaced) and damping ratios; the stiffness
check refuses the gains the method cannot carry (``omega_n h`` beyond its stability bound, on
the coupled closure modes), and those rows are kept as refused. Among the rows that ran, the
chosen gains give the smallest largest closure error; the Pareto front of closure error against
cost (wall time per simulated second) shows what cheaper settings give up.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import yaml

from vjm_ros.studies.sweep.spec import SweepSpec

OMEGA_N = tuple(float(w) for w in np.geomspace(10.0, 3000.0, 12).round(1))
"""Natural frequencies tried, rad/s (10 to 3000, log-spaced)."""
ZETA = (0.5, 0.7, 1.0, 1.5, 2.0)
"""Damping ratios tried."""


def tuning_spec(scene: str, integrator: str, rate: float, substeps: int, duration: float,
                omega_n=OMEGA_N, zeta=ZETA) -> SweepSpec:
    """The sweep of penalty gains for one scene, integrator and step."""
    return SweepSpec(
        name=f"tune_{Path(scene).stem}",
        scenes=[scene],
        settings={"closure": "penalty", "integrator": integrator, "rate": rate,
                  "substeps": substeps},
        axes={"omega_n": list(omega_n), "zeta": list(zeta)},
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


def pareto_front(rows: list[dict], cost: str = "wall_time",
                 error: str = "max_closure_error") -> list[dict]:
    """Rows no other row beats on both cost and error, cheapest first."""
    ok = sorted((r for r in rows if r.get("status") == "ok" and r.get(cost) is not None
                 and r.get(error) is not None), key=lambda r: (r[cost], r[error]))
    front, best = [], math.inf
    for r in ok:
        if r[error] < best:
            front.append(r)
            best = r[error]
    return front


def choose(rows: list[dict]) -> dict | None:
    """The row with the smallest largest closure error (then the cheapest), or None."""
    ok = [r for r in rows if r.get("status") == "ok" and r.get("max_closure_error") is not None]
    return min(ok, key=lambda r: (r["max_closure_error"], r.get("wall_time") or 0.0)) if ok else None


def gains_snippet(row: dict, scene: str, integrator: str, rate: float, substeps: int) -> str:
    """The chosen gains as a scene-file snippet, with what they were tuned for."""
    doc = {"closure_method": {"method": "penalty", "omega_n": float(row["omega_n"]),
                              "zeta": float(row["zeta"])}}
    note = (f"# tuned by vjm tune for {scene} with {integrator} at {rate:g} Hz x{substeps}: "
            f"largest closure error {row['max_closure_error']:.3g} m over "
            f"{row['duration']:g} s\n")
    return note + yaml.safe_dump(doc, sort_keys=False)


def plot_tuning(rows: list[dict], front: list[dict], chosen: dict | None, path: str | Path,
                title: str) -> Path:
    """Closure error against cost of every row that ran, the front and the choice (PNG)."""
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
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("cost: wall time per simulated second (ms)")
    ax.set_ylabel("largest closure error (m)")
    ax.set_title(f"{title}\n{len(ok)} ran, {refused} beyond the stability bound, "
                 f"{diverged} diverged", fontsize=9)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)
