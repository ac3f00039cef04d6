"""docs/accuracy.md from the study's results: findings, tables and recommended settings."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

from vjm_ros.studies.bench.analysis import (
    pareto_front,
)
from vjm_ros.studies.bench.grid import (
    DIVERGED,
    EXACT,
    EXACT_PROJ,
    FULL_SCENES,
    LIVE_HEADROOM,
    LIVE_RATE,
    QUICK_SCENES,
    REFUSED,
    THESIS,
    TIERS,
)
from vjm_ros.studies.bench.report import (
    _e,
    _front_table,
    _long_runs_text,
    _match_table,
    _measures_text,
    _ms,
    _mujoco_text,
    _overall_table,
    _ref_line,
    _scaling_text,
    _share_text,
    _tier_table,
    table,
)
from vjm_ros.studies.bench.runs import (
    RowResult,
)
from vjm_ros.studies.pages import sections


def merge_kept_sections(generated: str, previous: str) -> str:
    """``generated`` followed by the sections of ``previous`` it does not write itself.

    ``docs/accuracy.md`` also holds figures from other studies (the live node, start time,
    logs), written by hand from their own commands; refreshing the bench keeps them.
    """
    own = sections(generated)
    kept = [body.rstrip("\n") + "\n" for head, body in sections(previous).items()
            if head not in own]
    if not kept:
        return generated
    return generated.rstrip("\n") + "\n\n" + "\n".join(kept)


def render_docs(results: dict, rows: dict[str, list[RowResult]]) -> str:
    """``docs/accuracy.md``: findings, figures and recommended settings."""
    meta = results["meta"]
    m = meta["machine"]
    n_rows = sum(len(rs) for rs in rows.values())
    n_ref = sum(1 for rs in rows.values() for r in rs if r.status == REFUSED)
    n_div = sum(1 for rs in rows.values() for r in rs if r.status == DIVERGED)
    lines = [
        "# Accuracy and speed",
        "",
        f"This page is written by `{_docs_command(meta, list(rows))}` ({meta['date']}; "
        f"{m['cpu_count']}-core "
        f"{m['processor']} machine, Python {m['python']}, numpy {m['numpy']}, scipy {m['scipy']}, "
        f"MuJoCo {meta['mujoco']['version'] or 'not installed'}; vjm physics kernel "
        f"`{meta.get('kernel') or 'numpy'}`). Run it again to refresh the "
        "numbers; `bench_out/report.md` then lists every row and `bench_out/results.json` holds "
        "them all.",
        "",
        "## What is measured",
        "",
        f"For each scene, {'a reduced' if meta['quick'] else 'the full'} grid of integrator × tick "
        "rate/substeps × closure method (penalty at several gains, raw and as natural frequency "
        "and damping ratio, including the thesis's Kp = 1e5 N/m, Kv = 100 N·s/m; exact closure "
        "with and without projection) runs through the same `Simulator` as `vjm run` and the ROS "
        "node, from the scene's initial state with its default efforts. Accuracy is the largest "
        "distance between the run and a reference solved by vjm with `dop853` at rtol 1e-12 "
        "with exact closure, at the same tick times, over every chain tip and link end "
        "(*position error*). Speed is the wall time of the physics calls per simulated second, "
        f"single core, median of {meta['repeats']} runs; only ratios within one run are "
        "meaningful, the machine is shared.",
        "",
        *_measures_text(),
        "",
        *_mujoco_text(meta),
        *_share_text(meta),
        f"{n_rows} rows in {meta.get('bench_wall_time', 0) / 60:.0f} min; "
        f"{_plural(n_ref, 'row')} refused by the stiffness check and {_plural(n_div, 'row')} "
        "stopped by the divergence guard (all kept in the report).",
        "",
        "Horizons: " + "; ".join(
            f"`{n}` {results['scenes'][n]['horizon']:g} s" for n in rows) + ". "
        + " ".join(f"`{n}`: {results['scenes'][n]['horizon_note']}." for n in rows
                   if results["scenes"][n]["horizon_note"]),
        "",
        "## Recommended settings",
        "",
    ]
    lines += _recommended_text(results.get("recommended", {}), len(rows))
    lines += ["## Findings", ""]
    lines += _findings(results, rows)
    lines += ["### Settings at 1 kHz, one step per tick", "",
              "What a live node can use, worst case over the benched scenes:", "",
              *live_table(rows), ""]
    for name, rs in rows.items():
        lines += _scene_text(name, rs, results)
    if "scaling" in results:
        sc = _scaling_text(results["scaling"])
        sc = [ln.replace("(scaling.png)", f"(figures/{results['figures'].get('scaling', 'scaling.png')})")
              for ln in sc]
        lines += sc
    lines += _long_runs_text(results.get("long_runs", []))
    lines += _extremes_text()
    return "\n".join(lines) + "\n"


def _recommended_text(rec: dict, n_scenes: int) -> list[str]:
    """The recommended settings: the table, live control at 1 kHz, and each offline tier."""
    lines = _overall_table(rec, n_scenes) + [""]
    live = rec.get("live 1 kHz")
    if live:
        lines += [
            f"**Live control at 1 kHz**: {live['label']} — the most accurate setting with one "
            f"tick per millisecond whose physics takes at most 1/{LIVE_HEADROOM:g} of real time "
            "(CPU time of one core) on every benched scene: worst position error "
            f"{_e(live['worst_position_deviation'])} m, worst closure error "
            f"{_e(live['worst_max_closure_error'])} m, at most {_ms(live['worst_cpu_per_sim_s'])} ms "
            f"of CPU ({_ms(live['worst_wall_per_sim_s'])} ms of wall time on this shared machine) "
            "per simulated second.", ""]
    else:
        lines += ["**Live control at 1 kHz**: no single setting is both fast enough and valid on "
                  "every scene; see the per-scene tiers below.", ""]
    for tier, _tol in TIERS[1:]:
        b = rec.get(tier)
        if b:
            lines += [f"**Offline, position error within {tier}**: {b['label']} (worst "
                      f"{_e(b['worst_position_deviation'])} m, at most "
                      f"{_ms(b['worst_wall_per_sim_s'])} ms per simulated second).", ""]
        else:
            lines += [f"**Offline, position error within {tier}**: no single setting of the grid "
                      "reaches it on every scene; see the per-scene tables below.", ""]
    return lines


def _scene_text(name: str, rs: list[RowResult], results: dict) -> list[str]:
    """One scene's section: horizon, reference, figure, tiers, Pareto front, MuJoCo match."""
    sm = results["scenes"][name]
    fig = results["figures"].get(name)
    lines = [f"## {name}", "", f"Horizon {sm['horizon']:g} s. {_ref_line(sm['reference'])}", ""]
    if fig:
        lines += [f"![{name}: position error against cost](figures/{fig})", ""]
    lines += ["Recommended per tier:", "", *_tier_table(sm["recommended"]), "",
              "Pareto front (vjm):", "",
              *_front_table(pareto_front([r for r in rs if r.engine == "vjm"])), ""]
    if sm["matched_accuracy"]:
        lines += ["vjm against MuJoCo at matched accuracy (cheapest row of each within the "
                  "position error):", "", *_match_table(sm["matched_accuracy"]), ""]
    return lines


def _docs_command(meta: dict, scenes: list[str]) -> str:
    """The command that rewrites this page, without machine-specific paths."""
    parts = ["vjm bench"]
    default = list(QUICK_SCENES if meta.get("quick") else FULL_SCENES)
    if scenes != default:
        parts += scenes
    if meta.get("quick"):
        parts.append("--quick")
    return " ".join(parts + ["--out bench_out", "--docs docs/accuracy.md"])


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def _worst(rs: Sequence[RowResult], attr: str) -> float | None:
    vals = [getattr(r, attr) for r in rs if getattr(r, attr) is not None]
    return max(vals) if vals else None


def live_table(rows: dict[str, list[RowResult]]) -> list[str]:
    """Every vjm setting at 1 kHz with one step per tick, worst case over the scenes."""
    by: dict[tuple[str, str], list[RowResult]] = {}
    for rs in rows.values():
        for r in rs:
            if r.engine == "vjm" and r.step is not None and r.rate == LIVE_RATE and r.substeps == 1:
                by.setdefault((r.integrator, r.closure), []).append(r)
    rows = []
    for (integ, closure), rs in by.items():
        states = Counter(r.status for r in rs)
        ran = [r for r in rs if r.ok]
        rows.append([integ, closure, ", ".join(f"{v} {k}" for k, v in states.items()),
                     _ms(_worst(ran, "wall_per_sim_s")), _ms(_worst(ran, "cpu_per_sim_s")),
                     *(_e(_worst(ran, a)) for a in ("max_closure_error", "position_deviation",
                                                    "energy_drift"))])
    return table(["integrator", "closure", "status on the scenes", "worst ms per sim s",
                  "worst CPU ms per sim s", "worst max closure err m", "worst position err m",
                  "worst energy drift"], rows)


def _thesis_findings(vjm_rows: list[RowResult]) -> list[str]:
    """The thesis gains and exact rk4 at 1 kHz."""
    out = []
    thesis = [r for r in vjm_rows if r.closure == THESIS.label and r.ok and r.step is not None]
    exact = [r for r in vjm_rows if r.closure == EXACT.label and r.ok and r.step is not None]
    if thesis:
        khz = [r.max_closure_error for r in thesis if r.rate == LIVE_RATE]
        slow = [r for r in thesis if r.rate < LIVE_RATE]
        rk4 = [r.position_deviation for r in exact if r.integrator == "rk4" and r.rate == LIVE_RATE
               and r.position_deviation is not None]
        text = ("- **The thesis's penalty gains** (Kp = 1e5 N/m, Kv = 100 N·s/m) leave closure "
                f"errors of {_e(min(khz))}–{_e(max(khz))} m at 1 kHz whatever the fixed-step "
                "integrator and substeps: the spring's compliance sets them." if khz else
                "- **The thesis's penalty gains** (Kp = 1e5 N/m, Kv = 100 N·s/m):")
        if slow:
            worst = max(slow, key=lambda r: r.max_closure_error)
            text += (f" At lower rates they grow, up to {_e(worst.max_closure_error)} m "
                     f"({worst.scene}, {worst.label}, position error "
                     f"{_e(worst.position_deviation)} m).")
        if rk4:
            text += (f" Exact closure with rk4 at 1 kHz reaches position errors of "
                     f"{_e(min(rk4))}–{_e(max(rk4))} m on the same scenes.")
        out.append(text)
    return out


def _exact_findings(vjm_rows: list[RowResult]) -> list[str]:
    """Worst errors of the exact closures at 1 kHz."""
    out = []
    for lab in (EXACT.label, EXACT_PROJ.label):
        for integ in ("semi_implicit_euler", "rk4"):
            rs = [r for r in vjm_rows if r.closure == lab and r.integrator == integ and r.ok
                  and r.step is not None and r.rate == LIVE_RATE and r.substeps == 1]
            if rs:
                out.append(f"- **{lab}, {integ} at 1 kHz**: closure error at most "
                           f"{_e(_worst(rs, 'max_closure_error'))} m, position error at most "
                           f"{_e(_worst(rs, 'position_deviation'))} m, energy drift at most "
                           f"{_e(_worst(rs, 'energy_drift'))}, over the scenes.")
    return out


def _guard_findings(vjm_rows: list[RowResult]) -> list[str]:
    """Rows refused by the stiffness check or stopped by the divergence guard."""
    out = []
    refused = Counter(r.integrator for r in vjm_rows if r.status == REFUSED)
    if refused:
        text = ("- **Refused by the stiffness check** (ω_n·h beyond the method's bound, before "
                "running): " + ", ".join(_plural(v, k + " row") for k, v in sorted(refused.items()))
                + ".")
        ie = [r for r in vjm_rows if r.integrator == "implicit_euler" and r.closure != EXACT.label
              and r.step is not None]
        if ie and all(r.status != REFUSED for r in ie):
            text += " `implicit_euler` accepted every penalty gain of the grid at every step."
        out.append(text)
    div = [r for r in vjm_rows if r.status == DIVERGED]
    if div:
        out.append(f"- **Stopped by the divergence guard**: {_plural(len(div), 'row')} that passed "
                   "the stiffness check, e.g. "
                   + "; ".join(f"{r.scene} {r.label} (t = {r.diverged_at:.3g} s)" for r in div[:4])
                   + "."
                   + (" The stiffness check judges the coupled closure modes at the initial "
                      "pose; these stiffened as the pose moved, and the guard caught them."
                      if all(r.closure.startswith("penalty") for r in div) else ""))
    return out


def _mujoco_findings(results: dict, rows: dict[str, list[RowResult]]) -> list[str]:
    """Cost ratios against MuJoCo at matched accuracy, per scene."""
    out = []
    for name in rows:
        match = [m for m in results["scenes"][name].get("matched_accuracy", [])
                 if m["ratio"] is not None]
        if match:
            ratios = ", ".join(f"{m['ratio']:.3g}x within {m['level']:.0e} m" for m in match)
            missing = [m["level"] for m in results["scenes"][name]["matched_accuracy"]
                       if m["mujoco"] is None]
            out.append(f"- **{name} against MuJoCo**, cost of vjm's cheapest setting over MuJoCo's "
                       f"cheapest at matched position error: {ratios}."
                       + (f" No MuJoCo row of the grid reaches {min(missing):.0e} m: its soft "
                          "equality constraints set a floor." if missing else ""))
            lv = results["scenes"][name].get("live", {})
            if lv.get("vjm") and lv.get("mujoco"):
                out.append(
                    f"  At 1 kHz live, the most accurate rows: vjm {lv['vjm']['label']} "
                    f"({_e(lv['vjm']['position_deviation'])} m, {_ms(lv['vjm']['wall_per_sim_s'])} "
                    f"ms per simulated second) and {lv['mujoco']['label']} "
                    f"({_e(lv['mujoco']['position_deviation'])} m, "
                    f"{_ms(lv['mujoco']['wall_per_sim_s'])} ms).")
    return out


def _scaling_findings(results: dict) -> list[str]:
    """Growth of the cost per tick."""
    out = []
    if "scaling" in results:
        for family, what in (("links", "along one chain"), ("chains", "with the number of chains")):
            g = results["scaling"][family]["growth_exponent"]
            out.append(f"- **Cost per tick {what}** grows roughly as "
                       + ", ".join(f"n^{v:.2f} ({k})" for k, v in g.items() if v is not None)
                       + " for n >= 4 coordinates (see the scaling section).")
    return out


def _findings(results: dict, rows: dict[str, list[RowResult]]) -> list[str]:
    vjm_rows = [r for rs in rows.values() for r in rs if r.engine == "vjm"]
    return (_thesis_findings(vjm_rows) + _exact_findings(vjm_rows) + _guard_findings(vjm_rows)
            + _mujoco_findings(results, rows) + _scaling_findings(results) + [""])


def _extremes_text() -> list[str]:
    return [
        "## Extremes",
        "",
        "`test/test_extremes.py` asserts what happens at the edges; every case either stays within "
        "the bounds stated there or stops early with a clear error (`StiffnessError` before "
        "running, `DivergenceError` naming the closure, the time and the likely cause), never a "
        "silent NaN:",
        "",
        "- penalty Kp from 1e3 to 1e9 N/m with each fixed-step integrator at 1 kHz: the explicit "
        "methods are refused once ω_n·h passes their bound; `implicit_euler` runs all of them, "
        "with a closure error that falls as Kp grows; with the stiffness check off, the guard stops "
        "the run with a `DivergenceError`;",
        "- steps from 0.1 ms to 20 ms: exact closure stays bounded with every method; penalty "
        "closure at the thesis gains is refused for the explicit methods at large steps;",
        "- singular poses: the five-bar's stretched start, a four-bar within 0.01° of its toggle "
        "pose and a three-chain with one leg stretched keep a full-rank closure Jacobian, and exact "
        "closure stays closed to 1e-7 m; a five-bar whose two stretched legs lie on one line "
        "(the Jacobian loses a rank and the pin is locked) asks for unbounded forces under "
        "gravity: exact closure is stopped by the guard within 20 ms, penalty closure sags by "
        "less than 1 cm;",
        "- mass ratios from 1e-3 to 1e3 (the link carrying the pin) and zero link inertia: exact "
        "closure stays closed to 1e-8 m; penalty gains given as ω_n and ζ scale with the effective "
        "mass, so a light link gets a soft spring (closure error within 2 g Σm / Kp, 8 cm at "
        "1e-3); the thesis's raw gains are refused where the light link makes them too stiff for "
        "the step; a link with neither mass nor inertia at a chain's end is rejected when the "
        "scene loads;",
        "- chains of 1 to 32 links and 1 to 16 chains run with exact closure and with "
        "`implicit_euler` penalty closure; `semi_implicit_euler` with ω_n = 100 rad/s is refused "
        "by the stiffness check on sixteen chains (fifteen hinges pull on one point: the stiffest "
        "coupled closure mode has ω_n = 365 rad/s, ζ = 3.65, against 100 rad/s, ζ = 1 per row); "
        "forced with the check off, it blows up within 50 ms and is stopped by the guard; cost "
        "per tick is in the scaling section;",
        "- one hour of simulated time on `four_bar` with the live setting of the thesis's gains "
        "(`implicit_euler` at 1 kHz, slow test, `pytest -m slow`): finite and closed to 1 mm, "
        "and dissipative (see the long runs above).",
        "",
    ]
