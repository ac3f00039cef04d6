"""Stick-slip and impacts: which integrator, step and closure method hold them, at what cost.

``vjm bench --plant`` runs the friction and hard-stop cases (:data:`CASES`) over the
fixed-step integrators, steps and closure methods of :data:`GRID` against a fine reference of
each case (rk4 with exact closure at :data:`REFERENCE_SUBSTEPS` substeps of a 1 kHz tick: the
adaptive solvers do not take sticking friction or stops, whose efforts act once per step). Each
row reports the largest error of the joint coordinates against the reference on the common
1 kHz ticks, the energy the ledger misses at the end (the friction's and the impacts' work
counted), and the wall time per simulated second (best of ``repeats``). ``--docs FILE`` writes
the table as a section of that page (``docs/accuracy.md``).
"""

from __future__ import annotations

import datetime
import platform
import time

import numpy as np

from vjm_ros.core.errors import ConfigurationError, DivergenceError
from vjm_ros.scene.loader import builtin_scene_text, parse_scene
from vjm_ros.sim.samples import SampleBlock
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.simulator import Simulator

HEADING = "## Friction and hard stops"
"""Heading of the ``docs/accuracy.md`` section :func:`render` writes."""

ROD_ON_STOP = """
name: rod_on_stop
description: A rod falling from horizontal onto a hard stop 23 degrees before hanging.
chains:
  - name: arm
    links:
      - {name: rod, length: 1.0, mass: 1.0, inertia: 0.0833333333333333, com: [0.5, 0.0],
         joint: {name: pivot, type: revolute, angle: 0.0, range: [-1.1707963267948966, 3.0],
                 restitution: 0.5, friction: 0.1}}
"""


def _five_bar_friction() -> str:
    text = builtin_scene_text("five_bar")
    for angle, mu in (("45.0", 0.3), ("135.0", 0.3)):
        text = text.replace(f"type: revolute, angle: {angle}}}",
                            f"type: revolute, angle: {angle}, friction: {mu}}}")
    return text


CASES = {
    "five_bar, Coulomb friction 0.3 N m in every joint (stick-slip)": (_five_bar_friction, 2.0),
    "rod on a stop, e = 0.5, friction 0.1 N m (impacts, then rest)": (lambda: ROD_ON_STOP, 2.0),
}
"""Case label -> (scene text, simulated seconds)."""

GRID = {
    "integrators": ("explicit_euler", "semi_implicit_euler", "rk4", "implicit_euler"),
    "substeps": (1, 4),
    "closures": ("exact", "penalty"),
}
"""Rows per case: integrators x substeps of a 1 kHz tick x closure methods (penalty with the
scene's gains; open chains have no closure, so one row)."""

REFERENCE_SUBSTEPS = 64
"""The reference's substeps of a 1 kHz tick (rk4, exact closure)."""


def run(text: str, seconds: float, integrator: str, substeps: int, closure: str
        ) -> tuple[np.ndarray, float, float]:
    """Joint coordinates at every 1 kHz tick (shape (ticks + 1, n)), the ledger's miss at the
    end (J) and the wall time (s) of one run, its ticks in compiled blocks as ``vjm run``'s."""
    scene = parse_scene(text)
    settings = SimulationSettings(integrator=integrator, rate=1000.0, substeps=substeps,
                                  closure=closure)
    sim = Simulator(scene.model, settings, scene.gains if closure == "penalty" else {})
    sim.blocks_compiled()
    ticks = int(round(seconds * 1000.0))
    first = sim.sample(geometry=False)
    block = SampleBlock(scene.model, ticks)
    t0 = time.perf_counter()
    sim.advance_block(block, ticks)
    wall = time.perf_counter() - t0
    q = np.vstack((first.q, block.q[:ticks]))
    rate = np.concatenate(([first.power_in - first.dissipation],
                           block.power[:ticks] - block.dissipation[:ticks]))
    work = float(np.sum(0.5 * (rate[1:] + rate[:-1])) * 1e-3 - np.sum(block.loss[:ticks]))
    return q, float(block.energy[ticks - 1, 3] - first.energy[3] - work), wall


def measure(repeats: int = 2) -> list[dict]:
    """Every row of every case, with its error against the case's reference."""
    rows = []
    for label, (text_of, seconds) in CASES.items():
        text = text_of()
        closed = bool(parse_scene(text).model.closures)
        ref, _, _ = run(text, seconds, "rk4", REFERENCE_SUBSTEPS, "exact")
        for closure in GRID["closures"] if closed else ("exact",):
            for integrator in GRID["integrators"]:
                for substeps in GRID["substeps"]:
                    row = {"case": label, "integrator": integrator, "substeps": substeps,
                           "closure": closure if closed else "-"}
                    try:
                        walls = []
                        for _ in range(repeats):
                            q, miss, wall = run(text, seconds, integrator, substeps, closure)
                            walls.append(wall)
                        row.update(error=float(np.max(np.abs(q - ref))), ledger=abs(miss),
                                   us_per_sim_s=1e6 * min(walls) / seconds, status="ok")
                    except DivergenceError as exc:
                        row.update(error=float("inf"), ledger=float("inf"),
                                   us_per_sim_s=float("nan"), status=f"diverged at {exc.t:.3g} s")
                    except ConfigurationError:  # the stiffness check: the gains need a smaller h
                        row.update(error=float("inf"), ledger=float("inf"),
                                   us_per_sim_s=float("nan"), status="refused (stiffness)")
                    rows.append(row)
    return rows


def render(rows: list[dict]) -> str:
    """The ``docs/accuracy.md`` section of :func:`measure`'s rows."""
    when = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()
    lines = [
        HEADING, "",
        f"Written by `vjm bench --plant --docs docs/accuracy.md` ({when}; {platform.machine()}, "
        f"Python {platform.python_version()}). Each case against its reference: rk4, exact "
        f"closure, {REFERENCE_SUBSTEPS} substeps of a 1 kHz tick. Error: the largest joint "
        "coordinate difference on the 1 kHz ticks (rad); ledger: the energy the balance "
        "misses at the end (J; the friction's and impacts' work is dissipation); cost: wall "
        "time per simulated second (best of the repeats, one process; compare within the table).",
        "",
    ]
    for case in dict.fromkeys(r["case"] for r in rows):
        lines += [f"**{case}**", "",
                  "| integrator | substeps | closure | error (rad) | ledger (J) | ms per sim s |",
                  "|---|---|---|---|---|---|"]
        for r in (r for r in rows if r["case"] == case):
            if r["status"] != "ok":
                lines.append(f"| {r['integrator']} | {r['substeps']} | {r['closure']} | "
                             f"{r['status']} | | |")
                continue
            lines.append(f"| {r['integrator']} | {r['substeps']} | {r['closure']} | "
                         f"{r['error']:.2e} | {r['ledger']:.2e} | {r['us_per_sim_s'] / 1e3:.3g} |")
        lines.append("")
    lines.append("Error ratio from 1 to 4 substeps (4 for a first-order method, 256 for "
                 "fourth order):")
    lines.append("")
    for case in dict.fromkeys(r["case"] for r in rows):
        parts = []
        for r1 in (r for r in rows if r["case"] == case and r["substeps"] == 1):
            r4 = next((r for r in rows if r["case"] == case and r["substeps"] == 4
                       and r["integrator"] == r1["integrator"]
                       and r["closure"] == r1["closure"]), None)
            if r4 and r1["status"] == r4["status"] == "ok" and r4["error"] > 0:
                where = f", {r1['closure']}" if r1["closure"] != "-" else ""
                parts.append(f"{r1['integrator']}{where} {r1['error'] / r4['error']:.2g}")
        lines.append(f"- {case}: " + "; ".join(parts))
    lines += [
        "",
        "Friction and stops act once per step (`docs/design.md` section 4), so no method keeps "
        "its order through a stick-slip transition or an impact: the ratios above stay near 4 "
        "or below. Between the events a higher-order method still follows the smooth motion "
        "better, which is why rk4 leads on the five-bar (most of its time is sliding) and not "
        "on the rod (most of its time is impacts and rest). With penalty closure the error "
        "against the exact-closure reference includes the closure's give (its ratio stays "
        "near 1 once the step's error is below it).",
    ]
    return "\n".join(lines) + "\n"
