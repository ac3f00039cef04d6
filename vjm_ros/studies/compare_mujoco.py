"""The same mechanisms in MuJoCo, for the side-by-side rows of ``vjm bench``.

Optional: install with ``pip install .[compare]``. Nothing here imports :mod:`mujoco` at module
import time; :func:`import_mujoco` returns ``None`` when it is missing and the bench then leaves
the MuJoCo rows out (and says so).

The model is translated from a :class:`~vjm_ros.core.model.Model`, so that geometry, masses, inertias
and gravity are those of the scene:

* one MJCF body per link, nested along its chain, placed at the scene's initial pose (so
  ``qpos = 0`` is the vjm initial state); a revolute joint is a ``hinge`` about ``z`` at the link
  origin, a prismatic joint a ``slide`` along ``n(theta_pred)``;
* the link's mass at its mass centre ``(p, q)``, centroidal inertia ``I`` about ``z``; MuJoCo needs
  positive principal inertias, so ``(I/2 + eps, I/2 + eps, I + eps)`` with ``eps`` =
  :attr:`MujocoSettings.inertia_epsilon` (1e-12 kg m^2: a point mass of the thesis scenes stays a
  point mass to 1e-10 relative);
* a ``hinge`` closure is an equality ``connect`` between the two bodies (or the world) with the
  anchor at the closure point; ``solref``/``solimp`` set how soft MuJoCo makes it;
* each actuator is a ``motor`` on its joint (torque or force between the joint's two links);
* sites mark every link end, every named point (chain tips) and both sides of every closure, so
  that the bench reads the same positions as from vjm.

Slider and angle closures have no MuJoCo equality of the same kind and are refused with
:class:`NotImplementedError`.

MuJoCo 4.0.0 is excluded (:data:`MUJOCO_REQUIREMENT`): its sparse Cholesky factorization merges
rows with different descendants into one supernode and gives the Newton solver a wrong Hessian
factor when the constraint Jacobian is sparse (fixed in 4.0.1). Models this small use MuJoCo's
dense Jacobian (``jacobian="auto"`` picks dense below 60 degrees of freedom), so the bench's rows
are not affected, but a requirement cannot tell models apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from vjm_ros.core.errors import DivergenceError
from vjm_ros.core.mechanism import forward_kinematics
from vjm_ros.core.model import GROUND, HINGE, REVOLUTE, Model

MUJOCO_REQUIREMENT = "mujoco>=3.2,!=4.0.0"
"""Requirement string of the ``compare`` extra."""

KNOWN_BAD_VERSIONS = {
    "4.0.0": (
        "MuJoCo 4.0.0 has a sparse Cholesky bug (wrong Newton Hessian factor with a sparse "
        "constraint Jacobian; fixed in 4.0.1)"
    ),
}
"""Versions with a known defect that matters for this comparison, and why."""

INTEGRATORS = ("Euler", "implicitfast", "RK4")
"""MuJoCo integrators compared (MJCF spelling)."""

DEFAULT_SOLREF = (0.02, 1.0)
"""MuJoCo's default ``solref``: time constant 0.02 s, damping ratio 1."""
DEFAULT_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
"""MuJoCo's default ``solimp``."""


def import_mujoco() -> ModuleType | None:
    """The :mod:`mujoco` module, or None when it is not installed."""
    try:
        import mujoco
    except ImportError:
        return None
    return mujoco


def mujoco_version() -> str | None:
    """Installed MuJoCo version, or None."""
    mj = import_mujoco()
    return None if mj is None else str(mj.__version__)


def version_note(version: str | None) -> str | None:
    """Why a MuJoCo version is not trusted for the comparison, or None when it is."""
    if version is None:
        return None
    return KNOWN_BAD_VERSIONS.get(version)


@dataclass(frozen=True)
class MujocoSettings:
    """How MuJoCo integrates the mechanism.

    Attributes
    ----------
    integrator : str
        ``"Euler"``, ``"implicitfast"`` or ``"RK4"`` (also ``"implicit"``).
    rate : float
        Control ticks per second, Hz.
    substeps : int
        MuJoCo steps per tick (``timestep = 1 / (rate * substeps)``).
    solref : tuple of float
        Equality ``solref``: ``(timeconst, dampratio)`` or, both negative,
        ``(-stiffness, -damping)``.
    solimp : tuple of float
        Equality ``solimp`` (5 numbers).
    inertia_epsilon : float
        Added to every principal inertia, kg m^2.
    """

    integrator: str = "RK4"
    rate: float = 1000.0
    substeps: int = 1
    solref: tuple[float, ...] = DEFAULT_SOLREF
    solimp: tuple[float, ...] = DEFAULT_SOLIMP
    inertia_epsilon: float = 1e-12

    @property
    def timestep(self) -> float:
        """MuJoCo step, s."""
        return 1.0 / (self.rate * self.substeps)


def _f(x: float) -> str:
    return f"{float(x):.17g}"


def _vec(*xs: float) -> str:
    return " ".join(_f(x) for x in xs)


def model_to_mjcf(model: Model, settings: MujocoSettings | None = None) -> str:
    """MJCF text of a scene model.

    Parameters
    ----------
    model : Model
        Revolute and prismatic joints, hinge closures only.
    settings : MujocoSettings, optional

    Returns
    -------
    str

    Raises
    ------
    NotImplementedError
        For slider or angle closures.
    """
    s = settings or MujocoSettings()
    for cl in model.closures:
        if cl.kind != HINGE:
            raise NotImplementedError(
                f"closure '{cl.name}' is a {cl.kind}; only hinge closures have a MuJoCo counterpart"
            )
    q, _ = model.initial_state()
    kin = forward_kinematics(model, q)
    g = model.gravity
    eps = float(s.inertia_epsilon)
    lines = [
        f'<mujoco model="{model.name}">',
        '  <compiler angle="radian" inertiafromgeom="false" autolimits="true"/>',
        f'  <option timestep="{_f(s.timestep)}" integrator="{s.integrator}" '
        f'gravity="{_vec(g[0], g[1], 0.0)}">',
        '    <flag contact="disable" energy="enable"/>',
        "  </option>",
        "  <worldbody>",
    ]
    lines += [
        f'    <site name="cl_{cl.name}_b" pos="{_vec(*cl.target.local, 0.0)}"/>'
        for cl in model.closures
        if cl.target.link == GROUND
    ]
    for chain in model.chains:
        lines += _chain_bodies(model, chain, q, kin.theta, eps)
    lines.append("  </worldbody>")
    if model.closures:
        lines.append("  <equality>")
        for cl in model.closures:
            body2 = "world" if cl.target.link == GROUND else model.links[cl.target.link].name
            lines.append(
                f'    <connect name="{cl.name}" body1="{model.links[cl.point.link].name}" '
                f'body2="{body2}" anchor="{_vec(*cl.point.local, 0.0)}" '
                f'solref="{_vec(*s.solref)}" solimp="{_vec(*s.solimp)}"/>'
            )
        lines.append("  </equality>")
    if model.actuators:
        lines.append("  <actuator>")
        for a in model.actuators:
            jn = model.joints[a.joint].name
            lines.append(f'    <motor name="act_{jn}" joint="{jn}" gear="1"/>')
        lines.append("  </actuator>")
    lines.append("</mujoco>")
    return "\n".join(lines) + "\n"


def _chain_bodies(model: Model, chain, q: np.ndarray, theta: np.ndarray, eps: float) -> list[str]:
    """MJCF bodies of one chain, nested link after link, at the pose ``q``."""
    lines = []
    pred_theta = chain.angle
    for pos, i in enumerate(chain.links):
        link, joint = model.links[i], model.joints[i]
        slide = joint.slide if joint.kind == REVOLUTE else q[i]
        phi = float(theta[i] - pred_theta)
        indent = "    " + "  " * pos
        if pos == 0:
            th1, a1 = chain.angle, chain.length
            o = (
                np.asarray(chain.origin, dtype=float)
                + a1 * np.array([math.cos(th1), math.sin(th1)])
                + slide * np.array([-math.sin(th1), math.cos(th1)])
            )
            lines.append(
                f'{indent}<body name="{link.name}" pos="{_vec(o[0], o[1], 0.0)}" '
                f'euler="{_vec(0.0, 0.0, theta[i])}">'
            )
        else:
            prev = model.links[chain.links[pos - 1]]
            lines.append(
                f'{indent}<body name="{link.name}" pos="{_vec(prev.length, slide, 0.0)}" '
                f'euler="{_vec(0.0, 0.0, phi)}">'
            )
        lines += _link_contents(model, i, phi, indent + "  ", eps)
        pred_theta = float(theta[i])
    for d in range(len(chain.links) - 1, -1, -1):
        lines.append("    " + "  " * d + "</body>")
    return lines


def _link_contents(model: Model, i: int, phi: float, inner: str, eps: float) -> list[str]:
    """Joint, inertial and sites of link ``i`` (relative angle to its predecessor ``phi``)."""
    link, joint = model.links[i], model.joints[i]
    lines = []
    if joint.kind == REVOLUTE:
        lines.append(f'{inner}<joint name="{joint.name}" type="hinge" axis="0 0 1"/>')
    else:
        axis = _vec(math.sin(phi), math.cos(phi), 0.0)
        lines.append(f'{inner}<joint name="{joint.name}" type="slide" axis="{axis}"/>')
    inertia = float(link.inertia)
    lines.append(
        f'{inner}<inertial pos="{_vec(*link.com, 0.0)}" mass="{_f(max(link.mass, eps))}" '
        f'diaginertia="{_vec(inertia / 2 + eps, inertia / 2 + eps, inertia + eps)}"/>'
    )
    lines.append(f'{inner}<site name="end_{link.name}" pos="{_vec(link.length, 0.0, 0.0)}"/>')
    for p in model.points:
        if p.ref.link == i:
            lines.append(f'{inner}<site name="pt_{p.name}" pos="{_vec(*p.ref.local, 0.0)}"/>')
    for cl in model.closures:
        if cl.point.link == i:
            lines.append(f'{inner}<site name="cl_{cl.name}_a" pos="{_vec(*cl.point.local, 0.0)}"/>')
        if cl.target.link == i:
            lines.append(f'{inner}<site name="cl_{cl.name}_b" pos="{_vec(*cl.target.local, 0.0)}"/>')
    return lines


class MujocoSimulator:
    """Fixed-rate MuJoCo run of a scene, read through the same positions as vjm.

    Parameters
    ----------
    model : Model
    settings : MujocoSettings

    Raises
    ------
    ImportError
        When MuJoCo is not installed.
    """

    def __init__(self, model: Model, settings: MujocoSettings | None = None):
        mj = import_mujoco()
        if mj is None:
            raise ImportError("MuJoCo is not installed (pip install '.[compare]')")
        self.mj = mj
        self.model = model
        self.settings = settings or MujocoSettings()
        self.xml = model_to_mjcf(model, self.settings)
        self.m = mj.MjModel.from_xml_string(self.xml)
        self.d = mj.MjData(self.m)
        self.dt = 1.0 / self.settings.rate
        self.substeps = int(self.settings.substeps)
        self.ticks = 0
        self.t = 0.0

        def site(name: str) -> int:
            return int(mj.mj_name2id(self.m, mj.mjtObj.mjOBJ_SITE, name))

        self._ends = np.array([site(f"end_{lk.name}") for lk in model.links], dtype=int)
        self._points = np.array([site(f"pt_{p.name}") for p in model.points], dtype=int)
        self._cl_a = np.array([site(f"cl_{c.name}_a") for c in model.closures], dtype=int)
        self._cl_b = np.array([site(f"cl_{c.name}_b") for c in model.closures], dtype=int)
        self._badqacc = int(mj.mjtWarning.mjWARN_BADQACC)
        self._previous_handler = mj.get_mju_user_warning()
        self.warnings: list[str] = []
        mj.set_mju_user_warning(self.warnings.append)
        q0, qd0 = model.initial_state()
        self.d.qvel[:] = qd0
        mj.mj_forward(self.m, self.d)

    def close(self) -> None:
        """Restore MuJoCo's warning handler."""
        if self._previous_handler is not ...:
            self.mj.set_mju_user_warning(self._previous_handler)
            self._previous_handler = ...

    def __enter__(self) -> MujocoSimulator:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def set_efforts(self, efforts: np.ndarray) -> np.ndarray:
        """Hold actuator efforts (scene order, clamped to the scene's limits), N m or N.

        Returns
        -------
        ndarray
            The efforts as applied.
        """
        e = np.asarray(efforts, dtype=float).reshape(-1)
        limits = np.array([a.limit for a in self.model.actuators], dtype=float)
        e = np.clip(e, -limits, limits)
        self.d.ctrl[:] = e
        return e

    def power_in(self) -> float:
        """Actuator power ``tau . qd`` at the current state, W (after :meth:`refresh`)."""
        return float(self.d.qfrc_actuator @ self.d.qvel)

    def step_tick(self) -> None:
        """One control tick (``substeps`` MuJoCo steps), unchecked: what is timed."""
        self.mj.mj_step(self.m, self.d, nstep=self.substeps)

    def advance(self) -> None:
        """One control tick, then the divergence check.

        Raises
        ------
        DivergenceError
            When MuJoCo reported a bad acceleration (it then resets its state) or the state is no
            longer finite.
        """
        self.step_tick()
        self.ticks += 1
        self.t = self.ticks * self.dt
        self.check()

    def check(self) -> None:
        """Raise :class:`DivergenceError` if MuJoCo reported instability since the start."""
        if self.d.warning[self._badqacc].number > 0 or not (
            np.all(np.isfinite(self.d.qpos)) and np.all(np.isfinite(self.d.qvel))
        ):
            raise DivergenceError(
                self.t,
                "MuJoCo reported a bad acceleration (mjWARN_BADQACC) and reset its state",
                None,
                "constraint stiffness (solref) against the step, or the step too large",
            )

    def refresh(self) -> None:
        """Recompute derived quantities (positions, energy) at the current state."""
        self.mj.mj_forward(self.m, self.d)

    def link_ends(self) -> np.ndarray:
        """End point of every link, shape (n, 2), m."""
        return self.d.site_xpos[self._ends, :2].copy()

    def points(self) -> np.ndarray:
        """Named points (chain tips first), shape (n_points, 2), m."""
        return self.d.site_xpos[self._points, :2].copy()

    def closure_errors(self) -> np.ndarray:
        """Distance between the two sides of every closure, shape (k,), m."""
        if not len(self._cl_a):
            return np.zeros(0)
        diff = self.d.site_xpos[self._cl_a] - self.d.site_xpos[self._cl_b]
        return np.linalg.norm(diff, axis=1)

    def energy(self) -> tuple[float, float]:
        """Kinetic and potential (gravity) energy at the current state, J (after :meth:`refresh`)."""
        return float(self.d.energy[1]), float(self.d.energy[0])
