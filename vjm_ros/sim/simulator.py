"""The simulation loop without ROS: control ticks, closure settings, sampling, divergence guard.

A control tick of length ``dt = 1 / rate`` holds the efforts constant and advances the physics by
``substeps`` fixed steps (or one adaptive solve) to ``t + dt`` (docs/design.md section 3).
"""

from __future__ import annotations

import numpy as np

from vjm_ros.core.constraints import ExactClosure, PenaltyClosure
from vjm_ros.core.errors import ConfigurationError, DivergenceError
from vjm_ros.core.integrators import INTEGRATORS, AdaptiveIntegrator, make_integrator
from vjm_ros.core.model import Load, Model
from vjm_ros.core.pipeline import new_outputs
from vjm_ros.scene.plant import Plant
from vjm_ros.sim.actuators import Actuation
from vjm_ros.sim.history import StateHistory
from vjm_ros.sim.samples import Sample, SampleBlock
from vjm_ros.sim.sensors import SensorModel
from vjm_ros.sim.settings import SimulationSettings
from vjm_ros.sim.stiffness import (
    check_stiffness,
    closure_method,
    closure_modes,
    mobility_at,
)

HISTORY_STATES = 32
"""States kept before the latest ticks, judged when a run diverges (:meth:`Simulator._likely_cause`)."""


class Simulator:
    """Fixed-rate simulation of one scene.

    Parameters
    ----------
    model : Model
    settings : SimulationSettings
    scene_gains : dict, optional
        Gains from the scene file (``kp``, ``kv``, ``omega_n``, ``zeta``, ``alpha``, ``beta``,
        per-closure overrides under ``per_closure``); settings take precedence.
    plant : Plant, optional
        The scene's actuator dynamics and sensors (:attr:`Scene.plant
        <vjm_ros.scene.builder.Scene.plant>`); none by default.

    Raises
    ------
    ConfigurationError
        A setting cannot be used, or a delay of the plant is not a whole number of ticks.
    """

    def __init__(
        self,
        model: Model,
        settings: SimulationSettings | None = None,
        scene_gains: dict | None = None,
        plant: Plant | None = None,
    ):
        self.model = model
        self.settings = (settings or SimulationSettings()).validated()
        self.scene_gains = dict(scene_gains or {})
        self.dt = 1.0 / self.settings.rate
        self.h = self.dt / self.settings.substeps
        self.plant = plant or Plant()
        self.actuation = Actuation(model, self.plant.actuators, self.dt, self.plant.source)
        """Commands to applied efforts (:mod:`vjm_ros.sim.actuators`)."""
        self.sensors = (None if self.plant.sensors is None
                        else SensorModel(self.plant.sensors, self.dt, self.plant.source))
        """The joint sensors (:mod:`vjm_ros.sim.sensors`), or None."""
        self.measured: np.ndarray | None = None
        """The latest measurement, shape (3, n): position, velocity, effort (None without
        sensors)."""
        self.integrator = (
            make_integrator(
                self.settings.integrator, rtol=self.settings.rtol, atol=self.settings.atol
            )
            if self._adaptive()
            else make_integrator(self.settings.integrator)
        )
        if self._adaptive() and model.has_joint_efforts:
            raise ConfigurationError(
                f"integrator: expected a fixed-step method for {model.name}, whose sticking "
                f"friction and stops act once per step (explicit_euler, semi_implicit_euler, "
                f"rk4, implicit_euler; smooth friction works with any), found "
                f"{self.settings.integrator!r}")
        self.q0, self.qd0 = model.initial_state()
        self.selection = self.actuation.selection  # joint effort per unit of command
        self.limits = np.array([a.limit for a in model.actuators], dtype=float)
        self._closure_rows = model.n_rows
        self._mobility: np.ndarray | None = None  # G at the initial state, when first asked
        self._pipeline_ready = False
        self._point_links = np.array([p.ref.link for p in model.points], dtype=int)
        self._point_local = np.array([p.ref.local for p in model.points], dtype=float).reshape(-1, 2)
        self._observed = new_outputs(1, model)  # sample()'s row of observables
        self.method = closure_method(model, self.settings, self.scene_gains,
                                     self._initial_mobility)
        from vjm_ros.core.compiled import make_mechanism  # numba is imported only here

        self.mechanism = make_mechanism(model, self.method, self.settings.kernel)
        self.stiffness_report, radius = [], None
        if isinstance(self.method, PenaltyClosure) and model.n_rows:
            self.stiffness_report, radius = closure_modes(
                model, self.method, self.integrator, self.h, self._initial_mobility()
            )
        if self.settings.check_stiffness:
            check_stiffness(self.stiffness_report, radius, model, self.settings.integrator,
                            self.h, self.settings.substeps)
        self.divergence_limit = self.settings.divergence_limit
        if self.divergence_limit is None:
            scale = max(float(np.max(model.length, initial=0.0)), 0.1)
            # A quarter of the longest link: the closure has come apart, not merely sagged.
            self.divergence_limit = 0.25 * scale
        self.reset()

    # ------------------------------------------------------------------ set-up
    def _adaptive(self) -> bool:
        return issubclass(INTEGRATORS[self.settings.integrator], AdaptiveIntegrator)

    def _initial_mobility(self) -> np.ndarray:
        """``G = A M^-1 A^T`` at the initial state, shape (r, r) (computed once)."""
        if self._mobility is None:
            self._mobility = mobility_at(self.model, self.q0, self.qd0)
        return self._mobility

    def _closure_modes_at(self, q: np.ndarray, qd: np.ndarray) -> list[dict]:
        """:func:`~vjm_ros.sim.stiffness.closure_modes` of the run's gains at a state."""
        mobility = mobility_at(self.model, q, qd)
        return closure_modes(self.model, self.method, self.integrator, self.h, mobility)[0]

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Back to the scene's initial state (t = 0, zero efforts)."""
        self.t = 0.0
        self.ticks = 0
        self._history = StateHistory(HISTORY_STATES)
        self.q = self.q0.copy()
        self.qd = self.qd0.copy()
        self.efforts = np.zeros(len(self.model.actuators))
        self.tau = np.zeros(self.model.n)
        self.actuation.reset()
        self.integrator.reset()
        self.mechanism.clear_joint_efforts()
        if self.sensors is not None:
            self.measured = self.sensors.reset(self._exact_state())

    def _exact_state(self) -> np.ndarray:
        """Position, velocity and applied effort now, shape (3, n)."""
        exact = np.empty((3, self.model.n))
        exact[0], exact[1], exact[2] = self.q, self.qd, self.tau
        return exact

    def set_efforts(self, efforts: np.ndarray) -> np.ndarray:
        """Hold actuator commands for the following ticks, clamped to the scene's limits.

        Without actuator dynamics the joints receive ``gear * command`` from the next tick on
        (:attr:`tau` at once); with a lag or a delay :attr:`tau` follows tick by tick
        (:mod:`vjm_ros.sim.actuators`).

        Parameters
        ----------
        efforts : array_like, shape (n_actuators,)
            Commands, N m or N before the gear, in the scene's actuator order.

        Returns
        -------
        ndarray, shape (n_actuators,)
            The commands as held (after clamping).
        """
        e = np.asarray(efforts, dtype=float).reshape(-1)
        if e.shape != (len(self.model.actuators),):
            raise ConfigurationError(
                f"efforts: expected {len(self.model.actuators)} values (actuators "
                f"{self.model.actuator_names}), found {e.size}"
            )
        if not np.all(np.isfinite(e)):
            raise ConfigurationError(f"efforts: expected finite values, found {e.tolist()}")
        e = np.clip(e, -self.limits, self.limits)
        self.efforts = e
        if not self.actuation.dynamic:
            self.tau = self.selection @ e
        return e

    def set_external_loads(self, loads: tuple[Load, ...]) -> None:
        """Loads applied from the next tick on besides the scene's own (a user's wrench at a
        named point; :class:`~vjm_ros.core.model.Load`); ``()`` removes them."""
        self.mechanism.external_loads = tuple(loads)

    def advance(self, efforts: np.ndarray | None = None) -> None:
        """One control tick.

        Parameters
        ----------
        efforts : array_like, optional
            New efforts for this tick (held from now on); the previous ones when omitted.

        Raises
        ------
        DivergenceError
            On a non-finite state or a closure residual beyond the limit.
        """
        if efforts is not None:
            self.set_efforts(efforts)
        self._tick_actuators()
        self._step()
        if self.sensors is not None:
            self.measured = self.sensors.measure_one(self._exact_state())

    def _tick_actuators(self) -> None:
        """The efforts of the next tick (:attr:`tau`), when the actuators have dynamics."""
        if self.actuation.dynamic:
            self.tau = self.actuation.tick(self.efforts)

    def _step(self) -> None:
        """One tick with :attr:`tau` held (:meth:`advance` without the actuators' tick)."""
        self._history.append(self.t, self.q, self.qd)
        with np.errstate(all="ignore"):
            try:
                q, qd = self.integrator.advance(
                    self.mechanism,
                    self.t,
                    self.q,
                    self.qd,
                    self.tau,
                    self.dt,
                    self.settings.substeps,
                )
            except (FloatingPointError, np.linalg.LinAlgError) as exc:
                raise DivergenceError(self.t, str(exc), None, self._likely_cause()) from exc
        self.ticks += 1
        self.t = self.ticks * self.dt
        if isinstance(self.method, ExactClosure) and self.method.projection:
            q, qd = self.mechanism.project(q, qd)
            self.integrator.reset()
        self.q, self.qd = q, qd
        self._guard()

    def runs_blocks(self) -> bool:
        """True when :meth:`advance_block` runs in one compiled call (a fixed-step integrator on
        the compiled kernel); loads nothing (the pipeline's first ticks may run as plain Python,
        :mod:`vjm_ros.jit.tiers`)."""
        return self.integrator.fixed_step

    def blocks_compiled(self) -> bool:
        """True when :meth:`advance_block` runs in one compiled call (:meth:`runs_blocks`); loads
        that pipeline now (compiled on first use on a machine, then from numba's cache in a few
        tens of ms), so that a timed run or a realtime loop does not pay for it."""
        if not self.runs_blocks():
            return False
        if not self._pipeline_ready:
            self.mechanism.warm_up_pipeline()
            self._pipeline_ready = True
        return True

    def advance_block(self, block: SampleBlock, ticks: int) -> None:
        """``ticks`` control ticks with the commands held, each sampled into ``block``.

        The same states and samples as ``advance()`` then ``sample()`` per tick; with a compiled
        fixed-step integrator all ticks run in one compiled call
        (:func:`vjm_ros.core.pipeline.advance_ticks`), else tick by tick. With actuator
        dynamics, one call per tick until the actuators have settled (:meth:`_advance_actuated`).

        Parameters
        ----------
        block : SampleBlock
            Receives rows ``0 .. ticks - 1`` (``block.rows`` is set to the rows filled).
        ticks : int
            At most the block's capacity.

        Raises
        ------
        DivergenceError
            As :meth:`advance`; the block then holds the ticks before the failing one.
        """
        block.rows = 0
        try:
            if self.actuation.dynamic:
                self._advance_actuated(block, ticks)
                return
            block.effort = self.tau.copy()
            if ticks == 0 or not self.runs_blocks():
                self._advance_tick_by_tick(block, 0, ticks)
                return
            if self._advance_rows(block, 0, ticks):
                # The failing tick again, tick by tick: it raises with the full diagnosis.
                self._advance_tick_by_tick(block, block.rows, ticks)
        finally:  # also the rows before a divergence
            if self.sensors is not None:
                self._measure_block(block)

    def _measure_block(self, block: SampleBlock) -> None:
        """``block.measured`` of the rows filled (:attr:`sensors`)."""
        rows, n = block.rows, self.model.n
        if block.measured is None or len(block.measured) != len(block.t):
            block.measured = np.zeros((len(block.t), 3, n))
        if rows == 1:  # the node's tick: the scalar path
            exact = np.empty((3, n))
            exact[0], exact[1] = block.q[0], block.qd[0]
            exact[2] = block.effort[0] if block.effort.ndim == 2 else block.effort
            self.measured = self.sensors.measure_one(exact)
            block.measured[0] = self.measured
            return
        if not rows:
            return
        exact = np.empty((rows, 3, n))
        exact[:, 0], exact[:, 1], exact[:, 2] = block.q[:rows], block.qd[:rows], (
            block.effort[:rows] if block.effort.ndim == 2 else block.effort)
        block.measured[:rows] = self.sensors.measure(exact)
        self.measured = block.measured[rows - 1].copy()

    def _advance_rows(self, block: SampleBlock, first: int, ticks: int) -> int:
        """Rows ``first .. first + ticks - 1`` of ``block`` in one compiled call, :attr:`tau`
        held; ``block.rows`` is set to the rows filled. Returns the pipeline's code (non-zero:
        the tick after the rows filled failed)."""
        arrays = (block.arrays if first == 0 and ticks == len(block.t)
                  else tuple(a[first:first + ticks] for a in block.arrays))
        rows = self._closure_rows  # the model's, counted once (a property that sums)
        project = isinstance(self.method, ExactClosure) and self.method.projection and rows > 0
        limit = self.divergence_limit if (rows and self.divergence_limit) else np.inf
        start = self.ticks
        # compiled code raises no floating-point warnings: no np.errstate needed here
        done, code = self.mechanism.advance_observed(
            self.integrator.kernel_method, self.q, self.qd, self.tau, self.h,
            self.settings.substeps, project, limit, self.model.length, self._point_links,
            self._point_local, arrays)
        # the states the ticks started from, for the diagnosis of a divergence (self.q is
        # replaced below, never changed in place)
        last = first + done
        if done == 1:  # the node's tick
            self._history.append(start * self.dt, self.q, self.qd)
            block.t[first] = (start + 1) * self.dt
        else:
            self._history.add_block(start, self.dt, self.q, self.qd, block.q[first:last],
                                    block.qd[first:last])
            block.t[first:last] = (start + 1 + np.arange(done)) * self.dt
        block.rows = last
        if done:
            self.q, self.qd = block.q[last - 1].copy(), block.qd[last - 1].copy()
        self.ticks = start + done
        self.t = self.ticks * self.dt
        return code

    def _advance_actuated(self, block: SampleBlock, ticks: int) -> None:
        """:meth:`advance_block` with actuator dynamics: the applied efforts change tick by tick
        (one compiled call each) until the actuators have settled on the command held, then the
        rest of the block runs in one call. ``block.effort`` gets one row per tick (one row
        held over a block of one tick)."""
        per_row = ticks > 1
        block.effort = np.empty((len(block.t), self.model.n)) if per_row else self.tau.copy()
        compiled = ticks > 0 and self.runs_blocks()
        first = 0
        while first < ticks:
            count, code = 1, 0
            if compiled and self.actuation.settled(self.efforts):
                self.tau, count = self.selection @ self.efforts, ticks - first
            else:
                self.tau = self.actuation.tick(self.efforts)
            if compiled:
                code = self._advance_rows(block, first, count)
            else:
                self._step()
                block.put(first, self.sample())
                block.rows = first + 1
            if code:  # the failing tick again, with its efforts: it raises with the diagnosis
                self._step()
                block.put(block.rows, self.sample())
                block.rows += 1
            if per_row:
                block.effort[first:block.rows] = self.tau
            else:
                block.effort = self.tau.copy()
            first = block.rows

    def _advance_tick_by_tick(self, block: SampleBlock, first: int, ticks: int) -> None:
        """Rows ``first .. ticks - 1`` of ``block``, tick by tick."""
        for i in range(first, ticks):
            self._tick_actuators()
            self._step()
            block.put(i, self.sample())
            block.rows = i + 1

    def _guard(self) -> None:
        if not (np.all(np.isfinite(self.q)) and np.all(np.isfinite(self.qd))):
            raise DivergenceError(
                self.t, "the state is no longer finite", self._worst_closure(), self._likely_cause()
            )
        if self.model.n_rows and self.divergence_limit:
            err = self.mechanism.closure_errors(self.q)
            worst = int(np.argmax(err))
            if err[worst] > self.divergence_limit:
                raise DivergenceError(
                    self.t,
                    f"closure residual {err[worst]:.4g} beyond the limit {self.divergence_limit:.4g}",
                    self.model.closures[worst].name,
                    self._likely_cause(),
                )

    def _worst_closure(self) -> str | None:
        """Closure with the largest residual at the last good state (None without closures)."""
        if not self.model.n_rows or not self._history:
            return None
        _, q, _ = self._history[-1]
        return self.model.closures[int(np.argmax(self.mechanism.closure_errors(q)))].name

    def _likely_cause(self) -> str:
        """Name the likely cause of a divergence, judged at the last good state."""
        if isinstance(self.method, PenaltyClosure) and self.stiffness_report:
            # The closure modes stiffen as the pose changes: judge the last good poses too.
            worst, when = None, 0.0
            states = [(0.0, self.stiffness_report)] + [
                (t, self._closure_modes_at(q, qd))
                for t, q, qd in self._history
                if t > 0 and np.all(np.isfinite(q)) and np.all(np.isfinite(qd))
            ]
            for t, report in states:
                for mode in report:
                    ratio = mode["omega_h"] / max(mode["bound"], 1e-12)
                    if worst is None or ratio > worst["omega_h"] / max(worst["bound"], 1e-12):
                        worst, when = mode, t
            if worst is not None and worst["omega_h"] > 0.5 * worst["bound"]:
                pose = f" at t = {when:.6g} s" if when > 0 else ""
                return (
                    f"penalty stiffness against step (omega_n*h = {worst['omega_h']:.3g}, bound "
                    f"{worst['bound']:.3g} for {self.settings.integrator}{pose}, closure "
                    f"'{worst['closure']}'); lower the gains, add substeps, or use implicit_euler "
                    "or --closure exact"
                )
        # Judge the pose over the last good ticks: a blow-up leaves the singular pose quickly.
        worst = None
        for t, q, qd in self._history:
            sv = self._singular_values(q, qd)
            if sv.size and sv[0] > 0:
                ratio = sv[-1] / sv[0]
                if worst is None or ratio < worst[0]:
                    worst = (ratio, t, sv[-1], sv[0])
        if worst is not None and worst[0] < 1e-3:
            return (
                f"a singular pose (closure Jacobian singular values {worst[2]:.2g} to "
                f"{worst[3]:.2g} at t = {worst[1]:.6g} s); "
                + (
                    "exact closure asks for unbounded forces there: start away from the "
                    "singularity, or use penalty closure, which yields"
                    if isinstance(self.method, ExactClosure)
                    else "use --closure exact, a smaller step, or start away from the singularity"
                )
            )
        return "a step too large for the motion; add substeps or use an adaptive integrator"

    def smallest_singular_value(self) -> float:
        """Smallest singular value of the closure Jacobian at the current pose (nan if none)."""
        sv = self._singular_values(self.q, self.qd)
        return float(sv[-1]) if sv.size else float("nan")

    def _singular_values(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Singular values of the closure Jacobian at ``q``, largest first (empty if none)."""
        if not self.model.n_rows or not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
            return np.zeros(0)
        jacobian = self.mechanism.closure_jacobian(q)  # one kernel call, whatever M is
        return np.linalg.svd(jacobian, compute_uv=False)

    # ------------------------------------------------------------------ outputs
    def sample(self, singular_values: bool = False, geometry: bool = True) -> Sample:
        """Evaluate every observable at the current state.

        Parameters
        ----------
        singular_values : bool
            Also compute the smallest singular value of the closure Jacobian.
        geometry : bool
            Also compute the named points and the link segments (for drawing and logs); False
            leaves them None, for outputs that only need forces and energies.

        Returns
        -------
        Sample
        """
        out = self._observed  # one row of the block pipeline's observables
        self.mechanism.observe(self.q, self.qd, self.tau, self.model.length, self._point_links,
                               self._point_local, out)
        _, _, qdd, theta, points, force, error, cpoints, energy, power, dissipation, loss, \
            segments = (a[0] for a in out)
        sigma = np.nan
        if singular_values and self.model.n_rows:
            sigma = self.smallest_singular_value()
        return Sample(
            t=self.t,
            q=self.q.copy(),
            qd=self.qd.copy(),
            qdd=qdd.copy(),
            effort=self.tau.copy(),
            theta=theta.copy(),
            points=points.copy() if geometry else None,
            closure_force=force.copy(),
            closure_error=error.copy(),
            closure_points=cpoints.copy(),
            energy=energy.copy(),
            power_in=float(power),
            dissipation=float(dissipation),
            joint_loss=float(loss),
            segments=segments.copy() if geometry else None,
            sigma_min=sigma,
            measured=None if self.measured is None else self.measured.copy(),
        )

    def describe(self) -> dict:
        """Run settings as plain data (for summaries and log metadata)."""
        s = self.settings
        out = {
            "scene": self.model.name,
            "integrator": s.integrator,
            "closure": s.closure,
            "rate": s.rate,
            "substeps": s.substeps,
            "dt": self.dt,
            "h": self.h,
            "kernel": self.mechanism.kernel,
        }
        if self.sensors is not None:  # the logs keep the measured and the exact joint states
            out["sensors"] = True
        if isinstance(self.method, PenaltyClosure):
            out["kp"] = self.method.kp.tolist()
            out["kv"] = self.method.kv.tolist()
        else:
            out["alpha"] = self.method.alpha
            out["beta"] = self.method.beta
            out["projection"] = self.method.projection
        if not self.integrator.fixed_step:
            out["rtol"] = s.rtol
            out["atol"] = s.atol
        return out
