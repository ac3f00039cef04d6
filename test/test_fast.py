"""The compiled kernel (:mod:`vjm_ros.core.compiled`) reproduces the numpy oracle (:mod:`oracle.mechanism`).

Tolerances. The two implementations reach the same quantities by different formulas in double
precision: the kernel by one recursion per chain, ``M = sum m J^T J + I Jw^T Jw``, an LU factor
of ``M`` and a Jacobi eigen-solve of ``G = A M^-1 A^T``; the oracle by joint columns summed per
point, Newton-Euler, a Cholesky factor of ``M`` and the singular values of ``A L^-T``
(:mod:`oracle`). Kinematics, ``M``, ``b`` and the closure rows are sums of a few products: over
400 random states of every model and method they agree to 1.2e-14 of their largest entry, except
where a row is small against the terms it sums (a lone slider row's ``Cdot`` and ``Adot qd``
project a point's motion on the line's normal): up to 3e-13 there. ``RTOL = 1e-12`` holds both.
The solves are backward stable, so their results differ by about ``eps * kappa``, ``kappa`` the
condition number of the solve: ``cond(M)`` (penalty), ``cond(M) * cond+(G)`` (exact; ``cond+``
over the eigenvalues the truncated solve keeps), ``cond(M + h A^T (h Kp + Kv) A)``
(penalty-implicit velocity). The check is ``<= max(RTOL, 4 eps kappa)`` with ``RTOL = 1e-12``,
norm-wise (relative to the largest component of the reference). Measured over the same states,
the differences stay below 0.17 of that bound; they pass ``4 eps kappa`` (up to 40 ``eps kappa``)
only where ``kappa`` <= 21 (the pendulum, whose ``qd + h qdd`` can cancel, and the slider-crank),
at < 3e-14, which the floor ``RTOL`` holds. Any modelling difference (a wrong sign, a missing
term) shows at 1e-6 or more.
Random poses of the over-constrained test models are sometimes nearly singular; draws with
``kappa > KAPPA_MAX = 1e6`` are skipped, since there the comparison would measure conditioning,
not physics.

Over 1 s of RK4 at 1 kHz these round-off differences are carried through 1000 steps and amplified by
the dynamics (the five-bar and three-chain scenes grow perturbations ~10-100x per second,
docs/design.md section 6): measured differences are ~1e-13, and ``RUN_TOL = 1e-9`` (rad, m, rad/s, m/s) leaves
orders of magnitude of margin.
"""

from __future__ import annotations

import os
import subprocess
import sys
import zlib
from dataclasses import replace

import numpy as np
import pytest
from oracle.fixed import (
    RK4,
    ExplicitEuler,
    ImplicitPenaltyEuler,
    SemiImplicitEuler,
)
from oracle.kinematics import forward_kinematics
from oracle.mechanism import Mechanism

from vjm_ros.core.compiled import (
    HAVE_NUMBA,
    make_mechanism,
)
from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.evaluation import Evaluation as FastEvaluation
from vjm_ros.core.integrators import make_integrator
from vjm_ros.core.mechanism import Mechanism as FastMechanism
from vjm_ros.core.model import (
    ANGLE,
    GROUND,
    HINGE,
    PRISMATIC,
    REVOLUTE,
    SLIDER,
    Actuator,
    Chain,
    Closure,
    Joint,
    Link,
    Model,
    PointRef,
)
from vjm_ros.scene.loader import builtin_scenes, load_scene
from vjm_ros.sim.simulator import SimulationSettings, Simulator

pytestmark = pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")

RTOL = 1e-12
RUN_TOL = 1e-9
KAPPA_MAX = 1e6
EPS = float(np.finfo(float).eps)
SCENES = [s for s in builtin_scenes()
          if not (load_scene(s).model.has_plant_terms or load_scene(s).model.has_joint_efforts)]
"""The built-in scenes of the ideal mechanism: the oracle writes only that (joint damping,
friction, stops and loads have their own oracles in test_plant_terms.py and
test_joint_friction.py)."""
METHODS = ("penalty", "exact")


def _method(kind: str, rows: int, rng: np.random.Generator | None = None):
    """Penalty gains of the thesis (optionally varied per row) or the exact closure."""
    if kind == "exact":
        return ExactClosure(alpha=20.0, beta=15.0)
    kp = np.full(rows, 1e5)
    kv = np.full(rows, 100.0)
    if rng is not None:
        kp = kp * rng.uniform(0.5, 2.0, rows)
        kv = kv * rng.uniform(0.5, 2.0, rows)
    return PenaltyClosure(kp, kv)


def _close(fast, ref, rtol=RTOL):
    """Norm-wise relative agreement: ``max |fast - ref| <= rtol * max |ref|``."""
    fast, ref = np.asarray(fast, dtype=float), np.asarray(ref, dtype=float)
    assert fast.shape == ref.shape
    scale = max(float(np.max(np.abs(ref), initial=0.0)), 1e-300)
    err = float(np.max(np.abs(fast - ref), initial=0.0))
    assert err <= rtol * scale, f"max error {err:.3g} vs scale {scale:.3g}"


def _random_state(rng, model, speed=2.0):
    q = np.where(model.is_revolute, rng.uniform(-np.pi, np.pi, model.n), rng.uniform(-0.5, 0.5, model.n))
    return q, rng.uniform(-speed, speed, model.n), rng.normal(0.0, 5.0, model.n)


def _kappa(model, method, q, h: float = 0.0) -> float:
    """Condition number of the solve behind ``accelerations`` (``h = 0``) or the implicit step."""
    ev = Mechanism(model, method).evaluate(q, np.zeros(model.n), np.zeros(model.n))
    m, a = ev.dyn.mass_matrix, ev.closure.jacobian
    kappa = float(np.linalg.cond(m))
    if isinstance(method, ExactClosure):
        if a.shape[0]:
            w = np.linalg.eigvalsh(a @ np.linalg.solve(m, a.T))
            kept = w[w > method.rcond * w[-1]]
            kappa *= float(kept[-1] / kept[0])
    elif h > 0.0:
        kappa = max(kappa, float(np.linalg.cond(m + h * (a.T * (h * method.kp + method.kv)) @ a)))
    return kappa


def _tol(kappa: float) -> float:
    """Norm-wise relative tolerance for a solve of condition number ``kappa`` (module docstring)."""
    return max(RTOL, 4.0 * EPS * kappa)


def _states(rng, model, method, count):
    """``count`` random ``(q, qd, tau)`` whose solves have ``kappa <= KAPPA_MAX``."""
    out = []
    for _ in range(100 * count):
        state = _random_state(rng, model)
        if _kappa(model, method, state[0], 1e-2) <= KAPPA_MAX:
            out.append(state)
            if len(out) == count:
                return out
    raise AssertionError(f"{model.name}: fewer than {count} well-conditioned states")


def _mixed_model(rng: np.random.Generator) -> Model:
    """Three chains with revolute and prismatic joints and one closure of every kind and target.

    The built-in scenes use hinges and ground sliders only; this model adds sliders on a moving
    line, angle closures to ground and to another link, and prismatic joints (9 coordinates,
    8 closure rows).
    """
    links, joints = [], []
    kinds = [REVOLUTE, PRISMATIC, REVOLUTE, REVOLUTE, REVOLUTE, PRISMATIC, REVOLUTE, REVOLUTE,
             PRISMATIC]
    for k, kind in enumerate(kinds):
        length = float(rng.uniform(0.3, 1.2))
        links.append(
            Link(
                name=f"l{k}",
                chain=k // 3,
                length=length,
                mass=float(rng.uniform(0.3, 3.0)),
                inertia=float(rng.uniform(0.01, 0.3)),
                com=(float(rng.uniform(-0.2, 1.2) * length), float(rng.uniform(-0.3, 0.3))),
            )
        )
        joints.append(
            Joint(
                name=f"j{k}",
                kind=kind,
                angle=float(rng.uniform(-np.pi, np.pi)),
                slide=float(rng.uniform(-0.5, 0.5)),
                velocity=float(rng.uniform(-1.0, 1.0)),
            )
        )
    chains = (
        Chain("a", (0.0, 0.0), 0.3, 0.2, (0, 1, 2)),
        Chain("b", (1.5, 0.2), -0.4, 0.0, (3, 4, 5)),
        Chain("c", (0.5, -1.0), 1.2, 0.3, (6, 7, 8)),
    )
    d = rng.normal(size=2)
    d = tuple(float(x) for x in d / np.linalg.norm(d))
    closures = (
        Closure("hinge_links", HINGE, PointRef(2, (0.7, 0.1)), PointRef(5, (0.4, -0.1))),
        Closure("hinge_ground", HINGE, PointRef(8, (0.3, 0.0)), PointRef(GROUND, (0.5, 0.4))),
        Closure("slider_ground", SLIDER, PointRef(4, (0.6, 0.0)), PointRef(GROUND, (1.0, -0.5)), d),
        Closure("slider_link", SLIDER, PointRef(2, (0.2, 0.05)), PointRef(7, (0.1, 0.0)), (0.6, 0.8)),
        Closure("angle_ground", ANGLE, PointRef(1, (0.0, 0.0)), PointRef(GROUND, (0.0, 0.0)), offset=0.4),
        Closure("angle_link", ANGLE, PointRef(4, (0.0, 0.0)), PointRef(6, (0.0, 0.0)), offset=-2.9),
    )
    return Model.build(
        "mixed",
        chains,
        tuple(links),
        tuple(joints),
        closures,
        actuators=(Actuator(0), Actuator(3)),
        gravity=(0.3, -9.81),
    )


def _models():
    out = [(name, load_scene(name).model) for name in SCENES]
    out += [(f"mixed{seed}", _mixed_model(np.random.default_rng(seed))) for seed in (1, 2)]
    return out


MODELS = _models()
MODEL_IDS = [name for name, _ in MODELS]


# ---------------------------------------------------------------------------------- single calls
@pytest.mark.parametrize("kind", METHODS)
@pytest.mark.parametrize("name,model", MODELS, ids=MODEL_IDS)
def test_accelerations_and_implicit_velocity(name, model, kind):
    """Same ``qdd`` and penalty-implicit velocity at the initial and at random states."""
    rng = np.random.default_rng(zlib.crc32(f"{name}/{kind}".encode()))
    method = _method(kind, model.n_rows, rng)
    ref, fast = Mechanism(model, method), FastMechanism(model, method)
    q0, qd0 = model.initial_state()
    states = [(q0, qd0, np.zeros(model.n))] + _states(rng, model, method, 25)
    for q, qd, tau in states:
        _close(fast.accelerations(q, qd, tau), ref.accelerations(q, qd, tau), _tol(_kappa(model, method, q)))
        for h in (1e-3, 1e-2):
            _close(
                fast.implicit_penalty_velocity(q, qd, tau, h),
                ref.implicit_penalty_velocity(q, qd, tau, h),
                _tol(_kappa(model, method, q, h)),
            )
    assert fast.evaluations == ref.evaluations


@pytest.mark.parametrize("name,model", MODELS, ids=MODEL_IDS)
def test_closure_jacobian(name, model):
    """``A(q)`` from one kernel call equals the reference's (the node's singularity measure);
    the kernel sums the same products in another order: 1e-12 relative."""
    rng = np.random.default_rng(11)
    method = _method("exact", model.n_rows, rng)
    ref, fast = Mechanism(model, method), FastMechanism(model, method)
    for q, _, _ in [(*model.initial_state(), None)] + _states(rng, model, method, 5):
        a_ref = ref.closure_jacobian(q)
        np.testing.assert_allclose(fast.closure_jacobian(q), a_ref, rtol=1e-12,
                                   atol=1e-12 * max(1.0, float(np.abs(a_ref).max(initial=0.0))))
    assert fast.evaluations == 0


@pytest.mark.parametrize("kind", METHODS)
@pytest.mark.parametrize("name,model", MODELS, ids=MODEL_IDS)
def test_evaluate_every_term(name, model, kind):
    """Every field of :class:`Evaluation`, the energies and the closure reductions agree."""
    rng = np.random.default_rng(7)
    method = _method(kind, model.n_rows, rng)
    ref, fast = Mechanism(model, method), FastMechanism(model, method)
    for q, qd, tau in _states(rng, model, method, 5):
        a, b = ref.evaluate(q, qd, tau), fast.evaluate(q, qd, tau)
        tol = _tol(_kappa(model, method, q))
        assert isinstance(b, FastEvaluation)
        for field in ("theta", "origin", "omega", "v_origin", "a_origin", "n_pred", "rotation", "slide"):
            _close(getattr(b.dyn.kin, field), getattr(a.dyn.kin, field))
        _close(b.dyn.mass_matrix, a.dyn.mass_matrix)
        _close(b.dyn.bias, a.dyn.bias)
        _close(b.dyn.com, a.dyn.com)
        _close(b.dyn.com_velocity, a.dyn.com_velocity)
        for field in ("residual", "rate", "jacobian", "bias", "row_direction", "points"):
            _close(getattr(b.closure, field), getattr(a.closure, field))
        _close(b.qdd, a.qdd, tol)
        _close(b.row_force, a.row_force, tol)
        _close(fast.energies(b, qd), ref.energies(a, qd))
        _close(fast.closures.errors(b.closure), ref.closures.errors(a.closure))
        _close(
            fast.closures.closure_forces(b.closure, b.row_force),
            ref.closures.closure_forces(a.closure, a.row_force),
            tol,
        )
        guard = ref.closures.errors(ref.closures.evaluate(forward_kinematics(model, q), jacobian=False))
        _close(fast.closure_errors(q), guard)


def test_evaluations_do_not_share_memory():
    """Arrays returned by one call are not overwritten by the next."""
    model = load_scene("four_bar").model
    fast = FastMechanism(model, _method("penalty", model.n_rows))
    q, qd = model.initial_state()
    tau = np.zeros(model.n)
    first = fast.evaluate(q, qd, tau)
    qdd = fast.accelerations(q, qd, tau)
    kept = (first.qdd.copy(), first.dyn.mass_matrix.copy(), first.closure.residual.copy(), qdd.copy())
    fast.evaluate(q + 0.3, qd - 1.0, tau + 2.0)
    fast.accelerations(q + 0.3, qd - 1.0, tau + 2.0)
    for now, then in zip((first.qdd, first.dyn.mass_matrix, first.closure.residual, qdd), kept, strict=True):
        np.testing.assert_array_equal(now, then)


def test_rank_deficient_exact_closure():
    """A closure written twice makes ``A M^-1 A^T`` singular: minimum-norm multipliers.

    Both copies then carry half of the force, and the motion is that of the single closure.
    """
    single = load_scene("four_bar").model
    twice = Model.build(
        "four_bar_twice", single.chains, single.links, single.joints,
        single.closures + tuple(replace(c, name=c.name + "_again") for c in single.closures),
        single.actuators, single.points, tuple(single.gravity),
    )
    rng = np.random.default_rng(11)
    q0, qd0 = single.initial_state()
    for q, qd in [(q0, qd0)] + [(q0 + 0.1 * rng.normal(size=3), rng.normal(size=3)) for _ in range(5)]:
        tau = rng.normal(size=3)
        a = Mechanism(twice, ExactClosure()).evaluate(q, qd, tau)
        b = FastMechanism(twice, ExactClosure()).evaluate(q, qd, tau)
        one = FastMechanism(single, ExactClosure()).evaluate(q, qd, tau)
        _close(b.qdd, a.qdd)
        _close(b.row_force, a.row_force)
        _close(b.qdd, one.qdd)
        _close(b.row_force, 0.5 * np.concatenate((one.row_force, one.row_force)))


@pytest.mark.parametrize("name", [s for s in SCENES if load_scene(s).model.n_rows])
def test_project(name):
    """Projection onto the closure manifold gives the same ``q`` and ``qd``."""
    model = load_scene(name).model
    rng = np.random.default_rng(3)
    ref, fast = Mechanism(model, ExactClosure()), FastMechanism(model, ExactClosure())
    q0, qd0 = model.initial_state()
    for scale in (1e-3, 1e-2):
        q = q0 + scale * rng.normal(size=model.n)
        qd = qd0 + rng.normal(size=model.n)
        qa, va = ref.project(q, qd)
        qb, vb = fast.project(q, qd)
        _close(qb, qa, 1e-10)  # Gauss-Newton stops at |C| <= 1e-12: iterates agree to ~tol / |A|
        _close(vb, va, 1e-10)


def test_singular_mass_matrix_raises_like_numpy():
    """An exactly singular ``M`` raises ``LinAlgError`` from both implementations."""
    link = Link("massless", 0, 1.0, 0.0, 0.0, (0.5, 0.0))
    model = Model.build(
        "massless", (Chain("c", (0.0, 0.0), 0.0, 0.0, (0,)),), (link,), (Joint("j", REVOLUTE, 0.3, 0.0),)
    )
    q, qd = model.initial_state()
    tau = np.zeros(1)
    for mech in (Mechanism(model, ExactClosure()), FastMechanism(model, ExactClosure(), warm_up=False)):
        with pytest.raises(np.linalg.LinAlgError):
            mech.accelerations(q, qd, tau)


# ---------------------------------------------------------------------------------- integrators
STEPWISE = {  # the oracle's step-by-step methods, written from their textbook definitions
    "explicit_euler": ExplicitEuler,
    "semi_implicit_euler": SemiImplicitEuler,
    "rk4": RK4,
    "implicit_euler": ImplicitPenaltyEuler,
}


@pytest.mark.parametrize("kind", METHODS)
@pytest.mark.parametrize("name", list(STEPWISE))
def test_compiled_ticks_match_stepwise(name, kind):
    """A compiled tick equals the oracle's steps, one evaluation at a time, on the same mechanism."""
    model = _mixed_model(np.random.default_rng(5))
    method = _method(kind, model.n_rows)
    a, b = FastMechanism(model, method), FastMechanism(model, method)
    q, qd = model.initial_state()
    tau = np.linspace(-1.0, 1.0, model.n)
    qa, va = STEPWISE[name]().advance(a, 0.0, q, qd, tau, 1e-3, 3)
    integrator = make_integrator(name)
    assert integrator.kernel_method >= 0  # the one compiled call of a whole tick
    qb, vb = integrator.advance(b, 0.0, q, qd, tau, 1e-3, 3)
    _close(qb, qa)
    _close(vb, va)
    assert a.evaluations == b.evaluations


def test_make_mechanism():
    model = load_scene("four_bar").model
    method = _method("exact", model.n_rows)
    with pytest.raises(ValueError, match="kernel: expected one of auto, numba, found 'numpy'"):
        make_mechanism(model, method, "numpy")
    assert isinstance(make_mechanism(model, method, "numba"), FastMechanism)
    assert isinstance(make_mechanism(model, method), FastMechanism)
    with pytest.raises(ValueError, match="kernel"):
        make_mechanism(model, method, "cuda")


def test_advance_fixed_rejects_unknown_method():
    model = load_scene("pendulum").model
    fast = FastMechanism(model, _method("penalty", model.n_rows))
    q, qd = model.initial_state()
    with pytest.raises(ValueError, match="method"):
        fast.advance_fixed(99, q, qd, np.zeros(model.n), 1e-3, 1)


def _simulator(scene, kind: str) -> Simulator:
    gains = dict(scene.gains) if scene.gains.get("method", "penalty") == kind else {}
    settings = SimulationSettings(integrator="rk4", closure=kind, rate=1000.0)
    sim = Simulator(scene.model, settings, gains)
    if scene.model.actuators:
        sim.set_efforts(np.full(len(scene.model.actuators), 0.5))
    return sim


@pytest.mark.parametrize("seconds", [0.25, pytest.param(1.0, marks=pytest.mark.slow)])
@pytest.mark.parametrize("kind", METHODS)
@pytest.mark.parametrize("name", SCENES)
def test_one_second_rk4_run(name, kind, seconds):
    """RK4 at 1 kHz (0.25 s; 1 s in the slow suite), the simulator against the oracle's
    mechanism stepped by the oracle's RK4: same trajectory to ``RUN_TOL``, the same evaluation
    count, the same energies and forces."""
    scene = load_scene(name)
    fast = _simulator(scene, kind)
    assert fast.integrator.kernel_method >= 0
    ref = Mechanism(scene.model, fast.method)
    q, qd = scene.model.initial_state()
    ticks = int(round(seconds * 1000))
    for _ in range(ticks):
        q, qd = RK4().advance(ref, 0.0, q, qd, fast.tau, 1e-3, 1)
        fast.advance()
    assert fast.t == pytest.approx(seconds, abs=1e-12)
    np.testing.assert_allclose(fast.q, q, rtol=0, atol=RUN_TOL)
    np.testing.assert_allclose(fast.qd, qd, rtol=0, atol=RUN_TOL)
    assert fast.mechanism.evaluations == ref.evaluations
    ev = ref.evaluate(q, qd, fast.tau)
    energy = ref.energies(ev, qd)
    b = fast.sample()
    np.testing.assert_allclose(b.energy, energy, rtol=0, atol=RUN_TOL * max(1.0, np.max(np.abs(energy))))
    forces = fast.mechanism.closures.closure_forces(ev.closure, ev.row_force)
    np.testing.assert_allclose(b.closure_force, forces, rtol=1e-6, atol=1e-6)


def test_kernel_without_compilation():
    """With numba's JIT disabled the kernel runs as plain Python and gives the same results."""
    script = (
        "import numpy as np\n"
        "from vjm_ros.core.constraints import ExactClosure, PenaltyClosure\n"
        "from vjm_ros.core.integrators import make_integrator\n"
        "from vjm_ros.core.mechanism import Mechanism as FastMechanism\n"
        "from vjm_ros.scene.loader import load_scene\n"
        "from oracle.fixed import RK4\n"
        "from oracle.mechanism import Mechanism\n"
        "worst = 0.0\n"
        "for name in ('four_bar', 'rrr_platform', 'double_slider'):\n"
        "    m = load_scene(name).model\n"
        "    q, qd = m.initial_state()\n"
        "    tau = np.ones(m.n)\n"
        "    r = m.n_rows\n"
        "    for method in (ExactClosure(), PenaltyClosure(np.full(r, 1e5), np.full(r, 1e2))):\n"
        "        a, b = Mechanism(m, method), FastMechanism(m, method)\n"
        "        x, y = a.accelerations(q, qd, tau), b.accelerations(q, qd, tau)\n"
        "        worst = max(worst, np.max(np.abs(x - y)) / np.max(np.abs(x)))\n"
        "        x = RK4().advance(a, 0.0, q, qd, tau, 1e-3, 2)[1]\n"
        "        y = make_integrator('rk4').advance(b, 0.0, q, qd, tau, 1e-3, 2)[1]\n"
        "        worst = max(worst, np.max(np.abs(x - y)) / np.max(np.abs(x)))\n"
        "print(worst)\n"
    )
    here = os.path.dirname(os.path.abspath(__file__))  # the oracle package lives next to this file
    path = os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH", "")) if p)
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=path)
    out = subprocess.run(
        [sys.executable, "-W", "error", "-c", script], env=env, capture_output=True, text=True,
        timeout=300, check=True,
    )
    assert float(out.stdout.strip().splitlines()[-1]) <= RTOL


# ---------------------------------------------------------------------------------- readers
@pytest.mark.parametrize("name,model", MODELS, ids=MODEL_IDS)
def test_readers_match_the_oracle(name, model):
    """What assembly, replay, the builder and the controllers read through the kernels (link
    frames, closure residuals, ``M``, the motion and Jacobian of link points) equals the oracle's:
    the same formulas summed in another order, 1e-12 relative (module docstring)."""
    from oracle.constraints import ClosureSet
    from oracle.dynamics import mass_matrix
    from oracle.kinematics import point_jacobians, point_motion

    from vjm_ros.core.mechanism import Mechanism as Compiled
    from vjm_ros.core.model import PointRef
    from vjm_ros.core.readers import forward_kinematics as kernel_kinematics
    from vjm_ros.core.readers import point_reader

    rng = np.random.default_rng(13)
    reader = Compiled.reader(model)
    refs = [PointRef(-1, (0.3, -0.2))] + [PointRef(i, tuple(rng.normal(size=2))) for i in range(model.n)]
    points = point_reader(model, refs)
    links = np.array([r.link for r in refs])
    local = np.array([r.local for r in refs])
    for q, qd, _ in [(*model.initial_state(), None)] + _states(rng, model, ExactClosure(), 5):
        ref_kin = forward_kinematics(model, q, qd)
        for kin in (reader.kinematics(q, qd), kernel_kinematics(model, q, qd)):
            for field in ("theta", "origin", "omega", "v_origin", "a_origin", "rotation"):
                _close(getattr(kin, field), getattr(ref_kin, field))
        still = reader.kinematics(q)
        _close(still.origin, ref_kin.origin)
        assert not np.any(still.omega)
        dyn, closure = reader.terms(q, jacobian=False)
        _close(closure.residual, ClosureSet(model).evaluate(ref_kin, jacobian=False).residual)
        assert not np.any(dyn.mass_matrix) and not np.any(closure.jacobian)
        _close(reader.mass_matrix(q), mass_matrix(model, q))
        p, _, a = point_motion(ref_kin, links, local)
        rows = points.terms(q, qd)[1]
        _close(rows.residual.reshape(-1, 2), p)
        _close(rows.bias.reshape(-1, 2), a)
        _close(rows.jacobian.reshape(-1, 2, model.n), point_jacobians(model, ref_kin, links, p))
    assert reader.evaluations == 0


def test_readers_ignore_a_singular_mass_matrix():
    """Geometry is read where ``M`` is singular (the builder names such scenes): no error, and
    ``M`` comes back as it is, singular."""
    model = load_scene("four_bar").model
    links = tuple(replace(lk, mass=0.0, inertia=0.0) for lk in model.links)
    massless = Model.build("massless", model.chains, links, model.joints, model.closures)
    from vjm_ros.core.mechanism import Mechanism as Compiled

    reader = Compiled.reader(massless)
    q, qd = model.initial_state()
    assert not np.any(reader.mass_matrix(q))
    _close(reader.kinematics(q, qd).origin, forward_kinematics(model, q).origin)
    assert reader.closure_jacobian(q).shape == (model.n_rows, model.n)


def test_without_numba_the_kernels_run_as_plain_python():
    """Where numba is missing, 'auto' gives the same compiled-kernel mechanism running as plain
    Python (labelled so in summaries), 'numba' is refused, and the results are the kernels'."""
    script = (
        "import sys, numpy as np\n"
        "sys.modules['numba'] = None\n"  # as if numba were not installed
        "from vjm_ros.jit import deferred as jit\n"
        "assert not jit.HAVE_NUMBA\n"
        "from vjm_ros.core.compiled import make_mechanism\n"
        "from vjm_ros.core.constraints import ExactClosure\n"
        "from vjm_ros.scene.loader import load_scene\n"
        "from oracle.mechanism import Mechanism\n"
        "m = load_scene('four_bar').model\n"
        "mech = make_mechanism(m, ExactClosure(), 'auto')\n"
        "try:\n"
        "    make_mechanism(m, ExactClosure(), 'numba')\n"
        "except ValueError as exc:\n"
        "    assert 'numba' in str(exc)\n"
        "else:\n"
        "    raise AssertionError('numba accepted without numba')\n"
        "q, qd = m.initial_state()\n"
        "x = mech.accelerations(q, qd, np.ones(m.n))\n"
        "y = Mechanism(m, ExactClosure()).accelerations(q, qd, np.ones(m.n))\n"
        "print(mech.kernel, np.max(np.abs(x - y)) / np.max(np.abs(y)))\n"
    )
    here = os.path.dirname(os.path.abspath(__file__))
    path = os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH", "")) if p)
    out = subprocess.run([sys.executable, "-W", "error", "-c", script],
                         env=dict(os.environ, PYTHONPATH=path), capture_output=True, text=True,
                         timeout=300, check=True)
    label, diff = out.stdout.split()
    assert label == "python" and float(diff) <= RTOL
