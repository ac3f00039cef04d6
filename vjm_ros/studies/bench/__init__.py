"""Speed/accuracy study: ``vjm bench [SCENE ...] [--quick] [--out DIR] [--docs FILE]``.

For every scene the bench runs a grid of settings through :class:`~vjm_ros.sim.simulator.Simulator`
(so any faster kernel selected there is measured as it is) and, when MuJoCo is installed, the same
mechanism in MuJoCo (:mod:`vjm_ros.studies.compare_mujoco`). Each row reports (docs/design.md section 6):

* cost: wall time per simulated second of the physics calls (``Simulator.advance`` or
  ``mj_step``), median of ``--repeats`` runs over the scene's horizon, single-threaded; sampling
  the results is not timed. Rows are compared as ratios within one run;
* closure error: the largest ``|C|`` over the run, m;
* energy drift ``max |(T+V)(t) - (T+V)(0)| / max T`` and the energy-balance residual (J);
* accuracy: the largest distance, over all tick times, between the positions of the run and of a
  reference solved by vjm with ``dop853`` at ``rtol = 1e-12`` and exact closure. "tip" is the chain
  tips (the named points); "position" adds the end of every link (the joints), which is the
  measure used for the Pareto fronts and the tiers (for ``four_bar`` the only tip is the pinned
  rocker end, which says little about the motion).

Horizons are chosen where the mechanism is not chaotic: the five-bar's symmetric motion is
physically unstable and the three-chain amplifies round-off about tenfold per second, so both are
compared over 1 s (see :data:`HORIZONS`). A configuration refused by the stiffness check is a row
``refused (stiffness)``, one that diverged a row ``diverged`` with the time and the error; no row is
dropped.

Outputs in ``--out`` (default ``bench_out/``): ``report.md``, ``results.json``, one Pareto plot
per scene (``<scene>_pareto.png``) and ``scaling.png`` (cost per tick against chain length and
chain count). ``--docs FILE`` also writes the user-facing summary (``docs/accuracy.md``) and
copies the figures next to it under ``figures/``. ``--long-run S --out DIR`` instead runs only
the long four-bar run and writes ``DIR/long_run_<setting>.json``; reports later written to
``DIR`` include every ``long_run*.json`` found there.
"""

from vjm_ros.studies.bench.cli import main

__all__ = ["main"]
