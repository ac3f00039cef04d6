"""MJCF (MuJoCo's XML) of a scene: bodies nested per chain, closures as equality constraints.

The one MJCF writer of the package: ``vjm export --mjcf`` writes it and the MuJoCo side of
``vjm bench`` (:mod:`vjm_ros.studies.compare_mujoco`) runs it. Geometry, masses, inertias and
gravity are the scene's (docs/design.md section 1):

* one body per link, nested along its chain and placed at the scene's initial pose, its frame
  the link frame (origin ``O_i``, x along ``u(theta_i)``); a revolute joint is a ``hinge`` about
  z at the link origin, a prismatic joint a ``slide`` along ``n(theta_pred)``, each with the
  scene's joint name and ``ref`` = its initial coordinate, so that ``qpos`` *is* the scene's
  joint coordinate (zero where the scene's is zero) and ``qpos0`` the initial state;
* the link's mass at its mass centre ``(p, q)``; MuJoCo needs positive masses and principal
  inertias, so ``mass = max(m, eps)`` and ``diaginertia = (I/2 + eps, I/2 + eps, I + eps)``
  with ``eps`` = :attr:`MjcfSettings.inertia_epsilon` (1e-12: a point mass of the thesis scenes
  stays a point mass to 1e-10 relative); ``I/2`` about x and y is a thin lamina in the plane;
* a joint's ``damping`` and ``armature`` as MuJoCo's, its Coulomb ``friction`` as MuJoCo's
  ``frictionloss`` (a soft friction constraint: sticking within MuJoCo's ``solref``/``solimp``;
  the smooth ``tanh`` model has no MuJoCo counterpart and is written the same way);
* a joint's ``range`` (hard stops) as MuJoCo's ``range`` (``qpos`` is the coordinate), the stop
  a soft limit (:data:`STOP_TIME_STEPS`) whose damping ratio would give the scene's
  ``restitution`` to a linear spring-damper (:func:`stop_damping_ratio`): vjm's stop is an
  impact, MuJoCo's a soft unilateral constraint, so rebounds agree only roughly;
* gravity ``(g_x, g_y, 0)``, the plane being MuJoCo's x-y plane; ``<option>`` sets the step and
  integrator; contacts are off (``<flag contact="disable">``) and the geoms (capsules along the
  links, for MuJoCo's viewer) carry no mass (``inertiafromgeom="false"``);
* ``hinge`` closure: ``<connect>`` between the two bodies (or the world), anchor at the closure
  point in the point's body; MuJoCo puts the other side where the point is at ``qpos0``;
* ``slider`` closure (point on a line, rotation free): a carriage body (mass
  :func:`carriage_mass`, see :data:`CARRIAGE_MASS_RATIO`) on a
  ``slide`` joint ``<closure>_slide`` along the line, inside the body that carries the line (or
  the world), and a ``<connect>`` of the point to the carriage;
* ``angle`` closure (relative angle fixed, translation free): a carriage (the same mass) on two
  ``slide`` joints ``<closure>_x``, ``<closure>_y`` along the reference's axes and a
  ``<weld>`` of the link to it;
* each actuator a ``<motor>`` on its joint, ``gear`` its gear (joint effort = gear x control),
  ``ctrlrange`` its limit (none when unlimited); an actuator with a lag is a ``<general>``
  actuator with ``dyntype="filterexact"`` and ``dynprm`` its time constant, one with a delay
  has MuJoCo's ``delay`` (plus a quarter step: MuJoCo's force over the step from ``t`` takes
  the control of about ``t + h - delay``) and the ``nsample`` history it needs;
* a keyframe ``initial`` with the initial ``qpos`` and ``qvel`` (carriage rates included):
  ``mj_resetDataKeyframe(m, d, 0)`` starts the scene;
* sites at every link end (``end_<link>``), named point (``pt_<point>``) and both sides of
  every closure (``cl_<closure>_a`` on the point's body, ``cl_<closure>_b`` on the target, the
  carriage for slider and angle closures), from which positions are read as from vjm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from vjm_ros.core.model import ANGLE, GROUND, HINGE, REVOLUTE, SLIDER, Model
from vjm_ros.core.readers import forward_kinematics
from vjm_ros.formats.urdf_out import number, numbers
from vjm_ros.scene.plant import ActuatorDynamics, Plant

if TYPE_CHECKING:
    import mujoco

DEFAULT_SOLREF = (0.02, 1.0)
"""MuJoCo's default ``solref``: time constant 0.02 s, damping ratio 1."""
DEFAULT_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
"""MuJoCo's default ``solimp``."""
LIMIT_UNBOUNDED = 1e9
"""The missing side of a one-sided range (MuJoCo's ``range`` takes two numbers), rad or m."""
STOP_TIME_STEPS = 10
"""A stop's ``solreflimit`` time constant in MuJoCo steps. MuJoCo's stop is a soft unilateral
spring-damper: at 2 steps (its stiffest) RK4 overshoots the rebound of lightly damped stops
(restitution 0.8 gave 1.3), at 10 it stays within about 0.15 of the restitution for 0 to 0.8
(a free slider at 1 m/s, 0.25 and 1 ms steps: 0.13-0.14 for 0, 0.53-0.57 for 0.5, 0.74-0.79
for 0.8)."""
MIN_STOP_DAMPING = 0.05
"""Smallest stop damping ratio written (restitution 0.85 and above): MuJoCo diverged on an
undamped stop."""
INITIAL_KEY = "initial"
"""Name of the keyframe that holds the scene's initial state."""


@dataclass(frozen=True)
class MjcfSettings:
    """Solver settings written into the MJCF.

    Attributes
    ----------
    timestep : float
        MuJoCo step, s.
    integrator : str
        ``"Euler"``, ``"implicitfast"``, ``"implicit"`` or ``"RK4"``.
    solref : tuple of float
        Equality ``solref``: ``(timeconst, dampratio)`` or, both negative,
        ``(-stiffness, -damping)``.
    solimp : tuple of float
        Equality ``solimp`` (5 numbers).
    inertia_epsilon : float
        Added to every principal inertia, and the smallest mass, kg m^2 and kg.
    carriage_mass : float or None
        Mass (and principal inertias, kg m^2) of the slider and angle closures' carriages, kg;
        None: :data:`CARRIAGE_MASS_RATIO` times the lightest link's mass.
    """

    timestep: float = 0.001
    integrator: str = "RK4"
    solref: tuple[float, ...] = DEFAULT_SOLREF
    solimp: tuple[float, ...] = DEFAULT_SOLIMP
    inertia_epsilon: float = 1e-12
    carriage_mass: float | None = None


CARRIAGE_MASS_RATIO = 1e-3
"""Default carriage mass over the lightest link's. MuJoCo softens an equality by the inverse
mass of its bodies at ``qpos0`` (``body_invweight0``): with a carriage of negligible mass a slider
closure would not hold (a 1e-12 kg carriage let double_slider's tip leave its line by 16 mm in
0.2 s at ``solref = (-1e7, -2e3)``, ``solimp`` 0.9999). A thousandth of the lightest link holds it
(to 1e-7 m there) and changes the dynamics by about that fraction; :func:`stiffen_carriages`
gives carriages of negligible mass the weight of their link instead, for exact comparisons."""


def carriage_mass(model: Model, settings: MjcfSettings) -> float:
    """Mass of the closures' carriages for ``settings``, kg."""
    if settings.carriage_mass is not None:
        return float(settings.carriage_mass)
    masses = [lk.mass for lk in model.links if lk.mass > 0.0]
    return CARRIAGE_MASS_RATIO * min(masses) if masses else settings.inertia_epsilon


def stiffen_carriages(mj_model: mujoco.MjModel, model: Model) -> None:
    """Give each carriage the constraint weight (``body_invweight0``) of its closure's link.

    MuJoCo's regularization of an equality grows with its bodies' inverse masses at ``qpos0``;
    a carriage of negligible mass would make its closure soft. Copying the link's weights makes
    MuJoCo treat the closure as one between the links themselves, while the carriage's mass
    stays negligible. Call after compiling, before stepping.

    Parameters
    ----------
    mj_model : mujoco.MjModel
        Compiled from :func:`scene_mjcf` of ``model``.
    model : Model
    """
    import mujoco

    body = mujoco.mjtObj.mjOBJ_BODY
    for cl in model.closures:
        if cl.kind == HINGE:
            continue
        carriage = mujoco.mj_name2id(mj_model, body, f"{cl.name}_carriage")
        link = mujoco.mj_name2id(mj_model, body, model.links[cl.point.link].name)
        mj_model.body_invweight0[carriage] = mj_model.body_invweight0[link]


def scene_mjcf(model: Model, settings: MjcfSettings | None = None,
               plant: Plant | None = None) -> str:
    """MJCF text of a scene model.

    Parameters
    ----------
    model : Model
        Any scene: revolute and prismatic joints, hinge, slider and angle closures.
    settings : MjcfSettings, optional
    plant : Plant, optional
        The scene's actuator dynamics (``Scene.plant``): gears, lags and delays.

    Returns
    -------
    str

    Raises
    ------
    ValueError
        When a carriage's name clashes with a link of the scene.
    """
    s = settings or MjcfSettings()
    names = set(model.link_names) | set(model.joint_names)
    for cl in model.closures:
        for extra in _extra_names(cl):
            if extra in names:
                raise ValueError(f"'{extra}' clashes with the carriage of closure '{cl.name}'")
    q, qd = model.initial_state()
    writer = _Writer(model, s, q, qd)
    g = model.gravity
    eq = f'solref="{numbers(*s.solref)}" solimp="{numbers(*s.solimp)}"'
    lines = [
        f'<mujoco model="{model.name}">',
        '  <compiler angle="radian" inertiafromgeom="false" autolimits="true"/>',
        f'  <option timestep="{number(s.timestep)}" integrator="{s.integrator}" '
        f'gravity="{numbers(g[0], g[1], 0.0)}">',
        '    <flag contact="disable" energy="enable"/>',
        "  </option>",
        "  <default>",
        '    <geom contype="0" conaffinity="0" rgba="0.2 0.4 0.8 1"/>',
        "  </default>",
        "  <worldbody>",
    ]
    lines += writer.carried(GROUND, "    ")
    for chain in model.chains:
        lines += writer.chain(chain)
    lines.append("  </worldbody>")
    if model.closures:
        lines.append("  <equality>")
        for cl in model.closures:
            body1 = model.links[cl.point.link].name
            if cl.kind == HINGE:
                body2 = "world" if cl.target.link == GROUND else model.links[cl.target.link].name
                lines.append(f'    <connect name="{cl.name}" body1="{body1}" body2="{body2}" '
                             f'anchor="{numbers(*cl.point.local, 0.0)}" {eq}/>')
            elif cl.kind == SLIDER:
                lines.append(f'    <connect name="{cl.name}" body1="{body1}" '
                             f'body2="{cl.name}_carriage" '
                             f'anchor="{numbers(*cl.point.local, 0.0)}" {eq}/>')
            else:
                lines.append(f'    <weld name="{cl.name}" body1="{body1}" '
                             f'body2="{cl.name}_carriage" {eq}/>')
        lines.append("  </equality>")
    if model.actuators:
        lines.append("  <actuator>")
        dynamics = (plant.actuators if plant is not None else ()) or (
            (ActuatorDynamics(),) * len(model.actuators))
        for a, dyn in zip(model.actuators, dynamics, strict=True):
            lines.append("    " + _actuator(model.joints[a.joint].name, a.limit, dyn, s.timestep))
        lines.append("  </actuator>")
    lines += [
        "  <keyframe>",
        f'    <key name="{INITIAL_KEY}" qpos="{numbers(*writer.qpos)}" '
        f'qvel="{numbers(*writer.qvel)}"/>',
        "  </keyframe>",
        "</mujoco>",
    ]
    return "\n".join(lines) + "\n"


def _actuator(joint: str, limit: float, dyn: ActuatorDynamics, timestep: float) -> str:
    """A ``motor`` (or a ``general`` actuator with a ``filter`` for a lag) on ``joint``: force =
    gear x control, the control bounded by the scene's limit, delayed by ``delay``."""
    attrs = f'name="{joint}" joint="{joint}" gear="{number(dyn.gear)}"'
    if math.isfinite(limit):
        attrs += f' ctrlrange="{numbers(-limit, limit)}"'
    if dyn.delay > 0.0:
        # MuJoCo's force in the step from t takes the control of about t + h - delay: a quarter
        # step more starts the effort ``delay`` after the command, as in vjm, clear of rounding
        delay = dyn.delay + timestep / 4
        attrs += f' delay="{number(delay)}" nsample="{int(math.ceil(delay / timestep)) + 2}"'
    if dyn.time_constant > 0.0:
        return (f'<general {attrs} dyntype="filterexact" dynprm="{number(dyn.time_constant)}" '
                f'gainprm="1" biastype="none"/>')
    return f"<motor {attrs}/>"


def _joint_plant(joint, settings: MjcfSettings) -> str:
    """MuJoCo joint attributes of the scene joint's damping, armature and Coulomb friction
    (the friction constraint as stiff as the equalities: ``solreffriction``, ``solimpfriction``)."""
    attrs = ""
    for key, attr in (("damping", "damping"), ("armature", "armature"),
                      ("friction", "frictionloss")):
        value = float(getattr(joint, key))
        if value:
            attrs += f' {attr}="{number(value)}"'
    if joint.friction:
        attrs += (f' solreffriction="{numbers(*settings.solref)}" '
                  f'solimpfriction="{numbers(*settings.solimp)}"')
    lo, hi = joint.range
    if math.isfinite(lo) or math.isfinite(hi):
        lower = lo if math.isfinite(lo) else -LIMIT_UNBOUNDED
        upper = hi if math.isfinite(hi) else LIMIT_UNBOUNDED
        zeta = stop_damping_ratio(float(joint.restitution))
        attrs += (f' range="{numbers(lower, upper)}" '
                  f'solreflimit="{numbers(STOP_TIME_STEPS * settings.timestep, zeta)}" '
                  f'solimplimit="{numbers(*settings.solimp)}"')
    return attrs


def stop_damping_ratio(restitution: float) -> float:
    """Damping ratio of a spring-damper stop whose rebound speed is ``restitution`` times the
    impact speed: ``e = exp(-zeta pi / sqrt(1 - zeta^2))``, so ``zeta = -ln e / sqrt(pi^2 +
    ln^2 e)``; 1 (critical: no rebound) for ``e = 0``, at least :data:`MIN_STOP_DAMPING`."""
    if restitution <= 0.0:
        return 1.0
    log_e = math.log(min(restitution, 1.0))
    return max(-log_e / math.sqrt(math.pi * math.pi + log_e * log_e), MIN_STOP_DAMPING)


def _extra_names(closure) -> list[str]:
    if closure.kind == SLIDER:
        return [f"{closure.name}_carriage", f"{closure.name}_slide"]
    if closure.kind == ANGLE:
        return [f"{closure.name}_carriage", f"{closure.name}_x", f"{closure.name}_y"]
    return []


class _Writer:
    """Bodies, in the order MuJoCo numbers joints (depth first), with qpos0 and qvel."""

    def __init__(self, model: Model, settings: MjcfSettings, q: np.ndarray, qd: np.ndarray):
        self.model = model
        self.settings = settings
        self.eps = float(settings.inertia_epsilon)
        self.carriage_mass = carriage_mass(model, settings)
        self.q = q
        self.kin = forward_kinematics(model, q, qd)
        self.qpos: list[float] = []
        self.qvel: list[float] = []
        self.qd = qd

    # -------------------------------------------------------------- frames at the initial state
    def _frame(self, link: int) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
        """Origin, rotation, angular velocity and origin velocity of a link (ground: rest)."""
        if link == GROUND:
            return np.zeros(2), np.eye(2), 0.0, np.zeros(2)
        k = self.kin
        return k.origin[link], k.rotation[link], float(k.omega[link]), k.v_origin[link]

    def _point_motion(self, link: int, local) -> tuple[np.ndarray, np.ndarray]:
        """World position and velocity of a link point (ground: ``local`` is world)."""
        o, r, w, v = self._frame(link)
        rel = r @ np.asarray(local, dtype=float)
        return o + rel, v + w * np.array([-rel[1], rel[0]])

    def _in_frame(self, link: int, world: np.ndarray) -> np.ndarray:
        o, r, _, _ = self._frame(link)
        return r.T @ (world - o)

    # -------------------------------------------------------------- chains
    def chain(self, chain) -> list[str]:
        model, theta = self.model, self.kin.theta
        lines = []
        pred_theta = chain.angle
        for pos, i in enumerate(chain.links):
            link, joint = model.links[i], model.joints[i]
            slide = joint.slide if joint.kind == REVOLUTE else self.q[i]
            phi = float(theta[i] - pred_theta)
            indent = "    " + "  " * pos
            if pos == 0:
                th1, a1 = chain.angle, chain.length
                o = (np.asarray(chain.origin, dtype=float)
                     + a1 * np.array([math.cos(th1), math.sin(th1)])
                     + slide * np.array([-math.sin(th1), math.cos(th1)]))
                lines.append(f'{indent}<body name="{link.name}" pos="{numbers(o[0], o[1], 0.0)}" '
                             f'euler="{numbers(0.0, 0.0, theta[i])}">')
            else:
                prev = model.links[chain.links[pos - 1]]
                lines.append(f'{indent}<body name="{link.name}" '
                             f'pos="{numbers(prev.length, slide, 0.0)}" '
                             f'euler="{numbers(0.0, 0.0, phi)}">')
            lines += self._contents(i, phi, indent + "  ")
            pred_theta = float(theta[i])
        for d in range(len(chain.links) - 1, -1, -1):
            lines.append("    " + "  " * d + "</body>")
        return lines

    def _contents(self, i: int, phi: float, inner: str) -> list[str]:
        """Joint, inertial, geom, sites and carriages of link ``i``."""
        model, eps = self.model, self.eps
        link, joint = model.links[i], model.joints[i]
        lines = []
        plant = _joint_plant(joint, self.settings)
        if joint.kind == REVOLUTE:
            lines.append(f'{inner}<joint name="{joint.name}" type="hinge" axis="0 0 1" '
                         f'ref="{number(self.q[i])}"{plant}/>')
        else:
            axis = numbers(math.sin(phi), math.cos(phi), 0.0)
            lines.append(f'{inner}<joint name="{joint.name}" type="slide" axis="{axis}" '
                         f'ref="{number(self.q[i])}"{plant}/>')
        self.qpos.append(float(self.q[i]))
        self.qvel.append(float(self.qd[i]))
        inertia = float(link.inertia)
        lines.append(
            f'{inner}<inertial pos="{numbers(*link.com, 0.0)}" mass="{number(max(link.mass, eps))}" '
            f'diaginertia="{numbers(inertia / 2 + eps, inertia / 2 + eps, inertia + eps)}"/>')
        if link.length > 0.0:
            lines.append(f'{inner}<geom type="capsule" fromto="0 0 0 {number(link.length)} 0 0" '
                         f'size="{number(0.02 * link.length)}"/>')
        lines.append(f'{inner}<site name="end_{link.name}" pos="{numbers(link.length, 0.0, 0.0)}"/>')
        for p in model.points:
            if p.ref.link == i:
                lines.append(f'{inner}<site name="pt_{p.name}" pos="{numbers(*p.ref.local, 0.0)}"/>')
        for cl in model.closures:
            if cl.point.link == i:
                at = cl.point.local if cl.kind != ANGLE else (0.0, 0.0)
                lines.append(f'{inner}<site name="cl_{cl.name}_a" pos="{numbers(*at, 0.0)}"/>')
            if cl.kind == HINGE and cl.target.link == i:
                lines.append(f'{inner}<site name="cl_{cl.name}_b" '
                             f'pos="{numbers(*cl.target.local, 0.0)}"/>')
        lines += self.carried(i, inner)
        return lines

    # -------------------------------------------------------------- carriages and ground sites
    def carried(self, link: int, inner: str) -> list[str]:
        """Carriages of the slider and angle closures whose line or reference ``link`` carries
        (the world for :data:`GROUND`), and ground sites of hinge closures."""
        lines = []
        for cl in self.model.closures:
            if cl.target.link != link:
                continue
            if cl.kind == HINGE and link == GROUND:
                lines.append(f'{inner}<site name="cl_{cl.name}_b" '
                             f'pos="{numbers(*cl.target.local, 0.0)}"/>')
            elif cl.kind == SLIDER:
                lines += self._slider_carriage(cl, link, inner)
            elif cl.kind == ANGLE:
                lines += self._angle_carriage(cl, link, inner)
        return lines

    def _carriage_body(self, name: str, pos: np.ndarray, yaw: float, inner: str) -> str:
        return (f'{inner}<body name="{name}" pos="{numbers(pos[0], pos[1], 0.0)}" '
                f'euler="{numbers(0.0, 0.0, yaw)}">')

    def _carriage_inside(self, cl, inner: str) -> list[str]:
        eps = self.carriage_mass
        return [f'{inner}  <inertial pos="0 0 0" mass="{number(eps)}" '
                f'diaginertia="{numbers(eps, eps, eps)}"/>',
                f'{inner}  <site name="cl_{cl.name}_b" pos="0 0 0"/>',
                f"{inner}</body>"]

    def _slider_carriage(self, cl, link: int, inner: str) -> list[str]:
        """The point's carriage on the line, at the point's initial position."""
        at, v_at = self._point_motion(cl.point.link, cl.point.local)
        d = np.asarray(cl.direction, dtype=float)
        d = d / np.linalg.norm(d)
        _, r, w, _ = self._frame(link)
        _, v_carrier = self._point_motion(link, self._in_frame(link, at))
        rate = float((r @ d) @ (v_at - v_carrier))
        self.qpos.append(0.0)
        self.qvel.append(rate)
        return [self._carriage_body(f"{cl.name}_carriage", self._in_frame(link, at),
                                    math.atan2(d[1], d[0]), inner),
                f'{inner}  <joint name="{cl.name}_slide" type="slide" axis="1 0 0"/>',
                *self._carriage_inside(cl, inner)]

    def _angle_carriage(self, cl, link: int, inner: str) -> list[str]:
        """A carriage at the link's initial origin, free to translate in the reference's axes."""
        at, v_at = self._point_motion(cl.point.link, (0.0, 0.0))
        _, r, _, _ = self._frame(link)
        _, v_carrier = self._point_motion(link, self._in_frame(link, at))
        rel = r.T @ (v_at - v_carrier)
        self.qpos += [0.0, 0.0]
        self.qvel += [float(rel[0]), float(rel[1])]
        return [self._carriage_body(f"{cl.name}_carriage", self._in_frame(link, at), 0.0, inner),
                f'{inner}  <joint name="{cl.name}_x" type="slide" axis="1 0 0"/>',
                f'{inner}  <joint name="{cl.name}_y" type="slide" axis="0 1 0"/>',
                *self._carriage_inside(cl, inner)]
