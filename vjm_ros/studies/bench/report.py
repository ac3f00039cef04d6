"""Outputs of the study: results files, Pareto and scaling figures, the Markdown report."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

from vjm_ros.sim.samples import RUN_BLOCK_TICKS
from vjm_ros.studies.bench.analysis import (
    pareto_front,
)
from vjm_ros.studies.bench.grid import (
    DIVERGED,
    FAILED,
    LIVE_HEADROOM,
    MJ_INTEGRATORS,
    OK,
    REFUSED,
    TIERS,
)
from vjm_ros.studies.bench.runs import (
    RowResult,
)
from vjm_ros.studies.bench.scaling import (
    ONE_LINK_TICKS,
    _scaling_keys,
)

_COLORS = {
    "explicit_euler": "#d62728", "semi_implicit_euler": "#ff7f0e", "rk4": "#2ca02c",
    "implicit_euler": "#1f77b4", "dop853": "#9467bd", "rk45": "#8c564b", "rk23": "#e377c2",
    "radau": "#17becf", "bdf": "#bcbd22", "lsoda": "#7f7f7f",
    "Euler": "#555555", "implicitfast": "#999999", "RK4": "#000000",
}


def _marker(r: RowResult) -> str:
    if r.engine == "mujoco":
        return "^"
    if r.closure.startswith("exact + projection"):
        return "D"
    if r.closure.startswith("exact"):
        return "s"
    return "o"


def plot_pareto(name: str, rows: Sequence[RowResult], summary: dict, path: Path) -> None:
    """Position error against cost, every row that ran, with the Pareto fronts.

    Parameters
    ----------
    name : str
        Scene name.
    rows : sequence of RowResult
    summary : dict
        The scene's summary (horizon, counts).
    path : Path
        PNG file written.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    fig = Figure(figsize=(9.5, 6.0), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    pts = [r for r in rows if r.ok and r.wall_per_sim_s and r.position_deviation is not None]
    floor = 1e-14
    for r in pts:
        ax.scatter(r.wall_per_sim_s, max(r.position_deviation, floor), marker=_marker(r),
                   s=34 if r.engine == "vjm" else 40, color=_COLORS.get(r.integrator, "#333333"),
                   alpha=0.8, edgecolors="none" if _marker(r) != "^" else "black", linewidths=0.5)
    for engine, style, label in (("vjm", "-", "vjm Pareto front"),
                                 ("mujoco", "--", "MuJoCo Pareto front")):
        front = pareto_front([r for r in rows if r.engine == engine])
        if front:
            xs = [r.wall_per_sim_s for r in front]
            ys = [max(r.position_deviation, floor) for r in front]
            ax.step(xs, ys, where="post", linestyle=style, color="black", linewidth=1.0,
                    label=label)
    ax.axvline(1.0, color="gray", linestyle=":", linewidth=1)
    ax.axvline(1.0 / LIVE_HEADROOM, color="gray", linestyle="-.", linewidth=0.8)
    ax.text(1.0, 0.02, " realtime", transform=ax.get_xaxis_transform(), fontsize=7,
            color="gray")
    ax.text(1.0 / LIVE_HEADROOM, 0.06, f" live budget (RTF {LIVE_HEADROOM:g}) ",
            transform=ax.get_xaxis_transform(), fontsize=7, color="gray", ha="right")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("cost: wall seconds per simulated second (median, single core)")
    ax.set_ylabel("position error vs exact reference (m, max over ticks)")
    counts = summary.get("counts", {})
    ax.set_title(
        f"{name}: horizon {summary['horizon']:g} s; {counts.get(OK, 0)} rows ran, "
        f"{counts.get(REFUSED, 0)} refused (stiffness), {counts.get(DIVERGED, 0)} diverged",
        fontsize=10,
    )
    ax.grid(True, which="major", alpha=0.3)
    handles = [Line2D([], [], linestyle="", marker="^" if k in MJ_INTEGRATORS else "o", color=c,
                      label=f"MuJoCo {k}" if k in MJ_INTEGRATORS else k)
               for k, c in _COLORS.items() if any(r.integrator == k for r in pts)]
    handles += [Line2D([], [], linestyle="", marker=m, color="gray", label=label) for m, label in
                (("o", "penalty closure"), ("s", "exact closure"), ("D", "exact + projection"))]
    handles += ax.get_legend_handles_labels()[0]
    ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    fig.savefig(path)


def plot_scaling(scaling: dict, path: Path) -> None:
    """Seconds per 1 kHz tick against the number of coordinates, per family and method."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4.2), dpi=110)
    FigureCanvasAgg(fig)
    for k, (family, title) in enumerate((("links", "one chain of N links (1 slider row)"),
                                         ("chains", "N two-link chains meeting at one pin"))):
        ax = fig.add_subplot(1, 2, k + 1)
        table = scaling[family]["table"]
        for key in _scaling_keys(scaling):
            integ = key.split()[0]
            xs = [r["n"] for r in table if r.get(key)]
            ys = [r[key] * 1e6 for r in table if r.get(key)]
            g = scaling[family]["growth_exponent"].get(key)
            lab = f"{key} (~n^{g:.2f})" if g is not None else key
            ax.plot(xs, ys, marker="o", label=lab, color=_COLORS.get(integ, "black"),
                    markersize=4)
        ax.axhline(1000.0, color="gray", linestyle=":", linewidth=1)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("coordinates n")
        ax.set_ylabel("microseconds per 1 kHz tick")
        ax.set_title(title, fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6, loc="best", framealpha=0.7)
    fig.tight_layout()
    fig.savefig(path)


def _e(x, digits: int = 2) -> str:
    if x is None:
        return "–"
    if isinstance(x, str):
        return x
    if x == 0:
        return "0"
    return f"{x:.{digits}e}" if (abs(x) < 1e-2 or abs(x) >= 1e4) else f"{x:.{digits + 1}g}"


def _ms(x) -> str:
    return "–" if x is None else f"{1e3 * x:.3g}"


def _status(r: RowResult) -> str:
    if r.status == DIVERGED:
        return f"diverged at t = {r.diverged_at:.3g} s" if r.diverged_at is not None else DIVERGED
    return r.status


def table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """The lines of a Markdown table: the header, its rule and one line per row of cells."""
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header),
            *("| " + " | ".join(row) + " |" for row in rows)]


def _row_table(rows: Sequence[RowResult]) -> list[str]:
    return table(
        ["engine", "integrator", "rate Hz", "substeps", "h ms", "closure", "status",
         "ms per sim s", "RTF", "max closure err m", "energy drift", "ledger residual J",
         "tip err m", "position err m"],
        ([r.engine, r.integrator if r.step is not None
          else f"{r.integrator} rtol {r.settings.get('rtol'):.0e}", f"{r.rate:g}", str(r.substeps),
          "adaptive" if r.step is None else f"{1e3 * r.step:.3g}", r.closure, _status(r),
          _ms(r.wall_per_sim_s), _e(r.realtime_factor), _e(r.max_closure_error),
          _e(r.energy_drift), _e(r.energy_balance_residual), _e(r.tip_deviation),
          _e(r.position_deviation)] for r in rows),
    )


def _front_table(front: Sequence[RowResult]) -> list[str]:
    return table(
        ["setting", "ms per sim s", "RTF", "position err m", "max closure err m", "energy drift"],
        ([r.label, _ms(r.wall_per_sim_s), _e(r.realtime_factor), _e(r.position_deviation),
          _e(r.max_closure_error), _e(r.energy_drift)] for r in front),
    )


def _tier_rows(rec: dict, header: list[str], missing: str, cells) -> list[str]:
    """A Markdown table with one row per accuracy tier: ``cells(b)`` or ``missing``."""
    return table(header, ([tier, *([missing] + [""] * (len(header) - 2) if rec.get(tier) is None
                                   else cells(rec[tier]))] for tier, _ in TIERS))


def _tier_table(rec: dict) -> list[str]:
    return _tier_rows(
        rec,
        ["tier", "setting", "ms per sim s", "CPU ms per sim s", "position err m",
         "max closure err m"],
        "no row qualifies",
        lambda b: [b["label"], _ms(b["wall_per_sim_s"]), _ms(b.get("cpu_per_sim_s")),
                   _e(b["position_deviation"]), _e(b["max_closure_error"])],
    )


def _overall_table(rec: dict, n_scenes: int) -> list[str]:
    return _tier_rows(
        rec,
        ["tier", f"setting (qualifies on all {n_scenes} scenes)", "worst ms per sim s",
         "worst position err m", "worst max closure err m"],
        "no single setting qualifies on every scene",
        lambda b: [b["label"], _ms(b["worst_wall_per_sim_s"]), _e(b["worst_position_deviation"]),
                   _e(b["worst_max_closure_error"])],
    )


def _match_table(match: list[dict]) -> list[str]:
    def best(b: dict | None) -> list[str]:
        return [b["label"], _ms(b["wall_per_sim_s"])] if b else ["none", "–"]

    return table(["position err within", "vjm: cheapest setting", "ms per sim s",
                  "MuJoCo: cheapest setting", "ms per sim s", "vjm / MuJoCo cost"],
                 ([f"{m['level']:.0e} m", *best(m["vjm"]), *best(m["mujoco"]), _e(m["ratio"])]
                  for m in match))


def _ref_line(info: dict) -> str:
    if "error" in info:
        return f"Reference failed: {info['error']}"
    chk = info.get("check", {})
    s = (f"Reference: vjm `{info['integrator']}` at rtol {info['rtol']:.0e}, atol {info['atol']:.0e}, "
         f"exact closure, ticks at {info['rate']:g} Hz ({info['wall_time']:.1f} s wall).")
    if chk:
        s += (f" A solve at rtol {chk['rtol']:.0e} differs from it by at most "
              f"{chk['max_position_difference']:.1e} m, so position errors below about that "
              "size are not resolved by the check but the reference is tighter still.")
    return s


def render_report(results: dict, rows: dict[str, list[RowResult]]) -> str:
    """The full markdown report (every row of every scene)."""
    meta = results["meta"]
    m = meta["machine"]
    lines = [
        "# vjm bench report",
        "",
        f"`{meta['command']}` on {meta['date']}: {m['platform']}, {m['cpu_count']} cores "
        f"({m['processor']}), Python {m['python']}, numpy {m['numpy']}, scipy {m['scipy']}, "
        f"MuJoCo {meta['mujoco']['version'] or 'not installed'}; vjm physics kernel "
        f"`{meta.get('kernel') or 'numpy'}`. Single-threaded "
        f"({meta['threads']['blas']}); costs are medians of {meta['repeats']} runs, wall time of the "
        f"physics calls only; total bench time {meta.get('bench_wall_time', 0) / 60:.1f} min.",
        "",
        *_share_text(meta),
    ]
    lines += _mujoco_text(meta)
    lines += _measures_text() + [""]
    if results.get("recommended"):
        lines += ["## Recommended settings", "",
                  *_overall_table(results["recommended"], len(rows)), ""]
    for name, rs in rows.items():
        sm = results["scenes"][name]
        lines += [f"## {name}", "",
                  f"Horizon {sm['horizon']:g} s"
                  + (f" ({sm['horizon_note']})." if sm["horizon_note"] else "."),
                  _ref_line(sm["reference"]), "",
                  f"![{name} Pareto plot]({results['figures'].get(name, '')})", "",
                  "Recommended per tier:", "", *_tier_table(sm["recommended"]), "",
                  "Pareto front (vjm):", "",
                  *_front_table(pareto_front([r for r in rs if r.engine == "vjm"])), ""]
        if sm["matched_accuracy"]:
            lines += ["Pareto front (MuJoCo):", "",
                      *_front_table(pareto_front([r for r in rs if r.engine == "mujoco"])), "",
                      "vjm against MuJoCo at matched accuracy:", "",
                      *_match_table(sm["matched_accuracy"]), ""]
        lines += ["All rows:", "", *_row_table(rs), ""]
        bad = [r for r in rs if r.status in (DIVERGED, FAILED)]
        if bad:
            lines += ["Divergence and error messages:", ""]
            lines += [f"- {r.label}: {r.message}" for r in bad]
            lines.append("")
    if "scaling" in results:
        lines += _scaling_text(results["scaling"]) + [""]
    lines += _long_runs_text(results.get("long_runs", []))
    return "\n".join(lines)


def _mujoco_text(meta: dict) -> list[str]:
    mj = meta["mujoco"]
    if mj.get("skipped"):
        return [f"MuJoCo rows skipped: {mj['skipped']}.", ""]
    out = [f"MuJoCo {mj['version']} rows use the model of `vjm_ros.studies.compare_mujoco`, the "
           "scene's MJCF export (same geometry, masses, inertias plus 1e-12 kg m², gravity; "
           "hinge closures as equality `connect` constraints, slider closures as a `connect` to "
           "a carriage of negligible mass on a slide) and are timed the same way (`mj_step` "
           "calls only).", ""]
    if mj.get("note"):
        out += [f"**MuJoCo version warning**: {mj['note']}.", ""]
    return out


def _share_text(meta: dict) -> list[str]:
    share = meta.get("cpu_share")
    if share is None:
        return []
    s = (f"The timed physics calls got {100 * share:.0f} % of a core on average (CPU time over wall "
         "time)")
    if share < 0.9:
        s += ("; the machine was shared, so absolute costs are inflated by up to "
              f"{1 / share:.1f}x, while ratios measured in this run are much less affected.")
    else:
        s += "."
    return [s, ""]


def _measures_text() -> list[str]:
    return [
        "Measures: *ms per sim s* is wall milliseconds per simulated second (RTF its inverse); "
        "*max closure err* the largest closure residual (m); *energy drift* "
        "max|(T+V)(t) − (T+V)(0)| / max T; *ledger residual* the largest deviation from the "
        "energy balance (penalty: E = T + V + ½Kp|C|², dE/dt = τ·q̇ − Kv|Ċ|²; MuJoCo rows: "
        "T + V against the actuator work, so the soft constraint's own work counts as residual); "
        "*tip err* and *position err* the largest distance from the exact reference of the chain "
        "tips, and of the tips plus every link end, over all ticks. Rows refused by the stiffness "
        "check (ω_n·h beyond the integrator's bound) or stopped by the divergence guard are kept "
        "and marked.",
    ]


def _scaling_text(scaling: dict) -> list[str]:
    lines = ["## Cost per tick against size", "",
             "Microseconds per 1 kHz tick (one step per tick, each tick sampled, in blocks of "
             f"at most {RUN_BLOCK_TICKS} ticks, one compiled call each), median of repeats"
             + (f", each repeat timing enough ticks to take {1e3 * scaling['seconds_per_repeat']:g} ms"
                " at least" if scaling.get("seconds_per_repeat") else "") + ". `links`: one "
             "chain of N links whose tip runs on a line; `chains`: N two-link chains whose tips "
             "meet at one pin (2(N−1) closure rows).", "", "![scaling](scaling.png)", ""]
    for family in ("links", "chains"):
        rows = scaling[family]["table"]
        keys = _scaling_keys(scaling)
        lines += table([family, "n", "closure rows", *keys],
                       ([str(r["size"]), str(r["n"]), str(r["rows"]),
                         *("–" if r.get(k) is None else f"{1e6 * r[k]:.3g}" for k in keys)]
                        for r in rows))
        g = scaling[family]["growth_exponent"]
        lines += ["", "Growth exponent (cost ∝ n^p, sizes ≥ 4): "
                  + ", ".join(f"{k}: {'–' if v is None else f'{v:.2f}'}" for k, v in g.items()), ""]
        lines += _bare_step_lines(rows, keys)
    return lines


def _bare_step_lines(table: list[dict], keys: list[str]) -> list[str]:
    """The one-link row against its bare steps (``bare``: ``scaling.bare_step_cost``)."""
    row = next((r for r in table if r.get("bare")), None)
    if row is None:
        return []
    parts = []
    for k in keys:
        tick, bare = row.get("observed", {}).get(k), row["bare"].get(k)
        if tick and bare:
            parts.append(f"{k}: {1e6 * tick:.2f} µs per tick against {1e6 * bare:.2f} µs per "
                         f"bare step ({tick / bare:.2f}x)")
    if not parts:
        return []
    return [f"One link, {ONE_LINK_TICKS} ticks observed in blocks of {RUN_BLOCK_TICKS} against the "
            "same steps alone in one compiled call (nothing observed or stored; the arithmetic a "
            "tick cannot go below): "
            + "; ".join(parts) + ".", ""]


def _long_run_line(lr: dict) -> str:
    s = lr.get("settings", {})
    gains = (f"Kp {s.get('kp')}, Kv {s.get('kv')}" if s.get("kp") is not None
             else "scene gains" if s.get("closure") == "penalty" else
             ("projection" if s.get("projection") else "no projection"))
    e0, e1 = lr["energy_initial"], lr["energy_final"]
    change = f"{100 * (e1 - e0) / e0:+.2g} %" if e0 else "n/a"
    source = " (the `pytest -m slow` test)" if lr.get("source") == "long_run_slow_test.json" else ""
    return (
        f"`{lr['scene']}` for {lr['sim_time']:.0f} simulated seconds with {s.get('integrator')} at "
        f"{s.get('rate', 0):g} Hz x{s.get('substeps')}, {s.get('closure')} closure ({gains})"
        f"{source}, {lr['wall_time'] / 60:.1f} min wall: max closure error "
        f"{_e(lr['max_closure_error'])} m (final {_e(lr['final_closure_error'])} m); energy drift "
        f"{_e(lr['energy_drift'])}, T+V from {e0:.6g} J to {e1:.6g} J ({change}; largest "
        f"|Δ(T+V)| {_e(lr['max_energy_change'])} J"
        + (f", largest rise {_e(lr['max_energy_gain'])} J" if "max_energy_gain" in lr else "")
        + f"); finite: {lr['finite']}" + (f", stopped: {lr['error']}" if lr.get("error") else "")
        + "."
    )


def _long_runs_text(runs: list[dict]) -> list[str]:
    if not runs:
        return []
    lines = ["## Long runs", "", "Energy and closure over long simulated times (samples every "
             f"{runs[0].get('sample_every_ticks', 10)} ticks):", ""]
    lines += [f"- {_long_run_line(lr)}" for lr in runs]
    return lines + [""]
