"""URDF models (``.urdf``) read into a :class:`~vjm_ros.formats.graph.JointGraph`.

The kinematic tree (links, joints, inertials, limits) is read by yourdfpy, a maintained URDF
library; the elements it does not model are read from the XML:

* loop-closing joints written as SDFormat joints inside ``<gazebo>`` (Gazebo's way of closing a
  loop in a URDF): ``revolute``, ``continuous``, ``prismatic``, ``fixed``; their ``<pose>`` is in
  the child link's frame and their axis in the joint frame, as SDFormat 1.7 reads them;
* ``<constraint>`` elements (urdfdom's proposal): ``<parent link>``, ``<parent_origin>``,
  ``<parent_axis>``, ``<child link>``, ``<child_origin>``, ``<child_axis>``; types
  ``revolute``/``continuous``, ``prismatic``, ``fixed`` and ``spherical`` (in a planar mechanism a
  point constraint);
* actuators: ``<transmission>`` joints with an effort hardware interface, and ``<ros2_control>``
  joints with an ``effort`` command interface; the limit is the joint's ``<limit effort>``.

The root link is the ground (a fixed base, as ``robot_state_publisher`` takes it).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from vjm_ros.core.errors import SceneError
from vjm_ros.formats.graph import (
    CONNECT,
    CONSTRAINT,
    FIXED,
    LOOP,
    PRISMATIC,
    REVOLUTE,
    TREE,
    WORLD,
    Body,
    GraphActuator,
    GraphJoint,
    JointGraph,
    Pose,
    inertia_tensor,
    numbers,
    parse_xml,
    rpy_matrix,
)
from vjm_ros.formats.sdformat import JOINT_KINDS

URDF_KINDS = {"revolute": REVOLUTE, "continuous": REVOLUTE, "prismatic": PRISMATIC,
              "fixed": FIXED}
CONSTRAINT_KINDS = {**URDF_KINDS, "spherical": CONNECT, "ball": CONNECT}


def read_urdf(path: str) -> JointGraph:
    """The joint graph of the URDF file ``path``.

    Raises
    ------
    SceneError
        Malformed XML (line and column), or an element the planar model cannot represent.
    """
    import yourdfpy

    root = parse_xml(path)
    if root.tag != "robot":
        raise SceneError(path, f"<{root.tag}>", "a <robot> root element", root.tag)
    try:
        robot = yourdfpy.URDF.load(path, build_scene_graph=False, load_meshes=False).robot
    except Exception as exc:  # noqa: BLE001 (yourdfpy raises many kinds for a bad file)
        raise SceneError(path, "<robot>", "a URDF that yourdfpy reads", str(exc)) from None
    return _UrdfReader(path, root, robot).graph()


def _origin(el: ET.Element | None, path: str, where: str) -> Pose:
    """The transform of an ``<origin xyz rpy>``-like element (identity when absent)."""
    if el is None:
        return Pose.identity()
    xyz = numbers(el.get("xyz"), 3, path, f"{where} xyz", default=[0.0] * 3)
    rpy = numbers(el.get("rpy"), 3, path, f"{where} rpy", default=[0.0] * 3)
    return Pose(rpy_matrix(*rpy), np.array(xyz))


def _pose(el: ET.Element | None, path: str, where: str) -> Pose:
    """The transform of an SDFormat ``<pose>`` (``x y z roll pitch yaw``; identity when absent)."""
    if el is None:
        return Pose.identity()
    v = numbers(el.text, 6, path, where)
    return Pose(rpy_matrix(*v[3:]), np.array(v[:3]))


class _UrdfReader:
    def __init__(self, path: str, root: ET.Element, robot):
        self.path, self.root, self.robot = path, root, robot
        self.name = robot.name or "robot"

    def fail(self, where: str, expected: str, found: object = ...) -> SceneError:
        return SceneError(self.path, where, expected, found)

    def frames(self) -> tuple[str, dict]:
        """The root link and every link's frame at the zero pose."""
        links = {lk.name for lk in self.robot.links}
        children = {}
        for j in self.robot.joints:
            where = f"joint '{j.name}'"
            if j.type not in URDF_KINDS:
                raise self.fail(where, "a revolute, continuous, prismatic or fixed joint (a "
                                f"{'floating base' if j.type == 'floating' else 'joint'} the "
                                "planar model cannot represent)", j.type)
            if j.mimic is not None:
                raise self.fail(f"{where} <mimic>", "no mimic coupling (the scene has no "
                                "coupled joints)", j.mimic.joint)
            for role, link in (("parent", j.parent), ("child", j.child)):
                if link not in links:
                    raise self.fail(f"{where} <{role}>", "a link of the robot", link)
            if j.child in children:
                raise self.fail(f"{where} <child>", "a link that is the child of one joint (a "
                                "tree; close loops with <gazebo> joints or <constraint>)",
                                j.child)
            children[j.child] = j
        roots = [lk.name for lk in self.robot.links if lk.name not in children]
        if len(roots) != 1:
            raise self.fail("<robot>", "one root link", roots)
        frame = {roots[0]: Pose.identity()}
        pending = list(self.robot.joints)
        while pending:
            rest = [j for j in pending if j.parent not in frame]
            for j in pending:
                if j.parent in frame:
                    origin = np.eye(4) if j.origin is None else np.asarray(j.origin)
                    frame[j.child] = frame[j.parent] @ Pose(origin[:3, :3], origin[:3, 3])
            if len(rest) == len(pending):
                raise self.fail(f"joint '{rest[0].name}'", "a joint reached from the root link",
                                rest[0].parent)
            pending = rest
        return roots[0], frame

    def graph(self) -> JointGraph:
        root, frame = self.frames()
        self.root_link, self.frame = root, frame
        bodies = {}
        for lk in self.robot.links:
            if lk.name == root:
                continue
            pose = frame[lk.name]
            if lk.inertial is not None:
                local = lk.inertial.origin if lk.inertial.origin is not None else np.eye(4)
                rot = pose.rotation @ local[:3, :3]
                com = pose.apply(local[:3, 3])
                mass = float(lk.inertial.mass or 0.0)
                tensor = rot @ np.asarray(lk.inertial.inertia, dtype=float) @ rot.T
            else:
                mass, com, tensor = 0.0, pose.position.copy(), np.zeros((3, 3))
            bodies[lk.name] = Body(name=lk.name, mass=mass, com=com, inertia=tensor,
                                   origin=pose.position.copy(), element=f"link '{lk.name}'")
        for name, body in self.gazebo_links().items():
            bodies[name] = body
        joints = [self.tree_joint(j) for j in self.robot.joints]
        start = self.initial_values()
        for j in joints:
            j.start, j.velocity = start.get(j.name, (0.0, 0.0))
        joints += self.gazebo_joints()
        joints += self.constraints()
        ignored = ["collision and visual geometry"]
        if any(j.limit is not None and j.limit.lower is not None for j in self.robot.joints):
            ignored.append("joint position and velocity limits")
        return JointGraph(source=self.path, format="URDF", name=self.name, bodies=bodies,
                          joints=joints, gravity=np.array([0.0, 0.0, -9.81]),
                          actuators=self.actuators(), ignored=ignored)

    def end(self, link: str) -> str:
        return WORLD if link in (self.root_link, WORLD) else link

    def tree_joint(self, j) -> GraphJoint:
        pose = self.frame[j.child]
        axis = np.asarray(j.axis if j.axis is not None else [1.0, 0.0, 0.0], dtype=float)
        axis = pose.rotation @ (axis / np.linalg.norm(axis))
        dyn = j.dynamics
        return GraphJoint(name=j.name, kind=URDF_KINDS[j.type], parent=self.end(j.parent),
                          child=self.end(j.child), point=pose.position.copy(),
                          child_point=pose.position.copy(), axis=axis, role=TREE,
                          element=f"joint '{j.name}'",
                          damping=float((dyn.damping if dyn is not None else 0.0) or 0.0),
                          friction=float((dyn.friction if dyn is not None else 0.0) or 0.0))

    def link_frame(self, name: str, where: str) -> Pose:
        if name == WORLD and name not in self.frame:
            return Pose.identity()
        if name not in self.frame:
            raise self.fail(where, "a link of the robot (or 'world')", name)
        return self.frame[name]

    def gazebo_links(self) -> dict:
        """SDFormat links inside ``<gazebo>`` (the carriages of loop joints), in the root
        link's frame (their ``<pose>`` is in the model frame)."""
        out = {}
        for gz in self.root.findall("gazebo"):
            for el in gz.findall("link"):
                name = el.get("name", "")
                where = f"<gazebo> link '{name}'"
                if name in self.frame:
                    raise self.fail(where, "a link name the robot does not use", name)
                frame = _pose(el.find("pose"), self.path, f"{where} <pose>")
                self.frame[name] = frame
                inertial = el.find("inertial")
                mass = float(numbers(inertial.findtext("mass") if inertial is not None else None,
                                     1, self.path, f"{where} <mass>", default=[1.0])[0])
                tensor = np.zeros((3, 3))
                it = inertial.find("inertia") if inertial is not None else None
                if it is not None:
                    tensor = inertia_tensor(it, self.path, where, moment=0.0)
                    tensor = frame.rotation @ tensor @ frame.rotation.T
                out[name] = Body(name=name, mass=mass, com=frame.position.copy(),
                                 inertia=tensor, origin=frame.position.copy(), element=where)
        return out

    def gazebo_joints(self) -> list:
        """Loop joints written as SDFormat joints in ``<gazebo>`` (no ``reference``)."""
        out = []
        for gz in self.root.findall("gazebo"):
            for el in gz.findall("joint"):
                name = el.get("name", "")
                where = f"<gazebo> joint '{name}'"
                kind = el.get("type", "")
                if kind not in JOINT_KINDS:
                    raise self.fail(where, "a revolute, continuous, prismatic or fixed loop "
                                    "joint (the scene closes no other kind)", kind)
                parent = (el.findtext("parent") or "").strip()
                child = (el.findtext("child") or "").strip()
                pose_el = el.find("pose")
                rel = (pose_el.get("relative_to", "") if pose_el is not None else "") or child
                base = self.link_frame(rel, f"{where} <pose> relative_to")
                self.link_frame(parent, f"{where} <parent>")
                jf = base @ _pose(pose_el, self.path, f"{where} <pose>")
                xyz_el = el.find("axis/xyz")
                xyz = np.array(numbers(xyz_el.text if xyz_el is not None else None, 3,
                                       self.path, f"{where} <axis><xyz>",
                                       default=[0.0, 0.0, 1.0]))
                expressed = xyz_el.get("expressed_in", "") if xyz_el is not None else ""
                in_model = (expressed == "__model__" or (el.findtext("axis/use_parent_model_frame")
                                                         or "").strip() in ("true", "1"))
                axis = xyz if in_model else jf.rotation @ xyz
                out.append(GraphJoint(
                    name=name, kind=JOINT_KINDS[kind], parent=self.end(parent),
                    child=self.end(child), point=jf.position.copy(),
                    child_point=jf.position.copy(), axis=axis / np.linalg.norm(axis), role=LOOP,
                    element=where))
        return out

    def constraints(self) -> list:
        """urdfdom's proposed ``<constraint>`` elements."""
        out = []
        for el in self.root.findall("constraint"):
            name = el.get("name", "")
            where = f"<constraint> '{name}'"
            kind = el.get("type", "")
            if kind not in CONSTRAINT_KINDS:
                raise self.fail(where, "a revolute, continuous, prismatic, fixed or spherical "
                                "constraint", kind)
            ends = []
            for side in ("parent", "child"):
                link_el = el.find(side)
                link = link_el.get("link", "") if link_el is not None else ""
                base = self.link_frame(link, f"{where} <{side}>")
                pose = base @ _origin(el.find(f"{side}_origin"), self.path,
                                      f"{where} <{side}_origin>")
                ax_el = el.find(f"{side}_axis")
                ax = np.array(numbers(ax_el.get("xyz") if ax_el is not None else None, 3,
                                      self.path, f"{where} <{side}_axis>",
                                      default=[1.0, 0.0, 0.0]))
                ends.append((link, pose, pose.rotation @ (ax / np.linalg.norm(ax))))
            (pl, pp, pa), (cl, cp, _) = ends
            out.append(GraphJoint(
                name=name, kind=CONSTRAINT_KINDS[kind], parent=self.end(pl), child=self.end(cl),
                point=pp.position.copy(), child_point=cp.position.copy(), axis=pa,
                role=CONSTRAINT, element=where))
        return out

    def initial_values(self) -> dict:
        """``{joint: (position, velocity)}`` from ``<ros2_control>`` state interfaces'
        ``initial_value`` parameters (the start; 0 where none is given)."""
        out = {}
        for rc in self.root.findall("ros2_control"):
            for jel in rc.findall("joint"):
                values = [0.0, 0.0]
                for k, kind in enumerate(("position", "velocity")):
                    for si in jel.findall("state_interface"):
                        if si.get("name") != kind:
                            continue
                        for param in si.findall("param"):
                            if param.get("name") == "initial_value":
                                where = (f"<ros2_control> joint '{jel.get('name', '')}' "
                                         f"{kind} initial_value")
                                values[k] = numbers(param.text, 1, self.path, where)[0]
                out[jel.get("name", "")] = tuple(values)
        return out

    def actuators(self) -> list:
        """Effort actuators of ``<transmission>`` and ``<ros2_control>``."""
        limits = {j.name: (j.limit.effort if j.limit is not None else None)
                  for j in self.robot.joints}
        names = []
        for tr in self.root.findall("transmission"):
            for jel in tr.findall("joint"):
                hw = " ".join((h.text or "") for h in tr.iter("hardwareInterface"))
                if "effort" in hw.lower():
                    names.append((jel.get("name", ""), "<transmission> joint"))
        for rc in self.root.findall("ros2_control"):
            for jel in rc.findall("joint"):
                if any(ci.get("name") == "effort" for ci in jel.findall("command_interface")):
                    names.append((jel.get("name", ""), "<ros2_control> joint"))
        return [GraphActuator(n, limits.get(n), f"{where} '{n}'") for n, where in names]
