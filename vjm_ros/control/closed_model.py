"""The closed-chain model for controllers: kinematics, reduced dynamics, inverse dynamics.

A scene's chains are open; its closures ``C(q) = 0`` tie them into a mechanism of ``d = n - r``
degrees of freedom (``r`` independent closure rows). The controller's coordinates are ``d``
*independent* joint coordinates ``u`` (by default the first ``d`` actuated joints); the other
``r`` coordinates ``v`` follow from the closures. With ``A = dC/dq = [A_u A_v]``:

* velocities: ``qd = S ud`` with ``S = [I; -A_v^-1 A_u]`` (``A S = 0``);
* accelerations: ``qdd = S udd + s`` with ``s = [0; -A_v^-1 (Adot qd)]``;
* dynamics ``M qdd + b(q, qd) = B tau + A^T lambda``, projected on ``S`` (``S^T A^T = 0``):
  ``M_r udd + c_r + g_r = S^T B tau`` with ``M_r = S^T M S``, ``g_r = S^T b(q, 0)`` (gravity)
  and ``c_r = S^T (M s + b(q, qd) - b(q, 0))`` (Coriolis and centrifugal);
* a point ``x = f(q)`` of a link: ``xd = J S ud = J_t ud`` (the task Jacobian, with respect to
  the independent coordinates) and ``xdd = J_t udd + (J s + Jdot qd)`` (the task bias).

Inverse dynamics asks for the efforts ``tau`` with ``P tau = w``, ``P = S^T B`` (d x m),
``w = M_r udd + c_r + g_r``. With as many actuators as degrees of freedom the answer is unique;
with more (redundant actuation, e.g. three_chain: 3 actuators, 2 DOF) it is the minimum-norm
distribution ``tau = W^-1 P^T (P W^-1 P^T)^-1 w`` (weights ``W``), plus an optional internal
preload ``preload * z`` along the null space of ``P`` (antagonistic efforts that move nothing),
within the actuators' limits when a distribution within them exists
(:mod:`vjm_ros.control.distribution`). ``z`` has ``max |z_k| = 1`` and an orientation fixed by
the pose alone (the generalized cross product of the rows of ``[A^T B]``), continuous along a
motion and the same whichever independent coordinates are chosen.

A singular configuration is one where ``A_v`` loses rank (the dependent coordinates are not
determined by the independent ones); :meth:`ClosedChainModel.singularity_measure` is the smallest
singular value of ``A_v`` and every method refuses a pose where it is below
:data:`SINGULAR_TOLERANCE`. A point is singular where its task Jacobian ``J_t`` loses rank (the
point cannot be accelerated in some direction, as five_bar's pin at its start, both arms
stretched, although ``A_v`` is regular there): ``singularity_measure(q, point=...)`` is the
smallest singular value of ``J_t``, and task-space inverse dynamics refuses a pose where it is
below :data:`TASK_SINGULAR_TOLERANCE` times ``|J| |S|``. States are checked against the
closures: positions within ``closure_tolerance``, rates with ``|A qd|`` within
``velocity_tolerance``. Physics: the package's own kinematics, dynamics and closure rows
(:mod:`vjm_ros.core`), the same compiled kernels as the simulator's, read through
:meth:`~vjm_ros.core.mechanism.Mechanism.terms`. Joint-space inverse dynamics runs compiled as a
whole (:mod:`vjm_ros.control.compiled`: ~12 us per call on three_chain); the rest forms the
closed-chain algebra above in numpy from the kernel's ``M``, ``b``, ``A`` and ``Adot qd``, with
``S`` and ``s`` from the one compiled definition both paths share
(:func:`vjm_ros.control.compiled.velocity_map`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from vjm_ros.control.arguments import number_array, real, vector
from vjm_ros.control.compiled import preload_direction, velocity_map
from vjm_ros.control.distribution import (
    check_one_null_dimension,
    check_preload,
    distribute,
    inverse_weights,
)
from vjm_ros.control.errors import (
    InfeasibleEffortsError,
    SingularConfigurationError,
)
from vjm_ros.core.errors import ConfigurationError
from vjm_ros.core.mechanism import Mechanism
from vjm_ros.core.model import Model
from vjm_ros.core.readers import point_reader
from vjm_ros.scene.assembly import assemble
from vjm_ros.scene.loader import Scene, load_scene, parse_scene

SINGULAR_TOLERANCE = 1e-9
"""Smallest singular value of ``A_v`` (m per unit coordinate) below which a pose is singular."""
CLOSURE_TOLERANCE = 1e-6
"""Largest closure residual of a state the dynamics accept, m or rad (assembly reaches 1e-10)."""
UDD_UNIT = "rad/s^2 or m/s^2"
"""Units of the independent accelerations, for messages."""
CLOSURE_RATE = 1e3
"""1/s: the default largest closure rate ``|A qd|`` a state may have is its closure tolerance
times this rate. Measured over 5 s of free fall at 1 kHz (``vjm run``, rk4), the largest
``|A qd|`` was 26-97 times the largest ``|C|`` per second, exact and penalty closure, on
three_chain and five_bar (exact closure on five_bar: ``|C|`` <= 2.5e-8 m, ``|A qd|`` <= 9.5e-7 m/s
at up to 70 rad/s); 1e3 leaves a factor of ten over those, while rates off the closures by a
user's mistake (one joint's rate forgotten) are ~0.1-1 m/s."""
FRICTION_COMPENSATION_SCALE = 0.01
"""Velocity scale of the Coulomb-friction compensation of :class:`ClosedChainModel` with
``plant_terms=True``: a joint with sticking friction ``mu`` is compensated by
``mu tanh(rate / 0.01)`` (rad/s or m/s), ``mu sign(rate)`` but continuous through rest."""

TASK_SINGULAR_TOLERANCE = 1e-9
"""Smallest singular value of a point's task Jacobian ``J_t = J S``, relative to the largest it
can have, ``|J|_2 |S|_2`` (m per rad or per m), below which the point's acceleration cannot be
chosen freely: the task Jacobian's numerical rank is below 2. Round-off leaves the computed
``J_t`` about ``n eps cond(A_v) |J| |S|`` from the true one: at five_bar's start (both arms
stretched, ``cond(A_v) = 1``) it gives 1.6e-16 m/rad for a true zero; ``cond(A_v)`` stays below
2.6e4 along 5 s of three_chain's and five_bar's falls, ~3e-11 relative at worst. 1e-9 is above
that, and what it refuses is far beyond any actuator: on five_bar it refuses elbows bent by less
than 8e-9 rad, where 1 m/s^2 of the pin needs more than 1e7 N m (1 N m with the elbows bent by
0.1 rad)."""

JointValues = ArrayLike | Mapping[str, float]
"""Joint values in scene order (array_like, shape (n,)) or a ``{joint: value}`` map."""

__all__ = ["ClosedChainModel", "ReducedDynamics"]


@dataclass(frozen=True)
class ReducedDynamics:
    """``M_r udd + c_r + g_r = S^T B tau`` at one state.

    Attributes
    ----------
    mass_matrix : ndarray, shape (d, d)
        ``M_r``, kg or kg m^2 (mixed units for mixed coordinates).
    coriolis : ndarray, shape (d,)
        ``c_r``, N or N m.
    gravity : ndarray, shape (d,)
        ``g_r``, N or N m.
    velocity_map : ndarray, shape (n, d)
        ``S``: ``qd = S ud``.
    acceleration_bias : ndarray, shape (n,)
        ``s``: ``qdd = S udd + s``.
    effort_map : ndarray, shape (d, m)
        ``P = S^T B``.
    preload_direction : ndarray, shape (m,), or None
        ``z``, the oriented direction of the efforts that move nothing (``P z = 0``,
        ``max |z_k| = 1``, continuous along a motion:
        :func:`~vjm_ros.control.compiled.preload_direction`); None unless there is one
        actuator more than degrees of freedom.
    """

    mass_matrix: np.ndarray
    coriolis: np.ndarray
    gravity: np.ndarray
    velocity_map: np.ndarray
    acceleration_bias: np.ndarray
    effort_map: np.ndarray
    preload_direction: np.ndarray | None = None


def _compensated(model: Model) -> Model:
    """``model`` with its sticking friction made smooth (:data:`FRICTION_COMPENSATION_SCALE`)
    and without stops: the terms a controller's inverse dynamics can compensate."""
    joints = tuple(
        replace(j, range=(-math.inf, math.inf),
                friction_scale=j.friction_scale or FRICTION_COMPENSATION_SCALE)
        for j in model.joints)
    return Model.build(model.name, model.chains, model.links, joints, model.closures,
                       model.actuators, model.points, tuple(model.gravity), model.source_text,
                       model.extras, model.loads)


class ClosedChainModel:
    """A scene's closed mechanism, for controllers (no ROS).

    Parameters
    ----------
    model : Model
    independent : sequence of str, optional
        Joint names of the independent coordinates (``d`` of them); default: the first ``d``
        actuated joints, then other joints in order.
    closure_tolerance : float
        Largest closure residual of a state the dynamics accept, m or rad: the default suits
        assembled states and exact closure; a controller reading a penalty-closed simulator
        (closures met to ~1 mm) passes a looser bound.
    velocity_tolerance : float, optional
        Largest closure rate ``|A qd|`` of the rates ``qd`` the dynamics accept, m/s or rad/s;
        default ``closure_tolerance * CLOSURE_RATE`` (1e-3 m/s with the default closure
        tolerance; a penalty-closed simulator's rates are off by up to ~0.2 m/s).
    plant_terms : bool
        Whether the dynamics include the scene's joint damping, armature, friction and constant
        loads (their compensation in the inverse dynamics; sticking friction as the smooth
        ``mu tanh(rate / FRICTION_COMPENSATION_SCALE)``, stops left out); default False, the
        ideal mechanism.

    Raises
    ------
    ConfigurationError
        Unknown joint names, or a count other than the degrees of freedom.
    """

    def __init__(self, model: Model, independent: Sequence[str] | None = None,
                 closure_tolerance: float = CLOSURE_TOLERANCE,
                 velocity_tolerance: float | None = None, plant_terms: bool = False) -> None:
        model = _compensated(model) if plant_terms else model.without_plant_terms()
        self.model = model
        self.closure_tolerance = _tolerance(closure_tolerance, "closure_tolerance", "m or rad")
        self.velocity_tolerance = (
            self.closure_tolerance * CLOSURE_RATE if velocity_tolerance is None
            else _tolerance(velocity_tolerance, "velocity_tolerance", "m/s or rad/s"))
        self.mechanism = Mechanism.reader(model)
        self.n = model.n
        q0, _ = model.initial_state()
        a0 = self.mechanism.terms(q0)[1].jacobian
        rank = int(np.linalg.matrix_rank(a0)) if a0.size else 0
        self.dof = self.n - rank
        names = model.joint_names
        if independent is None:
            order = model.actuator_names + [j for j in names if j not in model.actuator_names]
            independent = order[: self.dof]
        for j in independent:
            if j not in names:
                raise ConfigurationError(
                    f"independent: expected joints of {model.name} ({', '.join(names)}), found {j!r}")
        if len(independent) != self.dof:
            raise ConfigurationError(
                f"independent: expected {self.dof} joints (the degrees of freedom), found "
                f"{len(independent)}")
        self.independent = [names.index(j) for j in independent]
        self.dependent = [i for i in range(self.n) if i not in self.independent]
        self._independent = np.array(self.independent, dtype=np.int64)
        self._dependent = np.array(self.dependent, dtype=np.int64)
        self._compiled_id = None
        self.actuated = [a.joint for a in model.actuators]
        self._actuated = np.array(self.actuated, dtype=np.int64)
        self.limits = np.array([a.limit for a in model.actuators], dtype=float)
        self.selection = model.actuator_matrix()
        self._row_closure = [c.name for c in model.closures for _ in range(c.rows)]
        self._points = {p.name: i for i, p in enumerate(model.points)}
        self._point_reader = point_reader(model, [p.ref for p in model.points])

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_scene(cls, scene: str | Path | Scene, independent: Sequence[str] | None = None,
                   **kwargs: float | bool | None) -> ClosedChainModel:
        """From a built-in scene name, a scene file, or a loaded :class:`Scene`."""
        if not isinstance(scene, Scene):
            scene = load_scene(scene)
        return cls(scene.model, independent, **kwargs)

    @classmethod
    def from_yaml(cls, text: str, independent: Sequence[str] | None = None,
                  source: str = "scene_description",
                  **kwargs: float | bool | None) -> ClosedChainModel:
        """From scene YAML text, e.g. what the node publishes on ``~/scene_description``."""
        return cls(parse_scene(text, source=source).model, independent, **kwargs)

    # ------------------------------------------------------------------ arguments
    def coordinates(self, values: JointValues, name: str = "q") -> np.ndarray:
        """A full coordinate vector from an array in scene order or a ``{joint: value}`` map.

        Raises
        ------
        ArgumentTypeError
            Not numbers (text, booleans, ...).
        ConfigurationError
            Wrong length, unknown or missing joint names, or non-finite values.
        """
        names = self.model.joint_names
        if isinstance(values, Mapping):
            unknown = [k for k in values if k not in names]
            if unknown:
                raise ConfigurationError(
                    f"{name}: expected joints of {self.model.name} ({', '.join(names)}), "
                    f"found {unknown[0]!r}")
            missing = [k for k in names if k not in values]
            if missing:
                raise ConfigurationError(f"{name}: expected a value for every joint, missing "
                                         f"{', '.join(missing)}")
            values = [values[k] for k in names]
        unit = "rad/s or m/s" if name.startswith("qd") else "rad or m"
        out = number_array(values, name, f"{self.n} numbers ({unit}) or a {{joint: value}} map")
        if out.shape != (self.n,):
            raise ConfigurationError(f"{name}: expected {self.n} values ({', '.join(names)}), "
                                     f"found {out.size}")
        if not np.all(np.isfinite(out)):
            raise ConfigurationError(f"{name}: expected finite values, found {out.tolist()}")
        return out

    def _point(self, point: str, q: np.ndarray, qd: np.ndarray | None = None):
        """Position (2,), ``Jdot qd`` (2,) and Jacobian ``dP/dq`` (2, n) of a named point."""
        if point not in self._points:
            raise ConfigurationError(
                f"point: expected a named point of {self.model.name} "
                f"({', '.join(self._points)}), found {point!r}")
        rows = slice(2 * self._points[point], 2 * self._points[point] + 2)
        terms = self._point_reader.terms(q, qd)[1]
        return terms.residual[rows].copy(), terms.bias[rows].copy(), terms.jacobian[rows].copy()

    # ------------------------------------------------------------------ kinematics
    def forward_kinematics(self, q: JointValues, point: str) -> np.ndarray:
        """World position of a named point, shape (2,), m."""
        q = self.coordinates(q)
        return self._point(point, q)[0]

    def link_frame(self, q: JointValues, link: str) -> tuple[np.ndarray, float]:
        """Origin (m, shape (2,)) and absolute angle (rad) of a link's frame."""
        q = self.coordinates(q)
        if link not in self.model.link_names:
            raise ConfigurationError(f"link: expected a link of {self.model.name} "
                                     f"({', '.join(self.model.link_names)}), found {link!r}")
        i = self.model.link_names.index(link)
        kin = self.mechanism.kinematics(q)
        return kin.origin[i].copy(), float(kin.theta[i])

    def closure_residual(self, q: JointValues) -> np.ndarray:
        """``C(q)``, shape (r,), m or rad."""
        q = self.coordinates(q)
        return self.mechanism.terms(q, jacobian=False)[1].residual

    def constraint_jacobian(self, q: JointValues) -> np.ndarray:
        """``A = dC/dq``, shape (r, n)."""
        q = self.coordinates(q)
        return self.mechanism.terms(q)[1].jacobian

    def assemble(self, u: ArrayLike, guess: JointValues | None = None,
                 tolerance: float = 1e-10) -> np.ndarray:
        """The full coordinates with the independent ones at ``u``, the closures met.

        Parameters
        ----------
        u : array_like, shape (d,)
            Independent coordinates, rad or m.
        guess : array_like or mapping, optional
            Coordinates near the wanted branch (default: the scene's initial state).
        tolerance : float
            Largest closure residual accepted, m or rad.

        Raises
        ------
        ConfigurationError
            The closures cannot be met from this guess.
        """
        u = vector(u, self.dof, "u", "rad or m")
        q = self.model.initial_state()[0] if guess is None else self.coordinates(guess, "guess")
        q = q.copy()
        q[self.independent] = u
        q_new, _, err = assemble(self.model.with_state(q, np.zeros(self.n)), self.independent,
                                 tolerance)
        if not err <= tolerance:
            raise ConfigurationError(
                f"u: expected independent coordinates the closures can meet, found {u.tolist()} "
                f"(residual {err:.3g} after assembly)")
        return q_new

    # ------------------------------------------------------------------ the closed chain
    def _terms(self, q: np.ndarray, qd: np.ndarray):
        terms = self.mechanism.terms(q, qd)[1]
        if terms.residual.size and np.max(np.abs(terms.residual)) > self.closure_tolerance:
            raise ConfigurationError(
                f"q: expected a state that meets the closures (within {self.closure_tolerance:g}), "
                f"found a residual of {np.max(np.abs(terms.residual)):.3g}; use assemble()")
        self._check_rates(terms.rate)
        a = terms.jacobian
        s_map = np.empty((self.n, self.dof))
        bias = np.empty(self.n)
        smallest = velocity_map(a, terms.bias, self._independent, self._dependent,
                                SINGULAR_TOLERANCE, s_map, bias)
        if smallest < SINGULAR_TOLERANCE:
            raise SingularConfigurationError(
                f"q: a singular configuration of {self.model.name} (smallest singular value of "
                f"the dependent-coordinate closure Jacobian {smallest:.3g} < "
                f"{SINGULAR_TOLERANCE:g}); the dependent coordinates are not determined by the "
                "independent ones here")
        return s_map, bias, a

    def _check_rates(self, rate: np.ndarray) -> None:
        """Refuse joint rates whose closure rates ``A qd`` exceed the velocity tolerance."""
        if not rate.size:
            return
        row = int(np.argmax(np.abs(rate)))
        if abs(rate[row]) > self.velocity_tolerance:
            raise ConfigurationError(
                f"qd: expected joint rates that keep the closures (|A qd| within "
                f"{self.velocity_tolerance:g} m/s or rad/s), found {rate[row]:.3g} on closure "
                f"{self._row_closure[row]!r}; use dependent_velocities() for the dependent rates "
                f"(or pass velocity_tolerance)")

    def velocity_map(self, q: JointValues) -> np.ndarray:
        """``S``, shape (n, d): ``qd = S ud``."""
        q = self.coordinates(q)
        return self._terms(q, np.zeros(self.n))[0]

    def dependent_velocities(self, q: JointValues, ud: ArrayLike) -> np.ndarray:
        """Full joint rates ``qd = S ud``, shape (n,)."""
        return self.velocity_map(q) @ vector(ud, self.dof, "ud", "rad/s or m/s")

    def singularity_measure(self, q: JointValues, point: str | None = None) -> float:
        """How far the pose is from a singular configuration (0 at one).

        Parameters
        ----------
        q : array_like or mapping
            Coordinates, rad or m.
        point : str, optional
            A named point: the measure is then the smallest singular value of its task
            Jacobian ``J_t`` (m per rad or per m; 0 where the point cannot be moved in some
            direction by the independent coordinates, such as five_bar's start, where both
            arms are stretched). Without it: the smallest singular value of ``A_v`` (0 where
            the dependent coordinates are not determined by the independent ones).

        Returns
        -------
        float
            ``inf`` for a mechanism without closures (no ``A_v``).

        Raises
        ------
        SingularConfigurationError
            With ``point``, where ``A_v`` itself is singular (``J_t`` is then undefined).
        """
        q = self.coordinates(q)
        if point is not None:
            return float(np.linalg.svd(self.task_jacobian(q, point), compute_uv=False)[-1])
        a = self.constraint_jacobian(q)[:, self.dependent]
        return float(np.linalg.svd(a, compute_uv=False)[-1]) if a.size else math.inf

    def task_jacobian(self, q: JointValues, point: str) -> np.ndarray:
        """``J_t``, shape (2, d): ``xd = J_t ud`` for a named point, m per rad (or m)."""
        q = self.coordinates(q)
        s_map = self._terms(q, np.zeros(self.n))[0]
        return self._point(point, q)[2] @ s_map

    def _regular_task_jacobian(self, q: np.ndarray, point: str) -> np.ndarray:
        """``J_t`` of a point, refused where its rank is below 2 (TASK_SINGULAR_TOLERANCE)."""
        s_map = self._terms(q, np.zeros(self.n))[0]
        jac = self._point(point, q)[2]
        jt = jac @ s_map
        scale = np.linalg.norm(jac, 2) * np.linalg.norm(s_map, 2)
        sv = np.linalg.svd(jt, compute_uv=False)
        rank = int(np.sum(sv > TASK_SINGULAR_TOLERANCE * scale))
        if rank < 2:
            raise SingularConfigurationError(
                f"point: {point!r} cannot be accelerated in every direction at this pose of "
                f"{self.model.name}: its task Jacobian has rank {rank} (expected 2; singular "
                f"values {', '.join(f'{v:.3g}' for v in sv)} m/rad against "
                f"{TASK_SINGULAR_TOLERANCE:g} x |J| |S| = {TASK_SINGULAR_TOLERANCE * scale:.3g});"
                f" singularity_measure(q, point={point!r}) tells how close a pose is")
        return jt

    def task_bias(self, q: JointValues, qd: JointValues, point: str) -> np.ndarray:
        """``J s + Jdot qd``, shape (2,), m/s^2: ``xdd = J_t udd + task_bias``."""
        q, qd = self.coordinates(q), self.coordinates(qd, "qd")
        s = self._terms(q, qd)[1]
        _, a_bias, jac = self._point(point, q, qd)
        return jac @ s + a_bias

    def reduced_dynamics(self, q: JointValues, qd: JointValues) -> ReducedDynamics:
        """``M_r``, ``c_r``, ``g_r`` (and ``S``, ``s``, ``P``) at a state (see the module doc)."""
        q, qd = self.coordinates(q), self.coordinates(qd, "qd")
        s_map, s, a = self._terms(q, qd)
        full = self.mechanism.terms(q, qd)[0]
        still = self.mechanism.terms(q)[0]
        m_r = s_map.T @ full.mass_matrix @ s_map
        g_r = s_map.T @ still.bias
        c_r = s_map.T @ (full.mass_matrix @ s + full.bias - still.bias)
        direction = None
        if len(self.actuated) == self.dof + 1:
            direction = np.empty(len(self.actuated))
            check_one_null_dimension(self.n - a.shape[0], len(self.actuated))
            preload_direction(np.ascontiguousarray(a), self._actuated, direction)
        return ReducedDynamics(m_r, c_r, g_r, s_map, s, s_map.T @ self.selection, direction)

    def inverse_dynamics(
        self,
        q: JointValues,
        qd: JointValues,
        udd: ArrayLike | None = None,
        *,
        point: str | None = None,
        xdd: ArrayLike | None = None,
        weights: ArrayLike | None = None,
        preload: float = 0.0,
        respect_limits: bool = True,
    ) -> np.ndarray:
        """Actuator efforts that give the asked acceleration, shape (m,), N m or N.

        Parameters
        ----------
        q, qd : array_like or mapping
            State (rad or m, rad/s or m/s), consistent with the closures.
        udd : array_like, shape (d,), optional
            Independent accelerations, rad/s^2 or m/s^2.
        point, xdd : str and array_like (2,), optional
            Instead of ``udd``: the acceleration of a named point, m/s^2 (needs ``d = 2``).
        weights : array_like, shape (m,), optional
            Effort weights of the minimum-norm distribution (redundant actuation).
        preload : float
            Internal preload, N m or N: ``preload * z`` is added to the efforts, ``z`` the
            null-space direction of ``P`` with ``max |z_k| = 1`` and ``det([P; z^T]) > 0``
            (:mod:`vjm_ros.control.distribution`), continuous along a motion: the same preload
            is the same antagonism everywhere. Needs one actuator more than degrees of freedom.
        respect_limits : bool
            Keep every effort within the scene's actuator limits (else report the request as
            infeasible); False returns the distribution whatever its size.

        Raises
        ------
        SingularConfigurationError
            ``A_v`` loses rank, or (with ``point``) the point's task Jacobian does (rank below 2
            by :data:`TASK_SINGULAR_TOLERANCE`; the message names the point and the rank).
        InfeasibleEffortsError
            No efforts within the limits give the motion (names the actuator's joint).
        ArgumentTypeError
            Text or other non-numbers where numbers are expected (``udd="ab"``,
            ``preload="20"``).
        ConfigurationError
            Wrong lengths, NaN or infinite values, unknown names, a state off the closures
            (``q``) or rates off them (``qd``: ``|A qd|`` beyond ``velocity_tolerance``), a
            nonzero ``preload`` without exactly one redundant actuator, ``udd`` together with
            ``xdd``.
        """
        preload = real(preload, "preload", "N m or N")
        check_preload(preload, self.dof, len(self.actuated), self.model.name)
        if xdd is None and point is None and udd is not None and (
            self._compiled_id is not None or self._compiled() is not None
        ):
            return self._inverse_dynamics_compiled(q, qd, udd, weights, preload, respect_limits)
        q, qd = self.coordinates(q), self.coordinates(qd, "qd")
        if xdd is not None or point is not None:
            udd = self._task_accelerations(q, qd, udd, point, xdd)
        elif udd is None:
            raise ConfigurationError(
                f"udd: expected the independent accelerations ({self.dof} numbers, {UDD_UNIT}), "
                f"or point and xdd, found none")
        rd = self.reduced_dynamics(q, qd)
        w = rd.mass_matrix @ vector(udd, self.dof, "udd", UDD_UNIT) + rd.coriolis + rd.gravity
        limits = self.limits if respect_limits else np.full(len(self.limits), np.inf)
        return distribute(rd.effort_map, w, limits, weights, preload, self.model.actuator_names,
                          rd.preload_direction)

    def _task_accelerations(self, q: np.ndarray, qd: np.ndarray, udd, point, xdd) -> np.ndarray:
        """``udd`` that gives ``point`` the acceleration ``xdd``: ``J_t^-1 (xdd - task bias)``."""
        if udd is not None:
            raise ConfigurationError(
                "udd and xdd: expected either udd (independent accelerations) or point and xdd "
                "(a point's acceleration), found both")
        if point is None:
            raise ConfigurationError("point: expected the named point xdd accelerates, found none")
        if xdd is None:
            raise ConfigurationError(
                f"xdd: expected the acceleration of {point!r} (2 numbers, m/s^2), found none")
        xdd = vector(xdd, 2, "xdd", "m/s^2")
        if self.dof != 2:
            raise ConfigurationError(
                f"xdd: expected a mechanism of 2 degrees of freedom (a point's acceleration fixes "
                f"2 coordinates), found {self.dof} in {self.model.name}")
        jt = self._regular_task_jacobian(q, point)
        return np.linalg.solve(jt, xdd - self.task_bias(q, qd, point))

    # ------------------------------------------------------------------ compiled path
    def _compiled(self):
        """The compiled joint-space inverse dynamics (None without numba)."""
        from vjm_ros.core.kernels import HAVE_NUMBA

        if not HAVE_NUMBA:
            return None
        if self._compiled_id is None:
            from vjm_ros.control.compiled import CompiledInverseDynamics

            self._compiled_id = CompiledInverseDynamics(self.model, self.independent)
        return self._compiled_id

    def _inverse_dynamics_compiled(self, q, qd, udd, weights, preload, respect_limits):
        """Joint-space inverse dynamics through the compiled path; arguments are validated by
        the compiled code first and again here, naming them, only when it refuses them."""
        from vjm_ros.control import compiled as C

        fast = self._compiled_id
        n = self.n
        if not (type(q) is np.ndarray and q.shape == (n,) and q.dtype == np.float64):
            q = self.coordinates(q)
        if not (type(qd) is np.ndarray and qd.shape == (n,) and qd.dtype == np.float64):
            qd = self.coordinates(qd, "qd")
        if not (type(udd) is np.ndarray and udd.shape == (self.dof,) and udd.dtype == np.float64):
            udd = vector(udd, self.dof, "udd", UDD_UNIT)
        winv = fast.ones if weights is None else inverse_weights(weights, len(fast.ones))
        limits = self.limits if respect_limits else fast.unlimited
        status = fast(q, qd, udd, winv, limits, self.closure_tolerance, self.velocity_tolerance,
                      SINGULAR_TOLERANCE, preload)
        if status == C.NONFINITE:
            self.coordinates(q)
            self.coordinates(qd, "qd")
            vector(udd, self.dof, "udd", UDD_UNIT)
        if status in (C.OFF_CLOSURES, C.OFF_VELOCITIES):
            self._terms(q, qd)  # raises the error that names the residual or the rate
        if status == C.SINGULAR:
            raise SingularConfigurationError(
                f"q: a singular configuration of {self.model.name} (the dependent-coordinate "
                f"closure Jacobian loses rank: its smallest singular value < {SINGULAR_TOLERANCE:g})")
        if status == C.UNDERACTUATED:
            raise InfeasibleEffortsError(
                "the actuators cannot produce every motion at this pose (S^T B has not full rank)")
        if status == C.BEYOND_LIMITS:
            direction = fast.direction.copy() if preload else None
            return distribute(fast.p.copy(), fast.w.copy(), limits, weights, preload,
                              self.model.actuator_names, direction)
        return fast.tau.copy()


def _tolerance(value: object, name: str, unit: str) -> float:
    """A positive tolerance; ``inf`` switches its check off."""
    if isinstance(value, float) and value == math.inf:
        return math.inf
    out = real(value, name, unit)
    if not out > 0:
        raise ConfigurationError(f"{name}: expected a positive number ({unit}), found {out:g}")
    return out
