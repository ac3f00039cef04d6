"""The closed mechanism: open-chain dynamics plus the chosen closure method, in compiled kernels.

:class:`Mechanism` is what the simulator, the integrators, the node, the controllers and the
studies see. Every quantity comes from the scalar chain recursions of :mod:`vjm_ros.core.kernels`
(compiled by numba, or run as plain Python where numba is missing) through its entry points
(:func:`~vjm_ros.core.kernels.evaluate`, :func:`~vjm_ros.core.kernels.project`, ...) on the
packed model (:attr:`Mechanism.packed`) and the instance's workspace
(:class:`~vjm_ros.core.layout.Data`):

* ``accelerations``, ``implicit_penalty_velocity``, ``evaluate``, ``energies`` and ``project``:
  the equations of motion (docs/design.md sections 1-2);
* :meth:`Mechanism.advance_fixed` runs whole control ticks of a fixed-step integrator in one
  compiled call, :meth:`Mechanism.advance_observed` observes every tick as well
  (:mod:`vjm_ros.core.pipeline`);
* :meth:`Mechanism.closure_errors`, :meth:`~Mechanism.closure_jacobian`,
  :meth:`~Mechanism.kinematics`, :meth:`~Mechanism.terms` and :meth:`~Mechanism.mass_matrix`
  read single quantities for the divergence guard, assembly, replay and the controllers.

An independent numpy formulation of the same physics lives in the test suite (``test/oracle/``),
which checks the kernels against it.

>>> from vjm_ros.scene.loader import load_scene
>>> from vjm_ros.core.constraints import PenaltyClosure
>>> import numpy as np
>>> model = load_scene("four_bar").model
>>> mech = Mechanism(model, PenaltyClosure(np.full(2, 1e5), np.full(2, 100.0)))
>>> q, qd = model.initial_state()
>>> mech.accelerations(q, qd, np.zeros(3)).shape
(3,)
"""

from __future__ import annotations

import time

import numpy as np

from vjm_ros.core import kernels as K
from vjm_ros.core import layout, pipeline
from vjm_ros.core.constraints import ClosureRows, ClosureTerms, ExactClosure, PenaltyClosure
from vjm_ros.core.evaluation import DynamicsTerms, Evaluation, as_vector, unpack
from vjm_ros.core.kinematics import Kinematics
from vjm_ros.core.model import Model
from vjm_ros.core.packing import add_loads, closure_layout, pack_method, pack_model
from vjm_ros.jit import tiers


class Mechanism:
    """Open chains closed by penalty forces or multipliers, evaluated by the compiled kernel.

    The closure method is packed for the kernel when it is assigned: assign a new one rather than
    changing its gains in place. An instance keeps a workspace, so use one instance per
    thread (the kernel itself releases the GIL); compiled callers that share its packed model
    (:attr:`packed`) take a workspace of their own (:meth:`new_data`).

    Parameters
    ----------
    model : Model
    method : PenaltyClosure or ExactClosure
    warm_up : bool
        Compile the kernel (or load it from numba's cache) now, so that the first control tick
        does not pay for it. Not where entry points start as plain Python
        (:func:`vjm_ros.jit.tiers.enabled`; the benchmarks and studies compile first): there
        the kernel's first :data:`STEP_PLAIN_CALLS` calls run as plain Python, which a run that
        ticks in the block pipeline (a kernel of its own) never outgrows, and it starts 0.1 s
        sooner without loading the kernel; :meth:`warm_up` loads it when a loop needs it.

    Attributes
    ----------
    model : Model
    closures : ClosureRows
        Row layout of the closures and the per-closure reductions.
    n : int
        Number of coordinates.
    evaluations : int
        Right-hand sides evaluated so far (RK4 counts four per step).
    kernel : str
        ``"numba"``, or ``"python"`` where numba is missing and the kernels run as plain Python
        (for run summaries and log metadata).
    warm_up_time : float
        Seconds the constructor spent compiling or loading the kernel (nan without warm-up).
    """

    kernel = "numba" if K.HAVE_NUMBA else "python"

    def __init__(
        self, model: Model, method: PenaltyClosure | ExactClosure, warm_up: bool = True
    ):
        self._packed = pack_model(model, method)
        self._external_loads: tuple = ()
        n, r = model.n, model.n_rows
        self._layout = closure_layout(model, self._packed.blocks)
        self._data = self.new_data()
        self._shapes = layout.output_shapes(self._packed)
        self._observe_data: tuple | None = None  # observe()'s workspace, made at its first call
        # the compiled copies with the hub solves only where there is a hub layout (they take
        # seconds more to compile)
        hub = self._layout[r, 0] >= 0
        # as plain Python while numba compiles them, on a machine whose cache lacks them
        # (vjm_ros.jit.tiers); the compiled functions themselves once they are in use
        self._step = tiers.entry(K, "step_with_hub" if hub else "step",
                                 plain_calls=STEP_PLAIN_CALLS)
        self._advance_ticks = tiers.entry(
            pipeline, "advance_ticks_with_hub" if hub else "advance_ticks",
            plain_calls=PIPELINE_PLAIN_CALLS)
        self._observe_state = tiers.entry(
            pipeline, "observe_state_with_hub" if hub else "observe_state",
            plain_calls=STEP_PLAIN_CALLS)
        self._tick_state = pipeline.tick_state(n)
        self._rows = r
        self.model = model
        self.n = n
        self.evaluations = 0
        self.method = method
        self.closures = ClosureRows(model)
        self.warm_up_time = (self.warm_up() if warm_up and not tiers.enabled()
                             else float("nan"))

    @classmethod
    def reader(cls, model: Model) -> Mechanism:
        """A mechanism to read kinematics, closure rows and ``M`` with (:meth:`terms`,
        :meth:`kinematics`, :meth:`closure_errors`, ...): zero penalty gains, no warm-up call."""
        zeros = np.zeros(model.n_rows)
        return cls(model, PenaltyClosure(zeros, zeros), warm_up=False)

    # ------------------------------------------------------------------ plumbing
    @property
    def method(self) -> PenaltyClosure | ExactClosure:
        """The closure method (assigning one re-packs it for the kernel)."""
        return self._method

    @method.setter
    def method(self, value: PenaltyClosure | ExactClosure) -> None:
        self._method = value
        gains, par = pack_method(value, self.model)
        if self._external_loads:
            par[layout.P_PLANT] = 1.0
        self._packed = self._packed._replace(gains=gains, par=par)

    @property
    def external_loads(self) -> tuple:
        """Loads applied besides the scene's own (:class:`~vjm_ros.core.model.Load`), e.g. a
        wrench a user sends; assigning a tuple re-packs the links' loads for the kernel."""
        return self._external_loads

    @external_loads.setter
    def external_loads(self, loads: tuple) -> None:
        self._external_loads = tuple(loads)
        lflt = self._packed.lflt.copy()
        lflt[:, layout.F_LOAD_FX : layout.F_LOAD_TZ + 1] = 0.0
        add_loads(lflt, self.model.loads + self._external_loads)
        par = self._packed.par.copy()
        par[layout.P_PLANT] = 1.0 if (self.model.has_plant_terms or self._external_loads) else 0.0
        self._packed = self._packed._replace(lflt=lflt, par=par)

    @property
    def packed(self) -> layout.PackedModel:
        """The model and closure method as the kernels read them (read-only: the mechanism's
        kernels use these very arrays; assign :attr:`method` to change the method)."""
        return self._packed

    def new_data(self, fill: float | None = None) -> layout.Data:
        """A fresh workspace of the kernels for this mechanism (:func:`vjm_ros.core.layout.make_data`),
        e.g. for another thread; ``fill``: the value its output buffers start with (uninitialized
        when None)."""
        data = layout.make_data(self._packed, self._layout)
        if fill is not None:
            for buffer in data[:7]:
                buffer.fill(fill)
        return data

    def _fresh_outputs(self, fill: float | None = None) -> layout.Data:
        """The instance's workspace with fresh output buffers (the scratch arrays shared)."""
        make = np.empty if fill is None else np.zeros
        return layout.Data(*(make(shape) for shape in self._shapes), *self._data[7:])

    def _check(self, status: int) -> None:
        """Settle the tiered kernel (:meth:`_settle_step`); a singular matrix as ``LinAlgError``."""
        if type(self._step) is tiers.Tiered:
            self._settle_step()
        if status:
            raise np.linalg.LinAlgError("Singular matrix")

    def _settle_step(self) -> None:
        """Call the kernel by its compiled function from now on if that is in use: the tiers'
        wrapper costs about 1 µs per call (an eighth of an evaluation of the four-bar)."""
        if self._step.ready:
            self._step = self._step.compiled

    def _settle_ticks(self) -> None:
        """:meth:`_settle_step` for the block pipeline."""
        if self._advance_ticks.ready:
            self._advance_ticks = self._advance_ticks.compiled

    @property
    def entry_points(self) -> tuple:
        """The compiled functions this mechanism calls: ``(step, advance_ticks)`` of
        :mod:`~vjm_ros.core.kernels` and :mod:`~vjm_ros.core.pipeline`, or their hub copies."""
        return tuple(e.dispatcher() if isinstance(e, tiers.Tiered) else e
                     for e in (self._step, self._advance_ticks))

    def warm_up(self) -> float:
        """Compile the kernel, or load it from numba's cache (``evaluations`` unchanged); where
        entry points start as plain Python, have it compiled in the background if the cache
        lacks it.

        Returns
        -------
        float
            Wall time spent, s: the first-call compile time when the cache is cold.
        """
        start = time.perf_counter()
        q, qd = self.model.initial_state()
        if type(self._step) is tiers.Tiered:
            self._step.eager()
        self._check(K.evaluate(self._packed, self._data, q, qd, np.zeros(self.n),
                               np.empty(self.n), self._step))
        return time.perf_counter() - start

    @property
    def tier(self) -> str:
        """How the block pipeline runs: ``"compiled"``, ``"plain"`` (plain Python while numba
        compiles it in the background, :mod:`vjm_ros.jit.tiers`) or ``"new"`` (not called yet)."""
        advance = self._advance_ticks
        return advance.tier if isinstance(advance, tiers.Tiered) else "compiled"

    @property
    def compiling(self) -> bool:
        """Whether an entry point of the kernels runs as plain Python while numba compiles it in
        the background (a first run on a machine, :mod:`vjm_ros.jit.tiers`)."""
        return any(isinstance(e, tiers.Tiered) and e.tier == "plain"
                   for e in (self._step, self._advance_ticks, self._observe_state))

    @property
    def joint_loss(self) -> float:
        """Energy the sticking joint friction and the stops (their impacts included) took over
        the last call of a fixed-step method, J (:mod:`vjm_ros.core.joint_efforts`)."""
        return float(self._data.impulse[self.n])

    @property
    def stop_efforts(self) -> np.ndarray:
        """The effort of each joint's stops over the last step of a fixed-step method, N m or N,
        shape (n,) (:mod:`vjm_ros.core.joint_efforts`; a copy)."""
        return self._data.stop.copy()

    def clear_joint_efforts(self) -> None:
        """Forget the last step's friction and stop efforts (a run starting again)."""
        self._data.impulse[:] = 0.0
        self._data.stop[:] = 0.0

    @property
    def is_penalty(self) -> bool:
        """True when closures are enforced by penalty forces."""
        return isinstance(self._method, PenaltyClosure)

    # ------------------------------------------------------------------ the equations of motion
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
        qdd = np.empty(self.n)
        self._check(K.evaluate(self._packed, self._data, as_vector(q), as_vector(qd), as_vector(tau), qdd,
                               self._step))
        return qdd

    def implicit_penalty_velocity(
        self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, h: float
    ) -> np.ndarray:
        """Velocity after one step that is implicit in the penalty forces.

        Solves ``M (v+ - v) = h (Q + A^T F+)`` with the penalty force linearized at the end of the
        step, ``F+ = -(Kp (C + h A v+) + Kv A v+)``:
        ``(M + h A^T (h Kp + Kv) A) dv = h (Q + A^T (F - h Kp A v))``.
        With exact closures this is the explicit (semi-implicit Euler) velocity update.

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
        v = np.empty(self.n)
        self._check(K.implicit_velocity(self._packed, self._data, as_vector(q), as_vector(qd), as_vector(tau),
                                        float(h), v, self._step))
        return v

    def evaluate(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> Evaluation:
        """Accelerations, closure forces and every derived quantity at one state.

        Parameters
        ----------
        q, qd, tau : ndarray, shape (n,)

        Returns
        -------
        Evaluation
            Fresh arrays, some of them views of one another (nothing is shared with later calls).
        """
        self.evaluations += 1
        data = self._fresh_outputs()
        qdd = np.empty(self.n)
        self._check(K.evaluate(self._packed, data, as_vector(q), as_vector(qd), as_vector(tau), qdd,
                               self._step))
        energy = data.kin[self.n, layout.K_PCOS : layout.K_SLIDE + 1].copy()
        data.kin[self.n, layout.K_PCOS : layout.K_SLIDE + 1] = 0.0
        dyn, closure = unpack(data, self.n)
        return Evaluation(qdd, dyn, closure, data.crow[:, layout.R_FORCE], energy)

    def observe(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, lengths: np.ndarray,
                plink: np.ndarray, plocal: np.ndarray, out: tuple[np.ndarray, ...]) -> None:
        """Every observable at one state into row 0 of ``out``, as a block's ticks are observed
        (:func:`vjm_ros.core.pipeline.observe_state`, one evaluation).

        Parameters
        ----------
        q, qd, tau : ndarray, shape (n,)
        lengths, plink, plocal, out
            As :meth:`advance_observed` takes them; ``out`` needs one row.
        """
        self.evaluations += 1
        if self._observe_data is None:  # output buffers of its own, the scratch arrays shared
            self._observe_data = layout.as_arguments(self._fresh_outputs())
        observe = self._observe_state
        status = observe(as_vector(q), as_vector(qd), as_vector(tau),
                         layout.as_arguments(self._packed), self._observe_data, lengths, plink,
                         plocal, out)
        if type(observe) is tiers.Tiered and observe.ready:
            self._observe_state = observe.compiled
        if status:
            raise np.linalg.LinAlgError("Singular matrix")

    def energies(self, ev: Evaluation, qd: np.ndarray) -> np.ndarray:
        """Kinetic, potential, constraint and total energy, J.

        Read from the kernel's sums in ``ev`` (the kinetic energy is that of the evaluated state;
        ``qd`` is kept for the signature).

        Returns
        -------
        ndarray, shape (4,)
        """
        kinetic, potential, constraint = (float(x) for x in ev.energy)
        return np.array([kinetic, potential, constraint, kinetic + potential + constraint])

    def project(
        self, q: np.ndarray, qd: np.ndarray, tol: float = 1e-12, iterations: int = 8
    ) -> tuple[np.ndarray, np.ndarray]:
        """Move ``q`` onto ``C(q) = 0`` and ``qd`` onto ``A qd = 0`` (mass-weighted least change).

        At most ``iterations`` Gauss-Newton steps in the metric of ``M`` until ``max |C| <= tol``,
        then one velocity projection (minimum-norm, ``rcond = 1e-10``).

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
        q_out, qd_out = np.empty(self.n), np.empty(self.n)
        self._check(K.project(self._packed, self._data, as_vector(q), as_vector(qd), int(iterations),
                              float(tol), q_out, qd_out, self._step))
        return q_out, qd_out

    # ------------------------------------------------------------------ extras
    def closure_jacobian(self, q: np.ndarray) -> np.ndarray:
        """The closure Jacobian ``A(q)``, shape (r, n), from one kernel call (``evaluations``
        unchanged: this is not a right-hand side; a singular mass matrix does not matter)."""
        zero = np.zeros(self.n)
        K.evaluate(self._packed, self._data, as_vector(q), zero, zero, np.empty(self.n), self._step)
        if type(self._step) is tiers.Tiered:
            self._settle_step()
        return self._data.jac.copy()

    def closure_errors(self, q: np.ndarray) -> np.ndarray:
        """Size of each closure's residual at ``q`` (what the simulator's divergence guard reads).

        The norm over each closure's rows of ``C(q)``, from one kernel call without dynamics.

        Parameters
        ----------
        q : ndarray, shape (n,)

        Returns
        -------
        ndarray, shape (k,)
            m for hinge and slider, rad for angle closures.
        """
        q = as_vector(q)
        self._check(K.residual(self._packed, self._data, q, self._step))
        res = self._data.crow[:, layout.R_RES].copy()
        return self.closures.errors(ClosureTerms(res, res, res, res, res, res))

    def kinematics(self, q: np.ndarray, qd: np.ndarray | None = None) -> Kinematics:
        """Link frames (and rates, with ``qd``) at ``q`` from one kernel call (``evaluations``
        unchanged; a singular mass matrix does not matter here).

        Parameters
        ----------
        q : ndarray, shape (n,)
        qd : ndarray, shape (n,), optional
            Rates; zero when omitted.

        Returns
        -------
        Kinematics
            Fresh arrays.
        """
        return self.terms(q, qd, jacobian=qd is not None)[0].kin

    def terms(
        self, q: np.ndarray, qd: np.ndarray | None = None, jacobian: bool = True
    ) -> tuple[DynamicsTerms, ClosureTerms]:
        """Kinematics, ``M``, ``b`` and closure rows at a state from one kernel call.

        ``evaluations`` is unchanged and a singular mass matrix raises nothing (no solve is
        used). With ``jacobian`` False the kernel skips the dynamics and the Jacobian: ``M``,
        ``b``, ``A``, ``Adot qd``, the mass centres and every rate are then zero.

        Parameters
        ----------
        q : ndarray, shape (n,)
        qd : ndarray, shape (n,), optional
            Rates; zero when omitted.
        jacobian : bool

        Returns
        -------
        dyn : DynamicsTerms
        closure : ClosureTerms
            Fresh arrays.
        """
        q = as_vector(q)
        qd = np.zeros(self.n) if qd is None else as_vector(qd)
        data = self._fresh_outputs(fill=0.0)
        if jacobian:
            K.evaluate(self._packed, data, q, qd, np.zeros(self.n), np.empty(self.n), self._step)
        else:
            K.residual(self._packed, data, q, self._step)
        if type(self._step) is tiers.Tiered:
            self._settle_step()
        data.kin[self.n, layout.K_PCOS : layout.K_SLIDE + 1] = 0.0  # the energies' slots
        return unpack(data, self.n)

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Joint-space inertia matrix ``M(q)``, shape (n, n) (kg, kg m, kg m^2)."""
        return self.terms(q)[0].mass_matrix

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
        q_out, qd_out = np.empty(self.n), np.empty(self.n)
        self._check(K.advance(self._packed, self._data, int(method), as_vector(q), as_vector(qd), as_vector(tau),
                              float(h), int(steps), q_out, qd_out, self._step))
        return q_out, qd_out

    def warm_up_pipeline(self) -> float:
        """Compile the block pipeline (:mod:`vjm_ros.core.pipeline`), or load it from numba's
        cache, with a call of zero ticks. Returns the wall time spent, s."""
        start = time.perf_counter()
        if type(self._advance_ticks) is tiers.Tiered:
            self._advance_ticks.eager()
        model = self.model
        q, qd = model.initial_state()
        links = np.array([p.ref.link for p in model.points], dtype=np.int64)
        no_ticks = pipeline.new_outputs(0, model)
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
        advance = self._advance_ticks
        rows = len(out[0])
        stages = 4 if method == K.RK4 else 1
        done, code = 0, pipeline.OK
        while True:
            # as plain Python (tiers), a few ticks per call: the compiled code takes over as soon
            # as it is there; each call's first tick evaluates its start state itself
            # a compiled function has no tiers; with the tiers off the call loads it at once
            ready = not isinstance(advance, tiers.Tiered) or advance.ready or not tiers.enabled()
            part = rows - done if ready else min(PLAIN_PART_TICKS, rows - done)
            part_out = out if part == rows else tuple(a[done : done + part] for a in out)
            ran, code = advance(
                int(method), as_vector(q), as_vector(qd), as_vector(tau), float(h), int(substeps), part,
                bool(project), float(limit), layout.as_arguments(self._packed),
                layout.as_arguments(self._data), lengths, plink, plocal,
                part_out, self._tick_state,
            )
            reused = max(ran - 1, 0)  # each tick after a call's first starts from the sample before
            self.evaluations += ran * (stages * int(substeps) + 1) - reused
            done += int(ran)
            if code or done >= rows:
                if type(advance) is tiers.Tiered:
                    self._settle_ticks()
                return done, int(code)
            q, qd = out[0][done - 1], out[1][done - 1]


STEP_PLAIN_CALLS = 64
"""Calls of the kernel (:func:`vjm_ros.core.kernels.step`) that run as plain Python before it is
loaded from numba's cache (:class:`vjm_ros.jit.tiers.Tiered`): one evaluation of the thesis
scenes takes 0.2-0.5 ms as plain Python, the load 70-120 ms on a slow machine, and 0.3-0.4 s
where it is the first compiled function a process needs (numba imported with it,
:func:`vjm_ros.jit.deferred.activate`). ``vjm run`` makes 8-11 such calls besides its block pipeline
(the scene's inertia check, its assembly, the mobility check, the first sample); ``vjm scenes``
41 for the eight built-in scenes."""


PIPELINE_PLAIN_CALLS = 1
"""Calls of the block pipeline (:func:`vjm_ros.core.pipeline.advance_ticks`) that run as plain
Python, :data:`PLAIN_PART_TICKS` ticks at most each, before it is loaded from numba's cache
(:class:`vjm_ros.jit.tiers.Tiered`), where entry points start as plain Python: a run's first
ticks then come before numba is imported at all (0.3-0.4 s with the loading of the pipeline,
against 10-20 ms for the plain ticks), and a run of that many ticks never imports it.
:meth:`Mechanism.warm_up_pipeline` loads it at once."""


PLAIN_PART_TICKS = 20
"""Ticks per call of the block pipeline while it runs as plain Python (:mod:`vjm_ros.jit.tiers`):
a few tens of ms of the thesis scenes, after which the compiled code is taken if it is there."""


_FIXED_METHODS = (K.EXPLICIT_EULER, K.SEMI_IMPLICIT_EULER, K.RK4, K.IMPLICIT_EULER)
