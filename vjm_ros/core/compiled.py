"""Compiled hot path: :class:`FastMechanism`, the same physics as :class:`~vjm_ros.core.mechanism.Mechanism`.

:class:`~vjm_ros.core.mechanism.Mechanism` assembles the equations of motion from small numpy operations
(about 40 array calls per evaluation on arrays of 1 to 9 elements), so one ``accelerations`` call
costs ~100 us, nearly all of it call overhead. :class:`FastMechanism` computes the same quantities
with the scalar chain recursions of :mod:`vjm_ros.core.kernels`, compiled by numba (one entry point,
compiled on first use and then loaded from numba's on-disk cache):

* ``accelerations``, ``implicit_penalty_velocity``, ``evaluate``, ``energies`` and ``project`` keep
  the signatures and results of :class:`~vjm_ros.core.mechanism.Mechanism` (to round-off: the sums are
  taken in another order, ``M`` is factored by LU with partial pivoting and ``A M^-1 A^T`` is
  diagonalized by Jacobi rotations instead of LAPACK's ``dgesv`` and ``dsyevd``);
* :meth:`FastMechanism.advance_fixed` runs whole control ticks of a fixed-step integrator in one
  compiled call, and :func:`fuse_integrator` gives the registry's fixed-step integrators an
  ``advance`` that uses it;
* :meth:`FastMechanism.closure_errors` gives the closure residual norms at ``q`` (the simulator's
  divergence guard) without building an evaluation.

Choose the implementation with :func:`make_mechanism` (``kernel="auto"``: compiled when numba is
installed, else the numpy reference). Without numba, :class:`FastMechanism` still works but runs
the kernel as plain Python (no faster than the reference).

>>> from vjm_ros.scene.loader import load_scene
>>> from vjm_ros.core.constraints import PenaltyClosure
>>> import numpy as np
>>> model = load_scene("four_bar").model
>>> mech = FastMechanism(model, PenaltyClosure(np.full(2, 1e5), np.full(2, 100.0)))
>>> q, qd = model.initial_state()
>>> mech.accelerations(q, qd, np.zeros(3)).shape
(3,)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from vjm_ros.core import kernels as K
from vjm_ros.core import pipeline
from vjm_ros.core.constraints import ClosureSet, ClosureTerms, ExactClosure, PenaltyClosure
from vjm_ros.core.dynamics import DynamicsTerms
from vjm_ros.core.integrators import Integrator
from vjm_ros.core.integrators.fixed import (
    RK4,
    ExplicitEuler,
    ImplicitPenaltyEuler,
    SemiImplicitEuler,
)
from vjm_ros.core.kinematics import Kinematics
from vjm_ros.core.mechanism import Evaluation, Mechanism
from vjm_ros.core.model import Model
from vjm_ros.core.packing import chain_blocks, pack_method, pack_model

KERNELS = ("auto", "numba")
"""Accepted values of the ``kernel`` choice: the compiled kernels (machine code with numba, plain
Python without), or the same with numba required."""

HAVE_NUMBA = K.HAVE_NUMBA
"""True when numba is importable (the compiled kernels are then machine code)."""

def _vec(x) -> np.ndarray:
    """A C-contiguous float64 vector (no copy when ``x`` already is one)."""
    return np.ascontiguousarray(x, dtype=np.float64)


class FastClosureSet(ClosureSet):
    """:class:`~vjm_ros.core.constraints.ClosureSet` with one-call per-closure reductions.

    ``errors`` and ``closure_forces`` add the rows of each closure in order with
    ``np.add.reduceat``, as ``np.add.at`` does, so the results are identical.
    """

    def __init__(self, model: Model):
        super().__init__(model)
        self._starts = np.array([sl.start for sl in self.row_slices()], dtype=np.intp)

    def errors(self, terms: ClosureTerms) -> np.ndarray:
        """Size of each closure's residual (norm over its rows).

        Returns
        -------
        ndarray, shape (k,)
            m for hinge and slider, rad for angle.
        """
        if not len(self._starts):
            return np.zeros(0)
        return np.sqrt(np.add.reduceat(terms.residual**2, self._starts))

    def closure_forces(self, terms: ClosureTerms, row_force: np.ndarray) -> np.ndarray:
        """As :meth:`ClosureSet.closure_forces`, with one reduction instead of a loop."""
        if not len(self._starts):
            return np.zeros((0, 3))
        return np.add.reduceat(terms.row_direction * row_force[:, None], self._starts, axis=0)


@dataclass
class FastEvaluation(Evaluation):
    """:class:`~vjm_ros.core.mechanism.Evaluation` plus the energies summed by the kernel.

    Attributes
    ----------
    energy : ndarray, shape (3,)
        Kinetic, gravitational and penalty-spring energy (0 for exact closures), J.
    """

    energy: np.ndarray = field(default_factory=lambda: np.zeros(3))


class FastMechanism(Mechanism):
    """:class:`~vjm_ros.core.mechanism.Mechanism` with a compiled kernel.

    Same constructor, attributes (``model``, ``method``, ``closures``, ``n``, ``evaluations``) and
    results (to round-off) as the reference. The closure method is packed for the kernel when it
    is assigned: assign a new one rather than changing its gains in place. An instance keeps
    scratch buffers, so use one instance per thread (the kernel itself releases the GIL).

    Parameters
    ----------
    model : Model
    method : PenaltyClosure or ExactClosure
    warm_up : bool
        Compile the kernel (or load it from numba's cache) now, so that the first control tick
        does not pay for it.

    Attributes
    ----------
    kernel : str
        ``"numba"`` (for run summaries; the reference has no such attribute).
    warm_up_time : float
        Seconds the constructor spent compiling or loading the kernel (nan without warm-up).
    """

    kernel = "numba"

    def __init__(
        self, model: Model, method: PenaltyClosure | ExactClosure, warm_up: bool = True
    ):
        self._lint, self._lflt, self._cint, self._cflt = pack_model(model)
        n, r, k = model.n, model.n_rows, len(model.closures)
        self._shapes = ((n + 1, K.N_KIN), (n, n), (n,), (n, K.N_CM), (r, K.N_CROW), (r, n), (k, 2))
        self._buffers = self._new_buffers()
        self._work = K.workspace(n, r, chain_blocks(model))
        self._tick_state = pipeline.tick_state(n)
        self._rows = r
        super().__init__(model, method)
        self.closures = FastClosureSet(model)
        self.warm_up_time = self.warm_up() if warm_up else float("nan")

    # ------------------------------------------------------------------ plumbing
    @property
    def method(self) -> PenaltyClosure | ExactClosure:
        """The closure method (assigning one re-packs it for the kernel)."""
        return self._method

    @method.setter
    def method(self, value: PenaltyClosure | ExactClosure) -> None:
        self._method = value
        self._gains, self._par = pack_method(value, self.model)
        self._packed = (self._lint, self._lflt, self._cint, self._cflt, self._gains, self._par)

    def _new_buffers(self) -> tuple[np.ndarray, ...]:
        """Fresh output buffers ``kin, mm, bias, cm, crow, jac, points`` (see :mod:`._kernels`)."""
        return tuple(np.empty(shape) for shape in self._shapes)

    def _run(
        self,
        op: int,
        q: np.ndarray,
        qd: np.ndarray,
        tau: np.ndarray,
        h: float = 0.0,
        steps: int = 1,
        tol: float = 0.0,
        buffers: tuple[np.ndarray, ...] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Call :func:`vjm_ros.core.kernels.step` and turn a singular matrix into ``LinAlgError``.

        ``buffers`` receive the terms of the last evaluation (the instance's scratch buffers when
        omitted). Returns the kernel's two output vectors, fresh arrays of shape (n,).
        """
        out_a = np.empty(self.n)
        out_b = np.empty(self.n)
        status = K.step(
            op, q, qd, tau, h, steps, tol, self._lint, self._lflt, self._cint, self._cflt,
            self._gains, self._par, *(self._buffers if buffers is None else buffers), out_a, out_b,
            self._work, K.NO_KNOWN, -1,
        )
        if status:
            raise np.linalg.LinAlgError("Singular matrix")
        return out_a, out_b

    def warm_up(self) -> float:
        """Compile the kernel, or load it from numba's cache (``evaluations`` unchanged).

        Returns
        -------
        float
            Wall time spent, s: the first-call compile time when the cache is cold.
        """
        start = time.perf_counter()
        q, qd = self.model.initial_state()
        self._run(K.EVALUATE, q, qd, np.zeros(self.n))
        return time.perf_counter() - start

    # ------------------------------------------------------------------ Mechanism interface
    def accelerations(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """``qdd`` of the closed mechanism.

        Parameters
        ----------
        q, qd : ndarray, shape (n,)
            Coordinates (rad or m) and rates (rad/s or m/s).
        tau : ndarray, shape (n,)
            Generalized efforts, N m or N.

        Returns
        -------
        ndarray, shape (n,)
            rad/s^2 or m/s^2.

        Raises
        ------
        numpy.linalg.LinAlgError
            When the mass matrix is exactly singular (as ``numpy.linalg.solve``).
        """
        self.evaluations += 1
        return self._run(K.EVALUATE, _vec(q), _vec(qd), _vec(tau))[0]

    def implicit_penalty_velocity(
        self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, h: float
    ) -> np.ndarray:
        """Velocity after one step that is implicit in the penalty forces.

        See :meth:`vjm_ros.core.mechanism.Mechanism.implicit_penalty_velocity`.

        Parameters
        ----------
        q, qd, tau : ndarray, shape (n,)
        h : float
            Step, s.

        Returns
        -------
        ndarray, shape (n,)
            rad/s or m/s.
        """
        self.evaluations += 1
        return self._run(K.IMPLICIT_VELOCITY, _vec(q), _vec(qd), _vec(tau), float(h))[0]

    def evaluate(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> FastEvaluation:
        """Accelerations and every derived quantity (see :meth:`Mechanism.evaluate`).

        Parameters
        ----------
        q, qd, tau : ndarray, shape (n,)

        Returns
        -------
        FastEvaluation
            Fresh arrays, some of them views of one another (nothing is shared with later calls).
        """
        self.evaluations += 1
        buffers = self._new_buffers()
        qdd, _ = self._run(K.EVALUATE, _vec(q), _vec(qd), _vec(tau), buffers=buffers)
        kin, mm, bias, cm, crow, jac, points = buffers
        n = self.n
        rotation = np.empty((n + 1, 2, 2))
        rotation[:, 0, 0] = kin[:, K.K_COS]
        rotation[:, 1, 0] = kin[:, K.K_SIN]
        rotation[:, 0, 1] = -kin[:, K.K_SIN]
        rotation[:, 1, 1] = kin[:, K.K_COS]
        n_pred = np.empty((n, 2))
        n_pred[:, 0] = -kin[:n, K.K_PSIN]
        n_pred[:, 1] = kin[:n, K.K_PCOS]
        energy = kin[n, K.K_PCOS : K.K_SLIDE + 1].copy()
        kin[n, K.K_PCOS : K.K_SLIDE + 1] = 0.0
        kinematics = Kinematics(
            theta=kin[:, K.K_THETA],
            origin=kin[:, K.K_OX : K.K_OY + 1],
            omega=kin[:, K.K_OMEGA],
            v_origin=kin[:, K.K_VX : K.K_VY + 1],
            a_origin=kin[:, K.K_AX : K.K_AY + 1],
            n_pred=n_pred,
            rotation=rotation,
            slide=kin[:n, K.K_SLIDE],
        )
        dyn = DynamicsTerms(
            kinematics, mm, bias, cm[:, K.C_X : K.C_Y + 1], cm[:, K.C_VX : K.C_VY + 1]
        )
        closure = ClosureTerms(
            residual=crow[:, K.R_RES],
            rate=crow[:, K.R_RATE],
            jacobian=jac,
            bias=crow[:, K.R_BIAS],
            row_direction=crow[:, K.R_DX : K.R_DZ + 1],
            points=points,
        )
        return FastEvaluation(qdd, dyn, closure, crow[:, K.R_FORCE], energy)

    def energies(self, ev: Evaluation, qd: np.ndarray) -> np.ndarray:
        """Kinetic, potential, constraint and total energy, J.

        Read from the kernel's sums for a :class:`FastEvaluation` (as the reference, the kinetic
        energy is that of the evaluated state), else computed by the reference.

        Returns
        -------
        ndarray, shape (4,)
        """
        if not isinstance(ev, FastEvaluation):
            return super().energies(ev, qd)
        kinetic, potential, constraint = (float(x) for x in ev.energy)
        return np.array([kinetic, potential, constraint, kinetic + potential + constraint])

    def project(
        self, q: np.ndarray, qd: np.ndarray, tol: float = 1e-12, iterations: int = 8
    ) -> tuple[np.ndarray, np.ndarray]:
        """Move ``q`` onto ``C(q) = 0`` and ``qd`` onto ``A qd = 0`` (mass-weighted least change).

        See :meth:`vjm_ros.core.mechanism.Mechanism.project`.

        Parameters
        ----------
        q, qd : ndarray, shape (n,)
        tol : float
            Largest accepted ``|C|``, m or rad.
        iterations : int
            Most Gauss-Newton steps.

        Returns
        -------
        q, qd : ndarray, shape (n,)
        """
        if self._rows == 0:
            return q, qd
        zero = np.zeros(self.n)
        return self._run(
            K.PROJECT, _vec(q), _vec(qd), zero, steps=int(iterations), tol=float(tol)
        )

    # ------------------------------------------------------------------ extras
    def closure_jacobian(self, q: np.ndarray) -> np.ndarray:
        """The closure Jacobian ``A(q)``, shape (r, n), from one kernel call (``evaluations``
        unchanged: this is not a right-hand side)."""
        zero = np.zeros(self.n)
        self._run(K.EVALUATE, _vec(q), zero, zero)
        return self._buffers[5].copy()

    def closure_errors(self, q: np.ndarray) -> np.ndarray:
        """Size of each closure's residual at ``q`` (what the simulator's divergence guard reads).

        Equals ``closures.errors(closures.evaluate(forward_kinematics(model, q), False))``.

        Parameters
        ----------
        q : ndarray, shape (n,)

        Returns
        -------
        ndarray, shape (k,)
            m for hinge and slider, rad for angle closures.
        """
        q = _vec(q)
        self._run(K.RESIDUAL, q, q, q)
        res = self._buffers[4][:, K.R_RES].copy()
        return self.closures.errors(ClosureTerms(res, res, res, res, res, res))

    def advance_fixed(
        self, method: int, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, h: float, steps: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """``steps`` fixed steps of one integrator in one compiled call, efforts held.

        Parameters
        ----------
        method : int
            ``_kernels.EXPLICIT_EULER``, ``SEMI_IMPLICIT_EULER``, ``RK4`` or ``IMPLICIT_EULER``.
        q, qd : ndarray, shape (n,)
            State at the start, rad or m and rad/s or m/s.
        tau : ndarray, shape (n,)
            Efforts, N m or N.
        h : float
            Step, s.
        steps : int

        Returns
        -------
        q, qd : ndarray, shape (n,)
            State after the steps.
        """
        if method not in _FIXED_METHODS:
            raise ValueError(f"method: expected one of {_FIXED_METHODS}, found {method!r}")
        stages = 4 if method == K.RK4 else 1
        self.evaluations += stages * int(steps)
        return self._run(int(method), _vec(q), _vec(qd), _vec(tau), float(h), int(steps))


    def warm_up_pipeline(self) -> float:
        """Compile the block pipeline (:mod:`vjm_ros.core.pipeline`), or load it from numba's
        cache, with a call of zero ticks. Returns the wall time spent, s."""
        start = time.perf_counter()
        model = self.model
        q, qd = model.initial_state()
        links = np.array([p.ref.link for p in model.points], dtype=np.int64)
        no_ticks = pipeline.new_outputs(0, self.n, len(model.points), len(model.closures))
        self.advance_observed(K.RK4, q, qd, np.zeros(self.n), 1e-3, 1, False, np.inf,
                              np.asarray(model.length, dtype=float), links,
                              np.zeros((len(model.points), 2)), no_ticks)
        return time.perf_counter() - start

    def advance_observed(
        self, method: int, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, h: float,
        substeps: int, project: bool, limit: float, lengths: np.ndarray, plink: np.ndarray,
        plocal: np.ndarray, out: tuple[np.ndarray, ...],
    ) -> tuple[int, int]:
        """Control ticks in one compiled call, each observed (:func:`vjm_ros.core.pipeline.advance_ticks`).

        As many ticks run as ``out`` has rows. ``evaluations`` counts the steps' stages and one
        evaluation per sample, less the RK4 first stages taken from the sample before.

        Returns
        -------
        done, code : int
            Ticks that ran, and :data:`vjm_ros.core.pipeline.OK` or why tick ``done`` failed.
        """
        if method not in _FIXED_METHODS:
            raise ValueError(f"method: expected one of {_FIXED_METHODS}, found {method!r}")
        done, code = pipeline.advance_ticks(
            int(method), _vec(q), _vec(qd), _vec(tau), float(h), int(substeps), len(out[0]),
            bool(project), float(limit), self._packed, self._buffers, lengths, plink, plocal, out,
            self._work, self._tick_state,
        )
        stages = 4 if method == K.RK4 else 1
        reused = max(done - 1, 0) if method == K.RK4 else 0  # first stages taken from samples
        self.evaluations += done * (stages * int(substeps) + 1) - reused
        return int(done), int(code)


_FIXED_METHODS = (K.EXPLICIT_EULER, K.SEMI_IMPLICIT_EULER, K.RK4, K.IMPLICIT_EULER)


# ---------------------------------------------------------------------------------- integrators
class _Fused:
    """Mixin: ``advance`` in one compiled call when the system is a :class:`FastMechanism`."""

    kernel_method: int = -1

    def advance(self, system, t, q, qd, tau, dt, substeps=1):
        if isinstance(system, FastMechanism):
            return system.advance_fixed(self.kernel_method, q, qd, tau, dt / substeps, substeps)
        return super().advance(system, t, q, qd, tau, dt, substeps)


class FusedExplicitEuler(_Fused, ExplicitEuler):
    """:class:`~vjm_ros.core.integrators.fixed.ExplicitEuler` with compiled ticks."""

    kernel_method = K.EXPLICIT_EULER


class FusedSemiImplicitEuler(_Fused, SemiImplicitEuler):
    """:class:`~vjm_ros.core.integrators.fixed.SemiImplicitEuler` with compiled ticks."""

    kernel_method = K.SEMI_IMPLICIT_EULER


class FusedRK4(_Fused, RK4):
    """:class:`~vjm_ros.core.integrators.fixed.RK4` with compiled ticks."""

    kernel_method = K.RK4


class FusedImplicitPenaltyEuler(_Fused, ImplicitPenaltyEuler):
    """:class:`~vjm_ros.core.integrators.fixed.ImplicitPenaltyEuler` with compiled ticks."""

    kernel_method = K.IMPLICIT_EULER


_FUSED: dict[type, type] = {
    ExplicitEuler: FusedExplicitEuler,
    SemiImplicitEuler: FusedSemiImplicitEuler,
    RK4: FusedRK4,
    ImplicitPenaltyEuler: FusedImplicitPenaltyEuler,
}


def fuse_integrator(integrator: Integrator, mechanism: Mechanism) -> Integrator:
    """The integrator with compiled ticks when both it and the mechanism allow it.

    Parameters
    ----------
    integrator : Integrator
        From :func:`vjm_ros.core.integrators.make_integrator`.
    mechanism : Mechanism
        The system it will advance.

    Returns
    -------
    Integrator
        A fused subclass instance (same ``name``, ``order``, ``step`` and stability bound) for the
        four fixed-step methods on a :class:`FastMechanism`; ``integrator`` itself otherwise.
    """
    fused = _FUSED.get(type(integrator))
    if fused is None or not isinstance(mechanism, FastMechanism):
        return integrator
    return fused()


def make_mechanism(
    model: Model, method: PenaltyClosure | ExactClosure, kernel: str = "auto"
) -> Mechanism:
    """The mechanism implementation for a kernel choice.

    Parameters
    ----------
    model : Model
    method : PenaltyClosure or ExactClosure
    kernel : str
        ``"auto"`` (the compiled kernels; plain Python where numba is missing) or ``"numba"``
        (an error without numba).

    Returns
    -------
    FastMechanism

    Raises
    ------
    ValueError
        For an unknown ``kernel`` (the former ``"numpy"`` included), or ``"numba"`` without
        numba installed.
    """
    if kernel == "numpy":
        raise ValueError("kernel: 'numpy' is no longer a choice (the physics runs only in the "
                         "compiled kernels, as plain Python where numba is missing); use 'auto' "
                         "or 'numba'")
    if kernel not in KERNELS:
        raise ValueError(f"kernel: expected one of {', '.join(KERNELS)}, found {kernel!r}")
    if kernel == "numba" and not HAVE_NUMBA:
        raise ValueError("kernel: 'numba' needs the numba package (pip install 'numba>=0.64')")
    return FastMechanism(model, method)
