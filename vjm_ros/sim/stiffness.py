"""Penalty gains and the stiffness check: can the chosen integrator and step carry them?

Linearized near the closure manifold, the penalty closure error obeys
``Cddot = -G (Kp C + Kv Cdot)`` with the mobility ``G = A M^-1 A^T``
(:func:`~vjm_ros.core.constraints.penalty_modes`): rows that share links ring together, and a
coupled mode can be stiffer than any row alone. Each mode is a damped oscillator
``(omega_n, zeta)``; a fixed step ``h`` carries it while ``omega_n h`` stays within
``integrator.stability_bound(zeta)``, computed from the method's one-step map on linear systems
(:meth:`~vjm_ros.core.integrators.base.FixedStepIntegrator.step_matrix`, checked against the
compiled kernel's steps; for a Runge-Kutta method the same as ``|R(h mu)| <= 1`` on both roots
``mu`` of the mode). Adaptive methods and
``implicit_euler`` have no bound (``inf``). The pose changes ``G`` as the mechanism moves; the
check before a run judges the initial pose only (no cost per tick), and the divergence guard
judges the last good poses when a run fails (docs/design.md section 2).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from vjm_ros.core.constraints import (
    ExactClosure,
    PenaltyClosure,
    closure_mobility,
    penalty_modes,
)
from vjm_ros.core.errors import StiffnessError
from vjm_ros.core.integrators import Integrator
from vjm_ros.core.mechanism import Mechanism
from vjm_ros.core.model import Model
from vjm_ros.sim.settings import SimulationSettings

THESIS_KP = 1e5
"""The thesis's closure stiffness (Tables 4.1-4.5, printed as "Ns/m"), N/m."""
THESIS_KV = 100.0
"""The thesis's closure damping, N s/m."""

STIFFNESS_MARGIN = 1e-6
"""Relative margin below a stability bound: a closure mode whose ``omega_n h`` comes within it of
the bound is refused. On the bound the linearized closure error neither grows nor decays, and
the changing pose tips it over (double_slider with semi-implicit Euler at ``Kp h (h + 2 Kv/Kp)
= 4 m_eff`` exactly diverges within 0.4 s)."""


def mobility_at(model: Model, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """The closure mobility ``G = A M^-1 A^T`` at a state.

    Parameters
    ----------
    model : Model
    q, qd : ndarray, shape (n,)
        Joint coordinates (rad or m) and rates.

    Returns
    -------
    ndarray, shape (r, r)
        1/kg for point rows, 1/(kg m^2) for angle rows.
    """
    dyn, closure = Mechanism(model, ExactClosure(), warm_up=False).terms(q, qd)
    return closure_mobility(dyn.mass_matrix, closure.jacobian)


def effective_masses(mobility: np.ndarray) -> np.ndarray:
    """Per-row effective mass ``1 / G_ii`` (0 for a row no coordinate moves).

    Parameters
    ----------
    mobility : ndarray, shape (r, r)

    Returns
    -------
    ndarray, shape (r,)
        kg, or kg m^2 for angle rows.
    """
    diag = np.diag(mobility)
    with np.errstate(divide="ignore"):
        return np.where(diag > 0, 1.0 / np.maximum(diag, 1e-300), 0.0)


def closure_method(model: Model, settings: SimulationSettings, scene_gains: dict,
                   initial_mobility: Callable[[], np.ndarray]) -> (
    PenaltyClosure | ExactClosure
):
    """The closure method and gains of a run: settings first, then the scene, then the thesis.

    Parameters
    ----------
    model : Model
    settings : SimulationSettings
    scene_gains : dict
        Gains from the scene file.
    initial_mobility : callable
        ``() -> G`` at the initial pose, called only for gains given as ``omega_n``/``zeta``
        (``Kp = m_eff omega_n^2``, ``Kv = 2 zeta m_eff omega_n``).

    Returns
    -------
    PenaltyClosure or ExactClosure
    """
    s, g = settings, scene_gains
    if s.closure == "exact":
        alpha = s.alpha if s.alpha is not None else g.get("alpha", 20.0)
        beta = s.beta if s.beta is not None else g.get("beta", 20.0)
        return ExactClosure(alpha=alpha, beta=beta, projection=s.projection)
    r = model.n_rows
    kp_raw, kv_raw, wn, zeta = s.kp, s.kv, s.omega_n, s.zeta
    if kp_raw is None and wn is None:
        kp_raw, kv_raw = g.get("kp"), g.get("kv")
        wn, zeta = g.get("omega_n"), g.get("zeta")
    if kp_raw is None and wn is None:
        kp_raw, kv_raw = THESIS_KP, THESIS_KV
    if kp_raw is not None:
        kp = np.full(r, float(kp_raw))
        kv = np.full(r, float(kv_raw if kv_raw is not None else 0.0))
    else:
        meff = effective_masses(initial_mobility())
        z = float(zeta if zeta is not None else 1.0)
        kp = meff * float(wn) ** 2
        kv = 2.0 * z * meff * float(wn)
    return PenaltyClosure(kp=kp, kv=kv)


def closure_modes(
    model: Model, method: PenaltyClosure, integrator: Integrator, h: float, mobility: np.ndarray
) -> tuple[list[dict], float | None]:
    """The coupled closure modes at one pose against the integrator's stability bound.

    Parameters
    ----------
    model : Model
    method : PenaltyClosure
    integrator : Integrator
    h : float
        Step, s.
    mobility : ndarray, shape (r, r)
        ``G`` at the pose.

    Returns
    -------
    report : list of dict
        One entry per mode, stiffest first: ``closure`` and ``row`` (the row carrying the
        largest share of the mode), ``rows``, ``share`` and ``closures`` (the rows that
        together carry 90 % of it, largest share first, and their closures), ``m_eff``
        (kg or kg m^2) and ``row_omega_n`` (rad/s) of that row alone, ``omega_n`` (rad/s),
        ``zeta``, ``omega_h`` (``omega_n h``) and ``bound`` of the mode.
    radius : float or None
        Spectral radius of one step on the coupled closure dynamics, computed only when the
        gains are not proportional (``Kv != c Kp``) and the method has a finite bound.
    """
    kp, kv = method.kp, method.kv
    modes = penalty_modes(mobility, kp, kv)
    meff = effective_masses(mobility)
    names = [c.name for c in model.closures for _ in range(c.rows)]
    fixed = integrator.fixed_step
    if fixed and modes.omega_n.size:
        bounds = integrator.stability_bounds(modes.zeta)
    else:
        bounds = np.full(modes.omega_n.size, np.inf)
    radius = None
    if (
        fixed
        and not modes.proportional
        and modes.stiffness.size
        and np.isfinite(integrator.stability_bound(0.0))
    ):
        # Modes of non-proportional gains are not independent oscillators: judge the
        # method's step on the coupled system as well.
        step = integrator.step_matrix(modes.stiffness, modes.damping, h)
        radius = float(np.max(np.abs(np.linalg.eigvals(step))))
    report = []
    for j, wn in enumerate(modes.omega_n):
        share = modes.share[j]
        order = [int(i) for i in np.argsort(-share, kind="stable")]
        cover = int(np.searchsorted(np.cumsum(share[order]), 0.9 * float(share.sum()))) + 1
        rows = order[: min(cover, len(order))]
        top = rows[0]
        m = float(meff[top])
        report.append(
            {
                "closure": names[top],
                "row": top,
                "closures": list(dict.fromkeys(names[i] for i in rows)),
                "rows": rows,
                "share": [float(share[i]) for i in rows],
                "m_eff": m,
                "row_omega_n": float(np.sqrt(kp[top] / m)) if m > 0 else float("nan"),
                "omega_n": float(wn),
                "zeta": float(modes.zeta[j]),
                "omega_h": float(wn) * h,
                "bound": float(bounds[j]),
            }
        )
    return report, radius


def check_stiffness(
    report: list[dict],
    radius: float | None,
    model: Model,
    integrator_name: str,
    h: float,
    substeps: int,
) -> None:
    """Raise :class:`StiffnessError` when a closure mode is beyond the method's bound.

    Parameters
    ----------
    report, radius
        From :func:`closure_modes` at the initial pose.
    model : Model
    integrator_name : str
    h : float
        Step, s.
    substeps : int
        Steps per control tick (the message says how many would be needed).
    """
    over = [m for m in report if m["omega_h"] > (1.0 - STIFFNESS_MARGIN) * m["bound"]]
    # A full 2r x 2r step map (non-proportional gains only): its eigenvalues near a double
    # root carry ~sqrt(eps) error, so growth counts from 1e-6 per step.
    if not over and (radius is None or radius <= 1.0 + 1e-6):
        return
    dt = h * substeps
    usable = [m for m in report if m["bound"] > 0 and np.isfinite(m["bound"])]
    need = max(
        (
            int(np.ceil(m["omega_n"] * dt / ((1.0 - STIFFNESS_MARGIN) * m["bound"])))
            for m in usable
        ),
        default=substeps,
    )
    hint = (
        f"use --substeps {need} or more" if need > substeps else "use more substeps"
    ) + ", the implicit_euler integrator, --closure exact, or lower gains"
    if not over:
        raise StiffnessError(
            f"penalty closure modes of {', '.join(repr(c.name) for c in model.closures)}:"
            f" one step of {integrator_name} with h = {h:.3g} s amplifies the closure error by "
            f"{radius:.4g} (spectral radius of the step on the linearized closure dynamics "
            f"at the initial pose, above 1); {hint}"
        )
    worst = max(over, key=lambda m: m["omega_h"] / max(m["bound"], 1e-300))
    raise StiffnessError(
        f"{_where(worst)}: omega_n = {worst['omega_n']:.4g} rad/s (zeta = {worst['zeta']:.3g}"
        f"{_alone(worst)}, effective mass {worst['m_eff']:.4g}) gives omega_n*h = "
        f"{worst['omega_h']:.3g} with h = {h:.3g} s, "
        f"{'beyond' if worst['omega_h'] > worst['bound'] else 'on'} the stability bound "
        f"{worst['bound']:.3g} of {integrator_name} (at the initial pose); {hint}"
    )


def _where(mode: dict) -> str:
    """The closure row, or the closures and rows of a coupled mode, in words."""
    if mode["share"][0] >= 0.99:
        return f"closure '{mode['closure']}' row {mode['row']}"
    names = mode["closures"]
    listed = ", ".join(f"'{c}'" for c in names[:4]) + (
        f" and {len(names) - 4} more" if len(names) > 4 else ""
    )
    rows = mode["rows"]
    shown = ", ".join(str(i) for i in rows[:6]) + (", ..." if len(rows) > 6 else "")
    return (
        f"closure{'s' if len(names) > 1 else ''} {listed} (coupled mode of "
        f"{len(rows)} row{'s' if len(rows) > 1 else ''}: {shown})"
    )


def _alone(mode: dict) -> str:
    """The stiffest row's own frequency, for a coupled mode."""
    if mode["share"][0] >= 0.99 or not np.isfinite(mode["row_omega_n"]):
        return ""
    return f"; row {mode['row']} alone: omega_n = {mode['row_omega_n']:.4g} rad/s"
