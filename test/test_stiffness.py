"""The penalty stiffness check judges the coupled closure modes, not each row alone.

Near the closure manifold the penalty closure error obeys ``x' = J x`` with ``x = (C, Cdot)`` and
``J = [[0, I], [-G Kp, -G Kv]]``, ``G = A M^-1 A^T``. Rows that share links ring together, so a
coupled mode can be stiffer than any row: the previous per-row rule (``omega_n^2 = Kp G_ii``)
accepted settings that then diverged.

Oracles: closed-form stability limits of the scalar test equation (explicit Euler 2 on the
negative real axis; RK4 2.7853 there and 2 sqrt(2) on the imaginary axis); a point mass on a
hinge (``omega_n^2 = Kp / m`` whatever the rows); ``G`` from central-difference ``M`` and ``A`` of
the independent chain geometry (``test/chains.py``); the eigenvalues of ``J`` formed here; and
actual runs, where refused settings blow up and accepted ones stay closed.
"""

from __future__ import annotations

import math
from dataclasses import replace

import chains as ch
import numpy as np
import pytest
from oracle.mechanism import Mechanism

from vjm_ros.core.constraints import closure_mobility, penalty_modes
from vjm_ros.core.errors import DivergenceError, StiffnessError
from vjm_ros.core.integrators import make_integrator
from vjm_ros.scene.loader import load_scene, parse_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

RK4_REAL = 2.785293563405282  # root of |1 + z + z^2/2 + z^3/6 + z^4/24| = 1 on z < 0
EXPLICIT = ("explicit_euler", "semi_implicit_euler", "rk4")


def point_mass(angle: float, mass: float = 2.0, length: float = 0.5, kp: float = 1e4,
               kv: float = 0.0):
    """A point mass on a massless arm turning about the origin, its tip pinned where it is.

    One coordinate, two hinge rows: ``A = L n(angle)`` (2 x 1), ``M = m L^2``, so
    ``G = n n^T / m`` has rank 1 and its one mode has ``omega_n^2 = Kp / m`` for any angle, while
    the rows alone have ``Kp n_i^2 / m`` (``n = (-sin, cos)``). No gravity.
    """
    tip = (length * math.cos(angle), length * math.sin(angle))
    return parse_scene(f"""
name: point_mass
gravity: [0.0, 0.0]
chains:
  - name: arm
    links:
      - {{name: arm, length: {length!r}, mass: {mass!r}, inertia: 0.0, com: [{length!r}, 0.0],
         joint: {{name: shoulder, type: revolute, angle: {angle!r}}}}}
closures:
  - {{name: tip_pin, type: hinge, point: {{link: arm, at: tip}}, target: {{ground: [{tip[0]!r}, {tip[1]!r}]}}}}
closure_method: {{method: penalty, kp: {kp!r}, kv: {kv!r}}}
""")


def per_row_ratio(g, kp, kv, integrator: str, h: float) -> float:
    """Worst ``omega_n h / bound`` of the rows taken one by one (the previous rule)."""
    integ = make_integrator(integrator)
    worst = 0.0
    for i in range(len(kp)):
        if g[i, i] <= 0 or kp[i] <= 0:
            continue
        wn = math.sqrt(kp[i] * g[i, i])
        zeta = kv[i] * g[i, i] / (2.0 * wn)
        worst = max(worst, wn * h / integ.stability_bound(zeta))
    return worst


def jacobian_eigenvalues(g, kp, kv):
    """Eigenvalues of ``J = [[0, I], [-G Kp, -G Kv]]``, 1/s."""
    r = len(kp)
    jac = np.block([[np.zeros((r, r)), np.eye(r)], [-g * kp[None, :], -g * kv[None, :]]])
    return np.linalg.eigvals(jac)


def fd_mobility(model, q, residual):
    """``G = A M^-1 A^T`` from central differences of the independent geometry."""
    a = ch.coordinate_jacobian(residual, q, ch.JAC_STEP)
    return a @ np.linalg.solve(ch.mass_matrix_fd(model, q), a.T)


def three_chain_residual(model, q):
    """``C`` of three_chain's two pins: chain 1's tip minus chain 2's and chain 3's tips, m."""
    tip = {}
    for name in ("c1_distal", "c2_distal", "c3_distal"):
        k = model.link_names.index(name)
        tip[name] = ch.point_on_link(model, q, k, (model.links[k].length, 0.0))
    return np.concatenate((tip["c1_distal"] - tip["c2_distal"], tip["c1_distal"] - tip["c3_distal"]))


def four_bar_residual(model, q):
    """``C`` of four_bar's tip pin: the rocker's tip minus the ground point (1, 0), m."""
    k = model.link_names.index("rocker")
    return ch.point_on_link(model, q, k, (model.links[k].length, 0.0)) - np.array([1.0, 0.0])


def run_until(sim, seconds: float) -> tuple[float, float | None]:
    """Advance ``sim``; return the largest closure error and the divergence time (None if none)."""
    worst = 0.0
    try:
        for _ in range(int(round(seconds * sim.settings.rate))):
            sim.advance()
            worst = max(worst, sim.sample().max_closure_error)
    except DivergenceError as exc:
        return worst, exc.time
    return worst, None


# ------------------------------------------------------------------ stability function
TAYLOR = {"explicit_euler": (1.0, 1.0), "rk4": (1.0, 1.0, 1 / 2, 1 / 6, 1 / 24)}
"""Coefficients of ``R(z) = sum c_k z^k``, the textbook stability functions of the Runge-Kutta
methods (``y' = mu y`` is stepped to ``R(h mu) y``)."""


def stability_function(name: str, z):
    """``R(z)`` of a Runge-Kutta method (:data:`TAYLOR`)."""
    return np.polynomial.polynomial.polyval(z, TAYLOR[name])


def ray_bound(name: str, angle: float) -> float:
    """Extent of ``|R(s exp(i angle))| <= 1`` from ``s = 0``: the smallest positive root of the
    real polynomial ``|R|^2 - 1`` in ``s`` (0 when its lowest term is positive: growth at
    once). Coefficients below 1e-12 are round-off of terms that cancel (``|R(iy)|^2`` has no
    ``y^2`` or ``y^4`` term for RK4)."""
    p = np.polynomial.Polynomial(np.array(TAYLOR[name]) * np.exp(1j * angle) ** np.arange(
        len(TAYLOR[name])))
    excess = (p * np.polynomial.Polynomial(p.coef.conj()) - 1.0).coef.real
    low = next(k for k in range(1, excess.size) if abs(excess[k]) > 1e-12)  # s^low divides
    if excess[low] > 0:
        return 0.0
    roots = np.roots(excess[low:][::-1])
    return float(min(r.real for r in roots if abs(r.imag) < 1e-9 and r.real > 0))


@pytest.mark.parametrize("name,angle,expect", [
    ("explicit_euler", math.pi, 2.0),  # |1 + z| = 1 at z = -2
    ("explicit_euler", math.pi / 2, 0.0),  # |1 + i y|^2 = 1 + y^2
    ("rk4", math.pi, RK4_REAL),
    ("rk4", math.pi / 2, 2.0 * math.sqrt(2.0)),  # |R(iy)|^2 = 1 - y^6/72 + y^8/576
])
def test_ray_bound_meets_the_textbook_extents(name, angle, expect):
    """Oracle check: the extents of the stability regions along the real and imaginary axes."""
    # roots of a degree <= 8 polynomial with O(1) coefficients: ~1e-14
    assert ray_bound(name, angle) == pytest.approx(expect, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("name", ["explicit_euler", "rk4"])
@pytest.mark.parametrize("zeta", [0.0, 0.1, 0.5, 0.9, 1.5, 3.0])
def test_oscillator_bound_agrees_with_the_stability_function(name, zeta):
    """A Runge-Kutta method is stable on an oscillator iff both roots mu have |R(h mu)| <= 1.

    Oracle: the roots are ``omega_n (-zeta +- i sqrt(1 - zeta^2))`` (angle ``pi - acos zeta``)
    below critical damping, and ``omega_n (-zeta -+ sqrt(zeta^2 - 1))`` (the larger decides, on
    the negative real axis) above it.
    """
    integ = make_integrator(name)
    if zeta < 1.0:
        expect = ray_bound(name, math.pi - math.acos(zeta))
    else:
        expect = ray_bound(name, math.pi) / (zeta + math.sqrt(zeta * zeta - 1.0))
    if name == "explicit_euler" and zeta == 0.0:
        # The radius 1 + x^2/2 passes the check's 1e-12 allowance up to x ~ 1.4e-6.
        assert expect == 0.0 and integ.stability_bound(0.0) < 2e-6
        return
    # The bisection stops within ~1e-12 of the crossing; the oscillator's spectral radius comes
    # from 2 x 2 eigenvalues (~1e-15), so 1e-9 relative is safe.
    assert integ.stability_bound(zeta) == pytest.approx(expect, rel=1e-9)


def test_step_matrix_is_r_of_hj_for_runge_kutta():
    """Oracle: a Runge-Kutta step on ``y' = J y`` is ``R(h J)``, so its eigenvalues are
    ``R(h mu)`` for the eigenvalues ``mu`` of J (non-proportional damping, coupled rows)."""
    rng = np.random.default_rng(7)
    b = rng.normal(size=(3, 3))
    g = b @ b.T + 0.1 * np.eye(3)
    kp, kv = np.array([1e4, 3e4, 2e4]), np.array([10.0, 80.0, 5.0])
    k, d = g * kp[None, :], g * kv[None, :]
    h = 1e-3
    for name in ("explicit_euler", "rk4"):
        step = make_integrator(name).step_matrix(k, d, h)
        mu = jacobian_eigenvalues(g, kp, kv)
        # Spectral radii of a well-conditioned 6 x 6 map: agreement to ~1e-12.
        assert np.max(np.abs(np.linalg.eigvals(step))) == pytest.approx(
            np.max(np.abs(stability_function(name, h * mu))), rel=1e-9)


# ------------------------------------------------------------------ modes
def test_single_decoupled_row_gives_its_own_omega_n():
    """Point mass with its arm along x: only the y row moves, so the one mode is that row's.

    Oracle: ``omega_n^2 = Kp / m``, ``zeta = Kv / (2 sqrt(Kp m))``; the x row, which no
    coordinate moves (``G`` has rank 1), sets no mode; the roots are those of
    ``m mu^2 + Kv mu + Kp = 0``.
    """
    m, kp, kv = 2.0, 1e4, 30.0
    scene = point_mass(0.0, mass=m, kp=kp, kv=kv)
    sim = Simulator(scene.model, SimulationSettings(integrator="rk4", rate=1000.0), scene.gains)
    (mode,) = sim.stiffness_report
    # G and the modes come from a 1 x 1 solve and a 2 x 2 eigen-decomposition: ~1e-15.
    assert mode["omega_n"] == pytest.approx(math.sqrt(kp / m), rel=1e-12)
    assert mode["zeta"] == pytest.approx(kv / (2 * math.sqrt(kp * m)), rel=1e-12)
    assert mode["row"] == 1 and mode["rows"] == [1] and mode["closure"] == "tip_pin"
    assert mode["m_eff"] == pytest.approx(m, rel=1e-12)
    assert mode["row_omega_n"] == pytest.approx(mode["omega_n"], rel=1e-12)
    assert mode["omega_h"] == pytest.approx(mode["omega_n"] * 1e-3, rel=1e-12)
    assert mode["bound"] == pytest.approx(make_integrator("rk4").stability_bound(mode["zeta"]))
    ev = Mechanism(scene.model, sim.method).evaluate(sim.q0, sim.qd0, np.zeros(1))
    modes = penalty_modes(closure_mobility(ev.dyn.mass_matrix, ev.closure.jacobian),
                          sim.method.kp, sim.method.kv)
    assert np.allclose(np.sort_complex(modes.eigenvalues[0]),
                       np.sort_complex(np.roots([m, kv, kp])), rtol=1e-12, atol=0)


def test_point_mass_mode_is_stiffer_than_either_row():
    """Arm at 30 deg: both rows move, and their mode has omega_n^2 = Kp / m exactly.

    Oracle: ``G = n n^T / m``. The rows alone see ``Kp sin^2 / m`` and ``Kp cos^2 / m`` (effective
    masses ``m / n_i^2``), each softer than the mode they share.
    """
    m, kp = 2.0, 1e4
    scene = point_mass(math.radians(30.0), mass=m, kp=kp)
    sim = Simulator(scene.model, SimulationSettings(integrator="rk4", rate=1000.0), scene.gains)
    (mode,) = sim.stiffness_report
    assert mode["omega_n"] == pytest.approx(math.sqrt(kp / m), rel=1e-12)
    assert mode["row"] == 1 and mode["rows"] == [1, 0]
    assert mode["share"] == pytest.approx([0.75, 0.25], rel=1e-12)  # cos^2, sin^2 of 30 deg
    assert mode["row_omega_n"] == pytest.approx(math.sqrt(kp / m) * math.cos(math.radians(30)),
                                                rel=1e-12)


@pytest.mark.parametrize("scene_name,residual,settings", [
    ("four_bar", four_bar_residual, {"kp": 1e7, "kv": 1e3}),
    ("three_chain", three_chain_residual, {"omega_n": 1000.0, "zeta": 1.0}),
])
def test_modes_are_the_eigenvalues_of_j(scene_name, residual, settings):
    """Oracle: every mode's roots are eigenvalues of J formed from the central-difference G.

    J has 2r eigenvalues and the report r modes of two roots each (G has full rank here).
    """
    scene = load_scene(scene_name)
    sim = Simulator(scene.model, SimulationSettings(check_stiffness=False, **settings),
                    scene.gains)
    g = fd_mobility(scene.model, sim.q0, lambda q: residual(scene.model, q))
    mu = jacobian_eigenvalues(g, sim.method.kp, sim.method.kv)
    report = sim.stiffness_report
    assert len(report) == len(sim.method.kp)
    for mode in report:
        wn, zeta = mode["omega_n"], mode["zeta"]
        for root in np.roots([1.0, 2 * zeta * wn, wn * wn]):
            # G from differences is good to ~1e-9 relative; the two roots of a mode are at
            # least ~400 rad/s apart here (closest to critical: zeta = 0.97), so they move by
            # ~1e-9 omega_n^2 / 400 rad/s ~ 1e-6 rad/s: 1e-6 of omega_n is safe.
            assert np.min(np.abs(mu - root)) < 1e-6 * wn, (mode, root)


# ------------------------------------------------------------------ the check against runs
def test_point_mass_threshold_is_the_coupled_one():
    """RK4, Kv = 0: the per-row rule would accept Kp up to (4/3) m (2 sqrt(2)/h)^2; the mode
    goes unstable at m (2 sqrt(2)/h)^2. Between the two the check refuses, and a run with the
    check off blows up; just below, the run stays closed.

    The arm is released 1 um off its pin (the tip pulled back along the arm's normal), at rest,
    without gravity: the closure error is the mode itself.
    """
    m, h = 2.0, 1e-3
    kp_mode = m * (2 * math.sqrt(2) / h) ** 2
    kp_row = kp_mode / math.cos(math.radians(30)) ** 2
    for factor, stable in ((1.1, False), (0.95, True)):
        kp = factor * kp_mode
        assert kp < 0.9 * kp_row  # the per-row rule accepts both
        scene = point_mass(math.radians(30.0), mass=m)
        settings = SimulationSettings(integrator="rk4", rate=1.0 / h, kp=kp, kv=0.0)
        if stable:
            Simulator(scene.model, settings, scene.gains)
        else:
            with pytest.raises(StiffnessError, match="tip_pin") as info:
                Simulator(scene.model, settings, scene.gains)
            assert "coupled mode" in str(info.value)
        sim = Simulator(scene.model, replace(settings, check_stiffness=False), scene.gains)
        sim.q = sim.q + 2e-6  # 2e-6 rad on a 0.5 m arm: 1 um along the arm's normal
        c0 = sim.sample().max_closure_error
        worst, diverged = run_until(sim, 0.2)
        if stable:
            # Undamped, RK4 inside its region: the error neither grows nor leaves the
            # perturbation's size (it decays slowly, |R| < 1); 1.01 allows for the geometry.
            assert diverged is None and worst <= 1.01 * c0, (worst, c0)
        else:
            # |R(i 3.0)| = 1.4 per step: from 1 um past the guard (12.5 cm) in ~40 steps.
            assert diverged is not None and diverged < 0.1


@pytest.mark.parametrize("scene_name,residual,settings,accepted", [
    # Bench rows: Kp = 1e7 with RK4 at 1 kHz (per-row 0.99 of the bound, the tip pin's mode
    # 1.07); accepted at Kp = 8e6.
    ("four_bar", four_bar_residual, {"kp": 1e7, "kv": 1e3}, {"kp": 8e6, "kv": 1e3}),
    # omega_n = 1000 rad/s, zeta = 1 per row with RK4 at 1 kHz: each row at 0.36 of the bound,
    # but three chains pulling on one pin make a mode at 1.26; accepted with two substeps.
    ("three_chain", three_chain_residual, {"omega_n": 1000.0, "zeta": 1.0},
     {"omega_n": 1000.0, "zeta": 1.0, "substeps": 2}),
])
def test_per_row_passes_coupled_refuses_and_the_run_diverges(scene_name, residual, settings,
                                                             accepted):
    """Settings the per-row rule accepts, the coupled check refuses, and they do diverge.

    Oracles: the per-row ratio and the mode's ratio from the central-difference ``G``; runs of
    0.3 s under gravity from the scene's start: the refused setting is stopped by the guard, the
    accepted one stays within 1 cm of closed (its gravity sag is below 1 mm).
    """
    scene = load_scene(scene_name)
    base = {"integrator": "rk4", "rate": 1000.0}
    probe = Simulator(scene.model, SimulationSettings(check_stiffness=False, **base, **settings),
                      scene.gains)
    g = fd_mobility(scene.model, probe.q0, lambda q: residual(scene.model, q))
    kp, kv = probe.method.kp, probe.method.kv
    assert per_row_ratio(g, kp, kv, "rk4", probe.h) < 1.0
    mu = jacobian_eigenvalues(g, kp, kv)
    assert np.max(np.abs(stability_function("rk4", probe.h * mu))) > 1.0 + 1e-3
    with pytest.raises(StiffnessError) as info:
        Simulator(scene.model, SimulationSettings(**base, **settings), scene.gains)
    msg = str(info.value)
    for c in scene.model.closures:
        assert f"'{c.name}'" in msg
    assert "coupled mode" in msg and "omega_n*h = " in msg and "stability bound" in msg
    assert "--substeps" in msg and "implicit_euler" in msg and "--closure exact" in msg
    assert "lower gains" in msg
    _, diverged = run_until(probe, 0.3)
    assert diverged is not None and diverged < 0.3
    sim = Simulator(scene.model, SimulationSettings(**{**base, **accepted}), scene.gains)
    worst, diverged = run_until(sim, 0.3)
    assert diverged is None and worst < 1e-2, (worst, diverged)


def test_suggested_substeps_pass_the_check():
    """The refusal's ``--substeps N`` is enough, and N - 1 is not (three_chain, RK4, 1 kHz)."""
    scene = load_scene("three_chain")
    gains = {"integrator": "rk4", "omega_n": 3000.0, "zeta": 1.0}
    with pytest.raises(StiffnessError) as info:
        Simulator(scene.model, SimulationSettings(**gains), scene.gains)
    need = int(str(info.value).split("--substeps ")[1].split()[0])
    assert need > 1
    Simulator(scene.model, SimulationSettings(substeps=need, **gains), scene.gains)
    with pytest.raises(StiffnessError):
        Simulator(scene.model, SimulationSettings(substeps=need - 1, **gains), scene.gains)


@pytest.mark.parametrize("integrator", EXPLICIT)
def test_check_agrees_with_the_step_on_the_coupled_system(integrator):
    """Oracle: the method's own step on the 2r-dimensional linearized closure system.

    For each Kp on a grid (three_chain, Kv = 2 sqrt(Kp * 1 kg), 1 kHz) the check refuses exactly
    when one step of the method on ``(C, Cdot)`` has a spectral radius above 1. Gains within
    0.1 % of the threshold are skipped (the check keeps a 1e-6 margin below the bound).
    """
    scene = load_scene("three_chain")
    integ = make_integrator(integrator)
    decided = set()
    for kp in np.geomspace(1e3, 1e8, 26):
        kv = 2.0 * math.sqrt(kp)
        settings = SimulationSettings(integrator=integrator, kp=kp, kv=kv, check_stiffness=False)
        sim = Simulator(scene.model, settings, scene.gains)
        g = fd_mobility(scene.model, sim.q0, lambda q: three_chain_residual(scene.model, q))
        step = integ.step_matrix(g * sim.method.kp[None, :], g * sim.method.kv[None, :], sim.h)
        radius = float(np.max(np.abs(np.linalg.eigvals(step))))
        if abs(radius - 1.0) < 1e-3:
            continue
        try:
            Simulator(scene.model, replace(settings, check_stiffness=True), scene.gains)
            refused = False
        except StiffnessError:
            refused = True
        assert refused == (radius > 1.0), (kp, radius)
        decided.add(refused)
    assert decided == {True, False}  # the grid straddles the threshold


def test_rank_deficient_mobility_drops_unreachable_directions():
    """Oracle: with G of rank 1 the closure error along its null space gets no force and no
    mode; penalty_modes returns the one mode and no NaN, for proportional and other gains."""
    n = np.array([-0.5, math.sqrt(3) / 2])
    g = np.outer(n, n) / 2.0
    for kp, kv in ((np.array([1e4, 1e4]), np.array([10.0, 10.0])),
                   (np.array([1e4, 1e4]), np.array([10.0, 50.0]))):
        modes = penalty_modes(g, kp, kv)
        assert modes.omega_n.shape == (1,) and np.all(np.isfinite(modes.omega_n))
        mu = jacobian_eigenvalues(g, kp, kv)
        live = mu[np.abs(mu) > 1e-6]
        for root in modes.eigenvalues[0]:
            # 4 x 4 eigenvalues of a well-scaled matrix: ~1e-12 of |mu| ~ 100.
            assert np.min(np.abs(live - root)) < 1e-8 * abs(root)
