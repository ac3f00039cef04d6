"""Analysis of the rows: Pareto fronts, recommended settings, accuracy-matched comparisons."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from operator import attrgetter
from typing import TypeVar

from vjm_ros.studies.bench.grid import (
    LIVE_HEADROOM,
    LIVE_RATE,
    MATCH_LEVELS,
    TIERS,
)
from vjm_ros.studies.bench.runs import (
    RowResult,
)

T = TypeVar("T")


def lowest_front(items: Iterable[T], cost: Callable[[T], float | None],
                 error: Callable[[T], float | None]) -> list[T]:
    """Items no other item beats on both ``cost`` and ``error``, cheapest first.

    Parameters
    ----------
    items : iterable
        Items whose ``cost`` or ``error`` is None are left out.
    cost, error : callable
        The two measures of an item (lower is better).

    Returns
    -------
    list
    """
    front, best = [], math.inf
    for x in sorted((x for x in items if cost(x) is not None and error(x) is not None),
                    key=lambda x: (cost(x), error(x))):
        if error(x) < best:
            front.append(x)
            best = error(x)
    return front


def pareto_front(rows: Sequence[RowResult]) -> list[RowResult]:
    """Rows not beaten in both cost and position error, cheapest first.

    Parameters
    ----------
    rows : sequence of RowResult
        Only rows that ran (``ok``) with a cost and a position error are considered.

    Returns
    -------
    list of RowResult
    """
    return lowest_front([r for r in rows if r.ok], attrgetter("wall_per_sim_s"),
                        attrgetter("position_deviation"))


def _live_ok(r: RowResult) -> bool:
    """Fixed step at 1 kHz, and at least :data:`LIVE_HEADROOM` times faster than real time.

    Speed here is CPU time per simulated second (wall time where none was measured): on a shared
    machine the wall time penalizes every row alike, the CPU time is what a core of its own
    would take.
    """
    cost = r.cpu_per_sim_s if r.cpu_per_sim_s else r.wall_per_sim_s
    return (r.ok and r.step is not None and abs(r.rate - LIVE_RATE) < 1e-9
            and cost is not None and cost > 0 and 1.0 / cost >= LIVE_HEADROOM
            and r.position_deviation is not None)


def recommend(rows: Sequence[RowResult]) -> dict:
    """The recommended vjm row per tier for one scene.

    ``live 1 kHz``: among fixed-step rows at 1 kHz at least :data:`LIVE_HEADROOM` times faster
    than real time (CPU time, see :func:`_live_ok`), the smallest position error (ties: the
    cheapest). Accuracy tiers: the
    cheapest row whose position error is within the tier.

    Returns
    -------
    dict
        Tier name to the row's key, label, cost and errors (None when no row qualifies).
    """
    mine = [r for r in rows if r.engine == "vjm" and r.ok and r.position_deviation is not None
            and r.wall_per_sim_s is not None]
    out = {}
    for tier, tol in TIERS:
        if tol is None:
            cand = sorted((r for r in mine if _live_ok(r)),
                          key=lambda r: (r.position_deviation, r.wall_per_sim_s))
        else:
            cand = sorted((r for r in mine if r.position_deviation <= tol),
                          key=lambda r: (r.wall_per_sim_s, r.position_deviation))
        out[tier] = _brief(cand[0]) if cand else None
    return out


def _brief(r: RowResult) -> dict:
    return {
        "key": r.key, "label": r.label, "wall_per_sim_s": r.wall_per_sim_s,
        "realtime_factor": r.realtime_factor, "cpu_per_sim_s": r.cpu_per_sim_s,
        "position_deviation": r.position_deviation,
        "tip_deviation": r.tip_deviation, "max_closure_error": r.max_closure_error,
        "energy_drift": r.energy_drift,
    }


def recommend_overall(scenes: dict) -> dict:
    """One setting per tier that qualifies on every benched scene.

    Live tier: the setting with the smallest worst-case position error among those that are live
    (1 kHz, CPU time at most 1 / :data:`LIVE_HEADROOM` of real time) on every scene. Accuracy tiers: the setting
    within the tier on every scene with the smallest total cost.

    Parameters
    ----------
    scenes : dict
        Scene name to its list of :class:`RowResult`.

    Returns
    -------
    dict
        Tier to a summary (None when no single setting qualifies everywhere).
    """
    by_key: dict[str, dict[str, RowResult]] = {}
    for name, rows in scenes.items():
        for r in rows:
            if r.engine == "vjm":
                by_key.setdefault(r.key, {})[name] = r
    names = list(scenes)
    out = {}
    for tier, tol in TIERS:
        best, best_score = None, None
        for key, per in by_key.items():
            if len(per) != len(names):
                continue
            rs = list(per.values())
            if tol is None:
                if not all(_live_ok(r) for r in rs):
                    continue
                score = (max(r.position_deviation for r in rs), sum(r.wall_per_sim_s for r in rs))
            else:
                if not all(r.ok and r.position_deviation is not None and r.position_deviation <= tol
                           and r.wall_per_sim_s is not None for r in rs):
                    continue
                score = (sum(r.wall_per_sim_s for r in rs), max(r.position_deviation for r in rs))
            if best_score is None or score < best_score:
                best, best_score = key, score
        if best is None:
            out[tier] = None
            continue
        rs = by_key[best]
        out[tier] = {
            "key": best,
            "label": next(iter(rs.values())).label,
            **{f"worst_{a}": max(getattr(r, a) for r in rs.values())
               for a in ("position_deviation", "max_closure_error", "wall_per_sim_s")},
            "worst_cpu_per_sim_s": max((r.cpu_per_sim_s or r.wall_per_sim_s) for r in rs.values()),
            "per_scene": {n: _brief(r) for n, r in rs.items()},
        }
    return out


def matched_accuracy(rows: Sequence[RowResult]) -> list[dict]:
    """vjm against MuJoCo: the cheapest row of each reaching a position error, per level.

    Returns
    -------
    list of dict
        ``level``, the two rows' labels and costs, and ``ratio`` (vjm cost / MuJoCo cost).
    """
    out = []
    for level in MATCH_LEVELS:
        best = {}
        for engine in ("vjm", "mujoco"):
            cand = [r for r in rows if r.engine == engine and r.ok and r.wall_per_sim_s is not None
                    and r.position_deviation is not None and r.position_deviation <= level]
            best[engine] = min(cand, key=lambda r: r.wall_per_sim_s) if cand else None
        v, m = best["vjm"], best["mujoco"]
        out.append({
            "level": level,
            "vjm": _brief(v) if v else None,
            "mujoco": _brief(m) if m else None,
            "ratio": (v.wall_per_sim_s / m.wall_per_sim_s) if (v and m and m.wall_per_sim_s) else None,
        })
    return out


def live_comparison(rows: Sequence[RowResult]) -> dict:
    """Best live (1 kHz) row of vjm and of MuJoCo, by position error."""
    out = {}
    for engine in ("vjm", "mujoco"):
        cand = [r for r in rows if r.engine == engine and _live_ok(r)]
        cand.sort(key=lambda r: (r.position_deviation, r.wall_per_sim_s))
        out[engine] = _brief(cand[0]) if cand else None
    return out
