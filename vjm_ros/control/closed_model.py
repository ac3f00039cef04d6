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
preload along the null space of ``P`` (antagonistic efforts that move nothing), within the
actuators' limits when a distribution within them exists.

A singular configuration is one where ``A_v`` loses rank (the dependent coordinates are not
determined by the independent ones); :meth:`ClosedChainModel.singularity_measure` is the smallest
singular value of ``A_v`` and every method refuses a pose where it is below
:data:`SINGULAR_TOLERANCE`. Physics: the package's own kinematics, dynamics and closure rows
(:mod:`vjm_ros.core`), the same compiled kernels as the simulator's, read through
:meth:`~vjm_ros.core.mechanism.Mechanism.terms`. Joint-space inverse dynamics runs compiled as a
whole (:mod:`vjm_ros.control.compiled`: ~12 us per call on three_chain); the rest forms the
closed-chain algebra above in numpy from the kernel's ``M``, ``b``, ``A`` and ``Adot qd``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vjm_ros.core.errors import ConfigurationError, VjmError
from vjm_ros.core.mechanism import Mechanism, point_reader
from vjm_ros.core.model import Model
from vjm_ros.scene.assembly import assemble
from vjm_ros.scene.loader import Scene, load_scene, parse_scene

SINGULAR_TOLERANCE = 1e-9
"""Smallest singular value of ``A_v`` (m per unit coordinate) below which a pose is singular."""
CLOSURE_TOLERANCE = 1e-6
"""Largest closure residual of a state the dynamics accept, m or rad (assembly reaches 1e-10)."""


class SingularConfigurationError(VjmError):
    """The dependent coordinates are not determined at this pose (``A_v`` loses rank)."""


class InfeasibleEffortsError(VjmError):
    """No distribution of efforts within the actuators' limits gives the asked motion."""


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
    """

    mass_matrix: np.ndarray
    coriolis: np.ndarray
    gravity: np.ndarray
    velocity_map: np.ndarray
    acceleration_bias: np.ndarray
    effort_map: np.ndarray


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

    Raises
    ------
    ConfigurationError
        Unknown joint names, or a count other than the degrees of freedom.
    """

    def __init__(self, model: Model, independent: Sequence[str] | None = None,
                 closure_tolerance: float = CLOSURE_TOLERANCE) -> None:
        self.model = model
        self.closure_tolerance = float(closure_tolerance)
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
        self.actuated = [a.joint for a in model.actuators]
        self.limits = np.array([a.limit for a in model.actuators], dtype=float)
        self.selection = model.actuator_matrix()
        self._points = {p.name: i for i, p in enumerate(model.points)}
        self._point_reader = point_reader(model, [p.ref for p in model.points])

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_scene(cls, scene: str | Path | Scene, independent: Sequence[str] | None = None,
                   **kwargs):
        """From a built-in scene name, a scene file, or a loaded :class:`Scene`."""
        if not isinstance(scene, Scene):
            scene = load_scene(scene)
        return cls(scene.model, independent, **kwargs)

    @classmethod
    def from_yaml(cls, text: str, independent: Sequence[str] | None = None,
                  source: str = "scene_description", **kwargs):
        """From scene YAML text, e.g. what the node publishes on ``~/scene_description``."""
        return cls(parse_scene(text, source=source).model, independent, **kwargs)

    # ------------------------------------------------------------------ arguments
    def coordinates(self, values, name: str = "q") -> np.ndarray:
        """A full coordinate vector from an array in scene order or a ``{joint: value}`` map.

        Raises
        ------
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
        out = np.asarray(values, dtype=float).reshape(-1)
        if out.shape != (self.n,):
            raise ConfigurationError(f"{name}: expected {self.n} values ({', '.join(names)}), "
                                     f"found {out.size}")
        if not np.all(np.isfinite(out)):
            raise ConfigurationError(f"{name}: expected finite values, found {out.tolist()}")
        return out

    def _vector(self, values, size: int, name: str) -> np.ndarray:
        out = np.asarray(values, dtype=float).reshape(-1)
        if out.shape != (size,):
            raise ConfigurationError(f"{name}: expected {size} values, found {out.size}")
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
    def forward_kinematics(self, q, point: str) -> np.ndarray:
        """World position of a named point, shape (2,), m."""
        q = self.coordinates(q)
        return self._point(point, q)[0]

    def link_frame(self, q, link: str) -> tuple[np.ndarray, float]:
        """Origin (m, shape (2,)) and absolute angle (rad) of a link's frame."""
        q = self.coordinates(q)
        if link not in self.model.link_names:
            raise ConfigurationError(f"link: expected a link of {self.model.name} "
                                     f"({', '.join(self.model.link_names)}), found {link!r}")
        i = self.model.link_names.index(link)
        kin = self.mechanism.kinematics(q)
        return kin.origin[i].copy(), float(kin.theta[i])

    def closure_residual(self, q) -> np.ndarray:
        """``C(q)``, shape (r,), m or rad."""
        q = self.coordinates(q)
        return self.mechanism.terms(q, jacobian=False)[1].residual

    def constraint_jacobian(self, q) -> np.ndarray:
        """``A = dC/dq``, shape (r, n)."""
        q = self.coordinates(q)
        return self.mechanism.terms(q)[1].jacobian

    def assemble(self, u, guess=None, tolerance: float = 1e-10) -> np.ndarray:
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
        u = self._vector(u, self.dof, "u")
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
        a = terms.jacobian
        a_v = a[:, self.dependent]
        sv = np.linalg.svd(a_v, compute_uv=False) if a_v.size else np.ones(1)
        if sv.size and sv[-1] < SINGULAR_TOLERANCE:
            raise SingularConfigurationError(
                f"q: a singular configuration of {self.model.name} (smallest singular value of "
                f"the dependent-coordinate closure Jacobian {sv[-1]:.3g} < {SINGULAR_TOLERANCE:g});"
                " the dependent coordinates are not determined by the independent ones here")
        s_map = np.zeros((self.n, self.dof))
        s_map[self.independent, np.arange(self.dof)] = 1.0
        bias = np.zeros(self.n)
        if a_v.size:
            solve = np.linalg.solve(a_v, np.column_stack((a[:, self.independent], terms.bias)))
            s_map[self.dependent] = -solve[:, : self.dof]
            bias[self.dependent] = -solve[:, self.dof]
        return s_map, bias

    def velocity_map(self, q) -> np.ndarray:
        """``S``, shape (n, d): ``qd = S ud``."""
        q = self.coordinates(q)
        return self._terms(q, np.zeros(self.n))[0]

    def dependent_velocities(self, q, ud) -> np.ndarray:
        """Full joint rates ``qd = S ud``, shape (n,)."""
        return self.velocity_map(q) @ self._vector(ud, self.dof, "ud")

    def singularity_measure(self, q) -> float:
        """Smallest singular value of ``A_v`` (0 at a singular configuration)."""
        q = self.coordinates(q)
        a = self.constraint_jacobian(q)[:, self.dependent]
        return float(np.linalg.svd(a, compute_uv=False)[-1]) if a.size else math.inf

    def task_jacobian(self, q, point: str) -> np.ndarray:
        """``J_t``, shape (2, d): ``xd = J_t ud`` for a named point, m per rad (or m)."""
        q = self.coordinates(q)
        s_map, _ = self._terms(q, np.zeros(self.n))
        return self._point(point, q)[2] @ s_map

    def task_bias(self, q, qd, point: str) -> np.ndarray:
        """``J s + Jdot qd``, shape (2,), m/s^2: ``xdd = J_t udd + task_bias``."""
        q, qd = self.coordinates(q), self.coordinates(qd, "qd")
        _, s = self._terms(q, qd)
        _, a_bias, jac = self._point(point, q, qd)
        return jac @ s + a_bias

    def reduced_dynamics(self, q, qd) -> ReducedDynamics:
        """``M_r``, ``c_r``, ``g_r`` (and ``S``, ``s``, ``P``) at a state (see the module doc)."""
        q, qd = self.coordinates(q), self.coordinates(qd, "qd")
        s_map, s = self._terms(q, qd)
        full = self.mechanism.terms(q, qd)[0]
        still = self.mechanism.terms(q)[0]
        m_r = s_map.T @ full.mass_matrix @ s_map
        g_r = s_map.T @ still.bias
        c_r = s_map.T @ (full.mass_matrix @ s + full.bias - still.bias)
        return ReducedDynamics(m_r, c_r, g_r, s_map, s, s_map.T @ self.selection)

    def inverse_dynamics(
        self,
        q,
        qd,
        udd=None,
        *,
        point: str | None = None,
        xdd=None,
        weights=None,
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
            Internal preload along the null space of ``P``, N m or N (its largest component).
        respect_limits : bool
            Keep every effort within the scene's actuator limits (else report the request as
            infeasible); False returns the distribution whatever its size.

        Raises
        ------
        SingularConfigurationError, InfeasibleEffortsError, ConfigurationError
        """
        if xdd is None and point is None and udd is not None and (
            getattr(self, "_compiled_id", None) is not None or self._compiled() is not None
        ):
            return self._inverse_dynamics_compiled(q, qd, udd, weights, preload, respect_limits)
        rd = self.reduced_dynamics(q, qd)
        if xdd is not None or point is not None:
            if xdd is None or point is None or udd is not None:
                raise ConfigurationError("give either udd, or point and xdd")
            jt = self.task_jacobian(q, point)
            if jt.shape != (2, 2):
                raise ConfigurationError(f"xdd: a point's acceleration fixes 2 coordinates, the "
                                         f"mechanism has {self.dof} degrees of freedom")
            udd = np.linalg.solve(jt, self._vector(xdd, 2, "xdd") - self.task_bias(q, qd, point))
        elif udd is None:
            raise ConfigurationError("udd: expected the independent accelerations (or point, xdd)")
        w = rd.mass_matrix @ self._vector(udd, self.dof, "udd") + rd.coriolis + rd.gravity
        limits = self.limits if respect_limits else np.full(len(self.limits), np.inf)
        return distribute(rd.effort_map, w, limits, weights, preload)


    # ------------------------------------------------------------------ compiled path
    def _compiled(self):
        """The compiled joint-space inverse dynamics (None without numba)."""
        from vjm_ros.core.kernels import HAVE_NUMBA

        if not HAVE_NUMBA:
            return None
        if getattr(self, "_compiled_id", None) is None:
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
            udd = self._vector(udd, self.dof, "udd")
        if weights is None:
            winv = fast.ones
        else:
            wts = np.asarray(weights, dtype=float).reshape(-1)
            if wts.shape != fast.ones.shape or not np.all(wts > 0):
                raise ConfigurationError(
                    f"weights: expected {len(fast.ones)} positive numbers, found {wts.tolist()}")
            winv = 1.0 / wts
        limits = self.limits if respect_limits else fast.unlimited
        status = fast(q, qd, udd, winv, limits, self.closure_tolerance, SINGULAR_TOLERANCE)
        if status == C.NONFINITE:
            self.coordinates(q)
            self.coordinates(qd, "qd")
            self._vector(udd, self.dof, "udd")
        if status == C.OFF_CLOSURES:
            self._terms(q, qd)  # raises the error that names the residual
        if status == C.SINGULAR:
            raise SingularConfigurationError(
                f"q: a singular configuration of {self.model.name} (the dependent-coordinate "
                f"closure Jacobian loses rank: its smallest singular value < {SINGULAR_TOLERANCE:g})")
        if status == C.UNDERACTUATED:
            raise InfeasibleEffortsError(
                "the actuators cannot produce every motion at this pose (S^T B has not full rank)")
        if preload or status == C.BEYOND_LIMITS:
            return distribute(fast.p.copy(), fast.w.copy(), limits, weights, preload)
        return fast.tau.copy()


def distribute(p: np.ndarray, w: np.ndarray, limits: np.ndarray, weights=None,
               preload: float = 0.0) -> np.ndarray:
    """Efforts ``tau`` with ``P tau = w``: minimum ``W``-norm, plus a preload, within limits.

    Parameters
    ----------
    p : ndarray, shape (d, m)
    w : ndarray, shape (d,)
    limits : ndarray, shape (m,)
        Largest ``|tau_i|``.
    weights : array_like, shape (m,), optional
        Positive weights ``W`` (default: ones).
    preload : float
        Largest component of an added null-space effort (antagonistic, moves nothing).

    Raises
    ------
    InfeasibleEffortsError
        ``w`` cannot be produced within the limits (or ``P`` has not full row rank).
    """
    d, m = p.shape
    wts = np.ones(m) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    if wts.shape != (m,) or not np.all(wts > 0):
        raise ConfigurationError(f"weights: expected {m} positive numbers, found {wts.tolist()}")
    winv = 1.0 / wts
    g = (p * winv) @ p.T
    if np.linalg.matrix_rank(g) < d:
        raise InfeasibleEffortsError(
            "the actuators cannot produce every motion at this pose (S^T B has not full rank)")
    tau = winv * (p.T @ np.linalg.solve(g, w))
    null = np.eye(m) - (winv[:, None] * p.T) @ np.linalg.solve(g, p)
    if preload and m > d:
        _, _, vt = np.linalg.svd(p)
        z = vt[-1] / np.max(np.abs(vt[-1]))
        tau = tau + preload * z
    if np.all(np.abs(tau) <= limits * (1 + 1e-12)):
        return tau
    if m > d:  # move along the null space into the box, if the box is reachable
        from scipy.optimize import linprog

        basis = np.linalg.svd(null)[0][:, : m - d]
        res = linprog(np.zeros(m - d), A_ub=np.vstack((basis, -basis)),
                      b_ub=np.concatenate((limits - tau, limits + tau)),
                      bounds=[(None, None)] * (m - d), method="highs")
        if res.status == 0:
            return tau + basis @ res.x
    worst = int(np.argmax(np.abs(tau) / limits))
    raise InfeasibleEffortsError(
        f"efforts beyond the limits: actuator {worst} needs {tau[worst]:.4g} against a limit of "
        f"{limits[worst]:g} (no distribution within the limits gives this motion)")
