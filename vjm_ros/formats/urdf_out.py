"""URDF of a scene: the cut chains as a tree, the closures as SDFormat joints in ``<gazebo>``.

URDF describes trees only, so the scene's chains are written as they are (docs/design.md
section 1) and its closures as SDFormat joints inside a ``<gazebo>`` element, the way Gazebo's
kinematic-loop tutorial closes a four-bar (Gazebo copies that element into the SDFormat model it
converts the URDF to). ``robot_state_publisher`` and RViz read the tree and ignore the rest.

The tree:

* a root link :data:`ROOT_LINK` (``world``, the frame of the node's markers) for the ground, with
  the chains' ground links, ground pins and slider lines drawn on it;
* one URDF link per scene link, its frame the scene's link frame: origin ``O_i``, x along
  ``u(theta_i)``, z out of the plane;
* one URDF joint per scene joint, with the scene's joint name, so that a URDF joint position is
  the scene's joint coordinate (``joint_states`` drive ``robot_state_publisher`` as they are).
  A revolute joint between link ``p`` and link ``i`` has origin ``xyz = (a_p, B, 0)`` (``B`` its
  locked slide), ``rpy = 0`` and axis ``z``: its position is ``theta_i - theta_p``. A prismatic
  joint has origin ``xyz = (a_p, 0, 0)``, ``rpy = (0, 0, phi)`` (``phi`` its locked relative
  angle) and axis ``n(theta_p)`` in the joint frame, ``(sin phi, cos phi, 0)``: its position is
  ``B``. A chain's first joint hangs from the root at ``O + a_1 u(theta_1)`` with the yaw
  ``theta_1`` added. Joints without a range are ``continuous`` (revolute) or ``prismatic`` with
  the bounds ``-UNBOUNDED, UNBOUNDED`` (URDF has no infinite value).

The URDF's zero pose is therefore ``q = 0``, where the closures need not hold. Gazebo builds a
closure joint at the pose it loads a model in, so for Gazebo write the file with
``zero="initial"``: each joint origin then takes in the scene's initial coordinate, the zero
pose is the scene's (closed) initial state and a URDF position is ``q - q0``.

A joint's viscous ``damping`` and Coulomb ``friction`` are its ``<dynamics>`` (URDF has no
armature); a revolute joint with a ``range`` (hard stops) is ``revolute`` with ``lower`` and
``upper`` the range in the file's positions (a missing side ``UNBOUNDED``), a prismatic joint's
range its bounds; a stop's restitution has no URDF element. Inertials: mass ``m_i`` at ``(p_i, q_i, 0)``, ``izz = I_i`` (centroidal, about z); ``ixx = iyy =
I_i / 2``, the inertia of a thin lamina in the plane (perpendicular-axis theorem), which is valid
(triangle inequality) and plays no part in planar motion. Links without mass get no
``<inertial>`` (URDF's default: massless).

Visuals: a box along each link from ``O_i`` to its end, a cylinder at each revolute joint, bars
from the link origin to points carried off the link's axis (closure points, named points).

Closures (``<gazebo>``):

* ``hinge``: an SDFormat ``revolute`` joint (axis z) with the target's link (or ``world``) as
  parent and the point's link as child, its ``<pose>`` the point in the child frame;
* ``slider`` (a point on a line: one row, rotation free): SDFormat has no such joint, so a
  carriage link of negligible mass (:data:`CARRIAGE_MASS`) slides along the line on a
  ``prismatic`` joint ``<closure>_slide`` and carries the point on a ``revolute`` joint named
  after the closure;
* ``angle`` (a fixed relative angle, translation free): a carriage slides along the reference
  link's x (``prismatic`` joint ``<closure>_x``) and carries the link on a ``prismatic`` joint
  named after the closure along the reference's y: two slides, no rotation.

Actuators and the initial state are in a ``<ros2_control>`` element: every joint has
``position`` and ``velocity`` state interfaces whose ``initial_value`` is the scene's initial
state (in the file's joint positions), and every actuated joint an ``effort`` command interface
with ``min``/``max`` its largest joint effort (gear times the command's limit), which is also the
joint's ``<limit effort>`` (0 on a passive joint). An actuator's lag and delay have no URDF
element and are not written.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np

from vjm_ros.core.model import ANGLE, GROUND, HINGE, REVOLUTE, SLIDER, Model
from vjm_ros.core.readers import forward_kinematics
from vjm_ros.scene.plant import Plant

ROOT_LINK = "world"
"""Name of the root link (the ground), the node's marker frame."""

UNBOUNDED = 1e9
"""Stands for "no limit" where URDF requires a number (slide range, effort, velocity), SI."""

CARRIAGE_MASS = 1e-9
"""Mass of a closure's carriage link in ``<gazebo>`` (SDFormat links need one), kg."""

ZERO_POSES = ("coordinates", "initial")
"""Where the URDF's zero pose is: at ``q = 0`` (positions = coordinates) or the initial state."""


def number(x: float) -> str:
    """Shortest text that reads back as the same double (``repr``), ``-0`` written ``0``."""
    x = float(x)
    return "0" if x == 0.0 else repr(x)


def numbers(*xs: float) -> str:
    """Several numbers separated by spaces."""
    return " ".join(number(x) for x in xs)


def scene_urdf(model: Model, zero: str = "coordinates", plant: Plant | None = None) -> str:
    """URDF text of a scene model.

    Parameters
    ----------
    model : Model
        The scene; its initial state is written as ``<ros2_control>`` initial values.
    zero : str
        ``"coordinates"``: URDF positions are the scene's joint coordinates (what the node's
        ``joint_states`` and ``robot_description`` use). ``"initial"``: the zero pose is the
        scene's initial state (for Gazebo), positions are ``q - q0``.
    plant : Plant, optional
        The scene's actuator dynamics (``Scene.plant``): effort bounds are the joint's, gear
        times the command's limit (lags and delays have no URDF element).

    Returns
    -------
    str
        The URDF document, UTF-8 XML with a declaration.

    Raises
    ------
    ValueError
        When ``zero`` is not one of :data:`ZERO_POSES` or a scene name clashes with
        :data:`ROOT_LINK` or a closure's construction.
    """
    if zero not in ZERO_POSES:
        raise ValueError(f"zero pose: expected one of {', '.join(ZERO_POSES)}, found {zero!r}")
    _check_names(model)
    q0, _ = model.initial_state()
    offset = q0 if zero == "initial" else np.zeros(model.n)
    robot = ET.Element("robot", name=model.name)
    robot.append(ET.Comment(
        f" scene {model.name} written by vjm export: link frames as the scene's (origin at the "
        f"link origin, x along the link, z out of the plane); joint positions are "
        f"{'the joint coordinates' if zero == 'coordinates' else 'q - q0 (zero pose = initial state)'} "))
    size = _scale(model)
    robot.append(_material("link", "0.2 0.4 0.8 1"))
    robot.append(_material("ground", "0.4 0.4 0.4 1"))
    robot.append(_root_link(model, size))
    efforts = _effort_limits(model, plant)
    for i in range(model.n):
        robot.append(_link(model, i, size))
        robot.append(_joint(model, i, float(offset[i]), efforts[i]))
    robot.append(_ros2_control(model, q0 - offset, efforts))
    if model.closures:
        robot.append(_gazebo(model, offset, zero))
    ET.indent(robot, space="  ")
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def _check_names(model: Model) -> None:
    """Refuse names the file would hold twice (SDFormat joints and links share the model)."""
    links, joints = set(model.link_names), set(model.joint_names)
    if ROOT_LINK in links:
        raise ValueError(f"link '{ROOT_LINK}': the URDF's root link has this name; rename the link")
    for cl in model.closures:
        carriage = f"{cl.name}_carriage"
        if cl.kind != HINGE and carriage in links:
            raise ValueError(f"link '{carriage}' clashes with the carriage of closure '{cl.name}'")
        suffixes = {HINGE: [""], SLIDER: ["", "_slide"], ANGLE: ["", "_x"]}[cl.kind]
        for extra in (cl.name + s for s in suffixes):
            if extra in joints:
                raise ValueError(f"joint '{extra}' clashes with the SDFormat joint of closure "
                                 f"'{cl.name}'; rename the joint or the closure")


def _scale(model: Model) -> float:
    """A drawing width for the scene, m: 4 % of its typical link length (at least 5 mm)."""
    lengths = [lk.length for lk in model.links if lk.length > 0]
    lengths += [c.length for c in model.chains if c.length > 0]
    typical = float(np.median(lengths)) if lengths else 0.5
    return max(0.04 * typical, 0.005)


def _material(name: str, rgba: str) -> ET.Element:
    m = ET.Element("material", name=name)
    ET.SubElement(m, "color", rgba=rgba)
    return m


def _origin(parent: ET.Element, xyz=(0.0, 0.0, 0.0), yaw: float = 0.0) -> None:
    ET.SubElement(parent, "origin", xyz=numbers(*xyz), rpy=numbers(0.0, 0.0, yaw))


def _bar(parent: ET.Element, start, end, width: float, material: str) -> None:
    """A box visual from ``start`` to ``end`` (link-frame points, m) of section ``width``."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    d = end - start
    length = float(np.hypot(*d))
    if length <= 0.0:
        return
    v = ET.SubElement(parent, "visual")
    mid = (start + end) / 2
    _origin(v, (mid[0], mid[1], 0.0), math.atan2(d[1], d[0]))
    g = ET.SubElement(v, "geometry")
    ET.SubElement(g, "box", size=numbers(length, width, width))
    ET.SubElement(v, "material", name=material)


def _pin(parent: ET.Element, at, width: float, material: str) -> None:
    """A cylinder visual along z at ``at`` (link-frame point, m)."""
    v = ET.SubElement(parent, "visual")
    _origin(v, (at[0], at[1], 0.0))
    g = ET.SubElement(v, "geometry")
    ET.SubElement(g, "cylinder", radius=number(width), length=number(2 * width))
    ET.SubElement(v, "material", name=material)


def _root_link(model: Model, size: float) -> ET.Element:
    """The ground: chains' ground links, ground pins and ground slider lines as visuals."""
    root = ET.Element("link", name=ROOT_LINK)
    for chain in model.chains:
        o = np.asarray(chain.origin, dtype=float)
        end = o + chain.length * np.array([math.cos(chain.angle), math.sin(chain.angle)])
        _bar(root, o, end, size, "ground")
        _pin(root, o, 1.5 * size, "ground")
    reach = 2.0 * sum(lk.length for lk in model.links) + 1.0
    for cl in model.closures:
        if cl.target.link != GROUND:
            continue
        p = np.asarray(cl.target.local, dtype=float)
        if cl.kind == HINGE:
            _pin(root, p, 1.5 * size, "ground")
        elif cl.kind == SLIDER:
            d = np.asarray(cl.direction, dtype=float)
            _bar(root, p - reach * d, p + reach * d, 0.3 * size, "ground")
    return root


def _carried_points(model: Model, i: int) -> list[tuple[float, float]]:
    """Points of link ``i`` named by closures and named points, in its frame, m."""
    pts = [p.ref.local for p in model.points if p.ref.link == i]
    for cl in model.closures:
        if cl.point.link == i and cl.kind != ANGLE:
            pts.append(cl.point.local)
        if cl.target.link == i and cl.kind != ANGLE:
            pts.append(cl.target.local)
    return list(dict.fromkeys(tuple(map(float, p)) for p in pts))


def _link(model: Model, i: int, size: float) -> ET.Element:
    lk = model.links[i]
    el = ET.Element("link", name=lk.name)
    if lk.mass > 0.0:
        inertial = ET.SubElement(el, "inertial")
        _origin(inertial, (lk.com[0], lk.com[1], 0.0))
        ET.SubElement(inertial, "mass", value=number(lk.mass))
        half = lk.inertia / 2.0
        ET.SubElement(inertial, "inertia", ixx=number(half), ixy="0", ixz="0", iyy=number(half),
                      iyz="0", izz=number(lk.inertia))
    _bar(el, (0.0, 0.0), (lk.length, 0.0), size, "link")
    if model.joints[i].kind == REVOLUTE:
        _pin(el, (0.0, 0.0), size, "link")
    for s, w in _carried_points(model, i):
        if abs(w) > 1e-9 or s < 0.0 or s > lk.length:
            _bar(el, (0.0, 0.0), (s, w), 0.6 * size, "link")
        _pin(el, (s, w), 0.8 * size, "link")
    return el


def joint_origin(model: Model, i: int, offset: float = 0.0) -> tuple[np.ndarray, float, np.ndarray]:
    """Origin (position, yaw) and axis of joint ``i`` in its parent's frame.

    Parameters
    ----------
    model : Model
    i : int
        Joint (= link) index.
    offset : float
        Joint coordinate taken into the origin (rad or m): the zero of the joint's position.

    Returns
    -------
    xyz : ndarray, shape (3,)
        Joint frame origin in the parent link frame (the root's for a chain's first joint), m.
    yaw : float
        Rotation of the joint frame about z, rad.
    axis : ndarray, shape (3,)
        Joint axis in the joint frame (unit).
    """
    joint = model.joints[i]
    a_pred = float(model.pred_length[i])
    if joint.kind == REVOLUTE:
        xyz = np.array([a_pred, joint.slide, 0.0])
        yaw, axis = offset, np.array([0.0, 0.0, 1.0])
    else:
        phi = joint.angle
        xyz = np.array([a_pred, offset, 0.0])
        yaw, axis = phi, np.array([math.sin(phi), math.cos(phi), 0.0])
    if model.first_of_chain[i]:
        th1 = float(model.base_angle[i])
        c, s = math.cos(th1), math.sin(th1)
        o = model.base_origin[i]
        xyz = np.array([o[0] + c * xyz[0] - s * xyz[1], o[1] + s * xyz[0] + c * xyz[1], 0.0])
        yaw += th1
    return xyz, yaw, axis


def _joint(model: Model, i: int, offset: float, effort: float) -> ET.Element:
    joint = model.joints[i]
    lo, hi = joint.range
    bounded = math.isfinite(lo) or math.isfinite(hi)
    if joint.kind == REVOLUTE:
        kind = "revolute" if bounded else "continuous"
    else:
        kind = "prismatic"
    el = ET.Element("joint", name=joint.name, type=kind)
    ET.SubElement(el, "parent",
                  link=ROOT_LINK if model.first_of_chain[i] else model.links[i - 1].name)
    ET.SubElement(el, "child", link=model.links[i].name)
    xyz, yaw, axis = joint_origin(model, i, offset)
    _origin(el, xyz, yaw)
    ET.SubElement(el, "axis", xyz=numbers(*axis))
    attrs = {"effort": number(effort), "velocity": number(UNBOUNDED)}
    if kind != "continuous":
        # positions of this file: the coordinate less the zero pose's offset
        lower = lo - offset if math.isfinite(lo) else -UNBOUNDED
        upper = hi - offset if math.isfinite(hi) else UNBOUNDED
        attrs = {"lower": number(lower), "upper": number(upper), **attrs}
    ET.SubElement(el, "limit", **attrs)
    damping, friction = float(joint.damping), float(joint.friction)
    if damping or friction:
        ET.SubElement(el, "dynamics", damping=number(damping), friction=number(friction))
    return el


def _effort_limits(model: Model, plant: Plant | None) -> np.ndarray:
    """Largest joint effort of each joint (N m or N): gear x limit where an actuator drives it
    (:data:`UNBOUNDED` for an unlimited one), 0 for a passive joint."""
    out = np.zeros(model.n)
    gears = [d.gear for d in plant.actuators] if plant is not None and plant.actuators else (
        [1.0] * len(model.actuators))
    for a, gear in zip(model.actuators, gears, strict=True):
        out[a.joint] = abs(gear) * a.limit if math.isfinite(a.limit) else UNBOUNDED
    return out


def _ros2_control(model: Model, initial: np.ndarray, efforts: np.ndarray) -> ET.Element:
    """Effort command interfaces of the actuated joints; every joint's initial state."""
    _, qd0 = model.initial_state()
    el = ET.Element("ros2_control", name=model.name, type="system")
    hw = ET.SubElement(el, "hardware")
    ET.SubElement(hw, "plugin").text = "gz_ros2_control/GazeboSimSystem"
    actuated = {a.joint for a in model.actuators}
    for i, joint in enumerate(model.joints):
        j = ET.SubElement(el, "joint", name=joint.name)
        if i in actuated:
            c = ET.SubElement(j, "command_interface", name="effort")
            ET.SubElement(c, "param", name="min").text = number(-efforts[i])
            ET.SubElement(c, "param", name="max").text = number(efforts[i])
        for name, value in (("position", initial[i]), ("velocity", qd0[i])):
            s = ET.SubElement(j, "state_interface", name=name)
            ET.SubElement(s, "param", name="initial_value").text = number(value)
        ET.SubElement(j, "state_interface", name="effort")
    return el


def _pose_text(x: float, y: float, yaw: float = 0.0) -> str:
    return numbers(x, y, 0.0, 0.0, 0.0, yaw)


def _sdf_joint(parent: ET.Element, name: str, kind: str, parent_link: str, child_link: str,
               pose: str, axis: tuple[float, float, float]) -> None:
    j = ET.SubElement(parent, "joint", name=name, type=kind)
    ET.SubElement(j, "parent").text = parent_link
    ET.SubElement(j, "child").text = child_link
    ET.SubElement(j, "pose").text = pose
    a = ET.SubElement(j, "axis")
    ET.SubElement(a, "xyz").text = numbers(*axis)
    if kind == "prismatic":
        lim = ET.SubElement(a, "limit")
        ET.SubElement(lim, "lower").text = number(-UNBOUNDED)
        ET.SubElement(lim, "upper").text = number(UNBOUNDED)


def _carriage(parent: ET.Element, name: str, x: float, y: float, yaw: float) -> None:
    """An SDFormat link of negligible mass at ``(x, y, yaw)`` in the model frame."""
    link = ET.SubElement(parent, "link", name=name)
    ET.SubElement(link, "pose").text = _pose_text(x, y, yaw)
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "mass").text = number(CARRIAGE_MASS)
    inertia = ET.SubElement(inertial, "inertia")
    for key in ("ixx", "iyy", "izz"):
        ET.SubElement(inertia, key).text = number(CARRIAGE_MASS * 1e-3)


def _gazebo(model: Model, offset: np.ndarray, zero: str) -> ET.Element:
    """The closures as SDFormat joints (and carriage links), at the URDF's zero pose."""
    el = ET.Element("gazebo")
    el.append(ET.Comment(" loop closures: SDFormat joints (poses in the child link frame) "))
    if zero == "coordinates":
        el.append(ET.Comment(
            " Gazebo builds these joints at the pose it loads, this file's zero pose q = 0, where "
            "the loops need not close: for Gazebo, export with zero pose initial (vjm export, option zero) "))
    kin = forward_kinematics(model, offset)

    def name_of(link: int) -> str:
        return ROOT_LINK if link == GROUND else model.links[link].name

    def world(link: int, local) -> np.ndarray:
        local = np.asarray(local, dtype=float)
        if link == GROUND:
            return local
        return kin.origin[link] + kin.rotation[link] @ local

    def angle(link: int) -> float:
        return 0.0 if link == GROUND else float(kin.theta[link])

    for cl in model.closures:
        child = name_of(cl.point.link)
        if cl.kind == HINGE:
            _sdf_joint(el, cl.name, "revolute", name_of(cl.target.link), child,
                       _pose_text(*cl.point.local), (0.0, 0.0, 1.0))
        elif cl.kind == SLIDER:
            carriage = f"{cl.name}_carriage"
            d = np.asarray(cl.direction, dtype=float)
            d_world = d if cl.target.link == GROUND else kin.rotation[cl.target.link] @ d
            at = world(cl.point.link, cl.point.local)
            _carriage(el, carriage, at[0], at[1], math.atan2(d_world[1], d_world[0]))
            _sdf_joint(el, f"{cl.name}_slide", "prismatic", name_of(cl.target.link), carriage,
                       _pose_text(0.0, 0.0), (1.0, 0.0, 0.0))
            _sdf_joint(el, cl.name, "revolute", carriage, child, _pose_text(*cl.point.local),
                       (0.0, 0.0, 1.0))
        else:
            carriage = f"{cl.name}_carriage"
            ref = cl.target.link
            at = kin.origin[cl.point.link]
            _carriage(el, carriage, at[0], at[1], angle(ref))
            _sdf_joint(el, f"{cl.name}_x", "prismatic", name_of(ref), carriage,
                       _pose_text(0.0, 0.0), (1.0, 0.0, 0.0))
            rel = angle(cl.point.link) - angle(ref)
            _sdf_joint(el, cl.name, "prismatic", carriage, child, _pose_text(0.0, 0.0),
                       (math.sin(rel), math.cos(rel), 0.0))
    return el
