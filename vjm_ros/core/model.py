"""Static description of a mechanism: chains of links, joints, closures and actuators.

No dynamics here: this module only holds what a scene says, in arrays that the kinematics and
dynamics read. Conventions follow docs/design.md section 1:

* a chain starts at a ground point ``O`` with ground angle ``theta1`` and ground length ``a1``;
* moving link ``i`` follows joint ``i``; the joint sits at the end of the preceding link (or of the
  ground link) and has a slide ``B`` along the preceding link's normal ``n(theta_pred)`` and a
  rotation ``phi = theta_i - theta_pred``; exactly one of the two is active (the existence
  factors), the other is a locked parameter;
* one generalized coordinate per joint: ``phi`` for a revolute joint (rad), ``B`` for a prismatic
  joint (m). Link ``k`` of the whole scene and coordinate ``k`` therefore share an index.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

REVOLUTE = "revolute"
PRISMATIC = "prismatic"
JOINT_KINDS = (REVOLUTE, PRISMATIC)

HINGE = "hinge"
SLIDER = "slider"
ANGLE = "angle"
CLOSURE_KINDS = (HINGE, SLIDER, ANGLE)

GROUND = -1
"""Link index that stands for the ground in :class:`PointRef` and :class:`Closure`."""


@dataclass(frozen=True)
class Link:
    """One moving rigid link.

    Its frame has the origin ``O_i`` at the joint in front of it, ``u(theta_i)`` along the link
    and ``n(theta_i)`` a quarter turn counter-clockwise from ``u``.

    Attributes
    ----------
    name : str
        Unique link name.
    chain : int
        Index of the chain that carries the link.
    length : float
        ``a_i``, distance from the link origin to its end along ``u(theta_i)``, m.
    mass : float
        ``m_i``, kg.
    inertia : float
        ``I_i``, centroidal moment of inertia about z, kg m^2.
    com : tuple of float
        ``(p_i, q_i)``: mass centre at ``O_i + p_i u(theta_i) + q_i n(theta_i)``, m.
    """

    name: str
    chain: int
    length: float  # m
    mass: float  # kg
    inertia: float  # kg m^2
    com: tuple[float, float]  # m, m


@dataclass(frozen=True)
class Joint:
    """The joint in front of a link (between its predecessor and the link).

    Attributes
    ----------
    name : str
        Unique joint name (the name used in ``JointState`` and CSV columns).
    kind : str
        ``"revolute"`` (coordinate: relative angle, rad) or ``"prismatic"`` (slide ``B``, m).
    angle : float
        Initial relative angle ``theta_i - theta_pred``, rad (the locked value if prismatic).
    slide : float
        Initial slide ``B``, m (the locked value if revolute).
    velocity : float
        Initial rate of the active coordinate, rad/s or m/s.
    damping : float
        Viscous damping of the active coordinate, N m s/rad or N s/m: the joint's generalized
        force is ``-damping * rate``.
    armature : float
        Reflected rotor inertia, kg m^2 or kg, added to the mass matrix's diagonal entry of the
        coordinate (its kinetic energy ``armature * rate^2 / 2``).
    friction : float
        Coulomb friction bound, N m or N (0: none).
    friction_scale : float
        0 for sticking friction (:mod:`vjm_ros.core.joint_efforts`), else the velocity scale
        ``v_s`` (rad/s or m/s) of the smooth model ``-friction * tanh(rate / v_s)``.
    range : tuple of float
        Hard stops ``(lo, hi)`` of the coordinate, rad or m (infinite: none).
    restitution : float
        Rebound rate over impact rate at a stop, 0..1.
    """

    name: str
    kind: str
    angle: float
    slide: float
    velocity: float = 0.0
    damping: float = 0.0
    armature: float = 0.0
    friction: float = 0.0
    friction_scale: float = 0.0
    range: tuple[float, float] = (-float("inf"), float("inf"))
    restitution: float = 0.0

    @property
    def position(self) -> float:
        """Initial value of the active coordinate."""
        return self.angle if self.kind == REVOLUTE else self.slide


@dataclass(frozen=True)
class Chain:
    """An open chain rooted at ground.

    Its links follow one another from the ground point ``O``: a link's origin is
    ``O_pred + a_pred u(theta_pred) + B n(theta_pred)``, with ``B`` the slide of the joint in
    front of it (held at its locked value for a revolute joint).

    Attributes
    ----------
    name : str
        Unique chain name.
    origin : tuple of float
        Ground point ``O``, m.
    angle : float
        Ground angle ``theta1``, rad.
    length : float
        Ground length ``a1``, m.
    links : tuple of int
        Global indices of the chain's moving links, base first (contiguous).
    """

    name: str
    origin: tuple[float, float]
    angle: float
    length: float
    links: tuple[int, ...]


@dataclass(frozen=True)
class PointRef:
    """A point on a link, or a fixed point of the ground.

    Attributes
    ----------
    link : int
        Global link index, or :data:`GROUND`.
    local : tuple of float
        ``(s, w)`` in the link frame (``s`` along ``u``, ``w`` along ``n``), m; for the ground, the
        world coordinates ``(x, y)``.
    """

    link: int
    local: tuple[float, float]


@dataclass(frozen=True)
class Closure:
    """A loop-closing condition (docs/design.md section 2).

    Attributes
    ----------
    name : str
        Unique closure name.
    kind : str
        ``"hinge"`` (2 rows), ``"slider"`` (1 row) or ``"angle"`` (1 row).
    point : PointRef
        The constrained point ``Pa`` (hinge, slider); for ``angle`` only ``point.link`` is used.
    target : PointRef
        Hinge: the point ``Pa`` must meet. Slider: a point of the line. Angle: ``target.link`` is the
        reference link or :data:`GROUND`.
    direction : tuple of float
        Slider only: line direction, world frame for a ground line, link frame otherwise (unit).
    offset : float
        Angle only: required ``theta_a - theta_b`` (``theta_b = 0`` for ground), rad.
    """

    name: str
    kind: str
    point: PointRef
    target: PointRef
    direction: tuple[float, float] = (1.0, 0.0)
    offset: float = 0.0

    @property
    def rows(self) -> int:
        """Number of scalar equations of the closure."""
        return 2 if self.kind == HINGE else 1


@dataclass(frozen=True)
class Actuator:
    """An effort source acting on one joint.

    Attributes
    ----------
    joint : int
        Global joint (= coordinate) index.
    limit : float
        Largest admissible ``|effort|``, N m or N (``inf`` when unlimited).
    effort : float
        Default constant effort used by ``vjm run``, N m or N.
    """

    joint: int
    limit: float = float("inf")
    effort: float = 0.0


@dataclass(frozen=True)
class Load:
    """A constant external load on a link: a force fixed in the world frame at a point of the
    link, and a torque about z.

    Both are conservative (a constant force and a constant torque): their potential
    ``-(F . P + torque * theta)`` is part of the potential energy.

    Attributes
    ----------
    name : str
        Unique load name.
    point : PointRef
        Where the force acts (a moving link; the ground carries no load).
    force : tuple of float
        ``(fx, fy)`` in the world frame, N.
    torque : float
        About z, N m.
    """

    name: str
    point: PointRef
    force: tuple[float, float] = (0.0, 0.0)
    torque: float = 0.0


@dataclass(frozen=True)
class NamedPoint:
    """A point whose world position is reported (``x.<name>``, ``y.<name>``)."""

    name: str
    ref: PointRef


@dataclass
class Model:
    """Frozen description of one scene, with the index arrays the kinematics use.

    Build it with :meth:`Model.build`; do not mutate after construction.

    Attributes
    ----------
    name : str
        Scene name.
    chains, links, joints, closures, actuators, points : tuple
        The parts, see the dataclasses above. ``links[k]`` and ``joints[k]`` belong together.
    gravity : ndarray, shape (2,)
        Gravity acceleration vector, m/s^2.
    n : int
        Number of generalized coordinates (= moving links = joints).
    is_revolute : ndarray of bool, shape (n,)
    ancestors : ndarray of float, shape (n, n)
        ``ancestors[i, k] = 1`` when joint ``k`` moves link ``i`` (``k`` is ``i`` or precedes it in
        the same chain).
    stop_joints : ndarray of int64, shape (s,)
        The joints with a ``range`` (a stop at one end at least), in joint order.
    """

    name: str
    chains: tuple[Chain, ...]
    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    closures: tuple[Closure, ...]
    actuators: tuple[Actuator, ...]
    points: tuple[NamedPoint, ...]
    gravity: np.ndarray
    source_text: str = ""
    extras: dict = field(default_factory=dict)
    loads: tuple[Load, ...] = ()

    # derived arrays (filled by build)
    n: int = 0
    is_revolute: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    ancestors: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    chain_of: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    first_of_chain: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    base_origin: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    base_angle: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    pred_length: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    length: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    mass: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    inertia: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    com: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    locked_angle: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    locked_slide: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    damping: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    armature: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    friction: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    friction_scale: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    range_lo: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    range_hi: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    restitution: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    stop_joints: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    _plant_terms: bool = field(default=False, repr=False)
    _joint_efforts: bool = field(default=False, repr=False)

    @classmethod
    def build(
        cls,
        name: str,
        chains: tuple[Chain, ...],
        links: tuple[Link, ...],
        joints: tuple[Joint, ...],
        closures: tuple[Closure, ...] = (),
        actuators: tuple[Actuator, ...] = (),
        points: tuple[NamedPoint, ...] = (),
        gravity: tuple[float, float] = (0.0, -9.81),
        source_text: str = "",
        extras: dict | None = None,
        loads: tuple[Load, ...] = (),
    ) -> Model:
        """Assemble a model and derive its index arrays.

        Parameters
        ----------
        name : str
            Scene name.
        chains, links, joints, closures, actuators, points : sequence
            The parts; ``links`` and ``joints`` are ordered chain by chain, base first.
        gravity : tuple of float
            Gravity vector, m/s^2.
        source_text : str
            The scene text the model was read from (kept for log attachments).
        extras : dict, optional
            Free-form scene metadata (description, provenance, defaults).
        loads : sequence of Load
            Constant external loads.

        Returns
        -------
        Model
        """
        model = cls(
            name=name,
            chains=tuple(chains),
            links=tuple(links),
            joints=tuple(joints),
            closures=tuple(closures),
            actuators=tuple(actuators),
            points=tuple(points),
            gravity=np.asarray(gravity, dtype=float),
            source_text=source_text,
            extras=dict(extras or {}),
            loads=tuple(loads),
        )
        n = len(links)
        if len(joints) != n:
            raise ValueError("one joint per link is required")
        model.n = n
        model.is_revolute = np.array([j.kind == REVOLUTE for j in joints], dtype=bool)
        anc = np.zeros((n, n))
        chain_of = np.zeros(n, dtype=int)
        first = np.zeros(n, dtype=bool)
        base_origin = np.zeros((n, 2))
        base_angle = np.zeros(n)
        pred_length = np.zeros(n)
        for c, chain in enumerate(model.chains):
            idx = list(chain.links)
            if idx != list(range(idx[0], idx[0] + len(idx))) if idx else False:
                raise ValueError(f"links of chain {chain.name} must be contiguous")
            for pos, i in enumerate(idx):
                chain_of[i] = c
                base_origin[i] = chain.origin
                base_angle[i] = chain.angle
                anc[i, idx[: pos + 1]] = 1.0
                first[i] = pos == 0
                pred_length[i] = chain.length if pos == 0 else links[idx[pos - 1]].length
        model.ancestors = anc
        model.chain_of = chain_of
        model.first_of_chain = first
        model.base_origin = base_origin
        model.base_angle = base_angle
        model.pred_length = pred_length
        model.length = np.array([lk.length for lk in links], dtype=float)
        model.mass = np.array([lk.mass for lk in links], dtype=float)
        model.inertia = np.array([lk.inertia for lk in links], dtype=float)
        model.com = np.array([lk.com for lk in links], dtype=float).reshape(n, 2)
        model.locked_angle = np.array([j.angle for j in joints], dtype=float)
        model.locked_slide = np.array([j.slide for j in joints], dtype=float)
        model.damping = np.array([j.damping for j in joints], dtype=float)
        model.armature = np.array([j.armature for j in joints], dtype=float)
        model.friction = np.array([j.friction for j in joints], dtype=float)
        model.friction_scale = np.array([j.friction_scale for j in joints], dtype=float)
        model.range_lo = np.array([j.range[0] for j in joints], dtype=float)
        model.range_hi = np.array([j.range[1] for j in joints], dtype=float)
        model.restitution = np.array([j.restitution for j in joints], dtype=float)
        sticking = (model.friction > 0) & (model.friction_scale == 0)
        model._plant_terms = bool(
            model.loads or np.any(model.damping) or np.any(model.armature)
            or np.any((model.friction > 0) & (model.friction_scale > 0)))
        model.stop_joints = np.flatnonzero(np.isfinite(model.range_lo)
                                           | np.isfinite(model.range_hi))
        model._joint_efforts = bool(np.any(sticking) or model.stop_joints.size)
        return model

    @property
    def has_plant_terms(self) -> bool:
        """True when a joint has damping, armature or smooth friction, or the scene has loads
        (found once by :meth:`build`)."""
        return self._plant_terms

    @property
    def has_joint_efforts(self) -> bool:
        """True when a joint has sticking Coulomb friction or a stop
        (:mod:`vjm_ros.core.joint_efforts`; found once by :meth:`build`)."""
        return self._joint_efforts

    # ------------------------------------------------------------------ names and lookups
    @property
    def joint_names(self) -> list[str]:
        """Joint names in coordinate order."""
        return [j.name for j in self.joints]

    @property
    def link_names(self) -> list[str]:
        """Link names in coordinate order."""
        return [lk.name for lk in self.links]

    @property
    def closure_names(self) -> list[str]:
        """Closure names in scene order."""
        return [c.name for c in self.closures]

    @property
    def force_names(self) -> list[str]:
        """Names of the constraint forces the outputs report: every closure in scene order, then
        the stop of each joint with a ``range``, ``<joint>_stop``, in joint order."""
        return self.closure_names + [f"{self.joints[j].name}_stop" for j in self.stop_joints]

    @property
    def force_is_moment(self) -> list[bool]:
        """Per entry of :attr:`force_names`: True where the force is a moment ``Mz`` (an angle
        closure, the stop of a revolute joint), False where it is a force ``(Fx, Fy)``."""
        return ([c.kind == ANGLE for c in self.closures]
                + [bool(self.is_revolute[j]) for j in self.stop_joints])

    @property
    def actuator_names(self) -> list[str]:
        """Names of the actuated joints in actuator order."""
        return [self.joints[a.joint].name for a in self.actuators]

    @property
    def n_rows(self) -> int:
        """Total number of scalar closure equations."""
        return sum(c.rows for c in self.closures)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Initial generalized coordinates and rates.

        Returns
        -------
        q : ndarray, shape (n,)
            rad for revolute joints, m for prismatic joints.
        qd : ndarray, shape (n,)
        """
        q = np.array([j.position for j in self.joints], dtype=float)
        qd = np.array([j.velocity for j in self.joints], dtype=float)
        return q, qd

    def actuator_matrix(self) -> np.ndarray:
        """Selection matrix mapping actuator efforts to generalized forces.

        Returns
        -------
        ndarray, shape (n, n_actuators)
        """
        s = np.zeros((self.n, len(self.actuators)))
        for k, a in enumerate(self.actuators):
            s[a.joint, k] = 1.0
        return s

    def without_plant_terms(self) -> Model:
        """This model without joint damping, armature, friction, stops and loads (itself when it
        has none)."""
        if not (self.has_plant_terms or self.has_joint_efforts):
            return self
        joints = tuple(replace(j, damping=0.0, armature=0.0, friction=0.0,
                               range=(-float("inf"), float("inf"))) for j in self.joints)
        return Model.build(self.name, self.chains, self.links, joints, self.closures,
                           self.actuators, self.points, tuple(self.gravity), self.source_text,
                           self.extras)

    def with_state(self, q: np.ndarray, qd: np.ndarray) -> Model:
        """A copy whose initial joint values (and locked parameters) are ``q``, ``qd``.

        Locked coordinates keep their values; only the active ones change.
        """
        joints = []
        for j, qi, vi in zip(self.joints, q, qd, strict=True):
            if j.kind == REVOLUTE:
                joints.append(replace(j, angle=float(qi), velocity=float(vi)))
            else:
                joints.append(replace(j, slide=float(qi), velocity=float(vi)))
        return Model.build(
            self.name,
            self.chains,
            self.links,
            tuple(joints),
            self.closures,
            self.actuators,
            self.points,
            tuple(self.gravity),
            self.source_text,
            self.extras,
            self.loads,
        )
