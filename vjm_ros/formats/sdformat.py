"""SDFormat 1.4-1.11 models (``.sdf``) read into a :class:`~vjm_ros.formats.graph.JointGraph`.

Read with the standard library against the SDFormat specification (no maintained Python parser
exists). Frames follow the spec's version:

* a link's ``<pose>`` is in the model frame, or (1.7+) in the frame its ``relative_to`` names;
* a joint's ``<pose>`` is in its child link's frame, or (1.7+) in its ``relative_to`` frame;
* a joint axis ``<xyz>`` is in the model frame in 1.4, in the joint frame from 1.5 (the model
  frame with ``<use_parent_model_frame>true``, 1.5-1.6) and (1.7+) in the frame its
  ``expressed_in`` names;
* ``<frame>`` elements (1.7+) are attached to a link (named points) or to the model;
* poses are ``x y z roll pitch yaw`` (1.9+: ``degrees="true"``, ``rotation_format="quat_xyzw"``).

The model frame is the world of the scene; ``world`` as a joint's parent or child is the ground.
Gravity is the world's ``<gravity>`` (1.4: ``<physics><gravity>``), default ``0 0 -9.8``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np

from vjm_ros.core.errors import SceneError
from vjm_ros.formats.graph import (
    FIXED,
    GRAPH,
    PRISMATIC,
    REVOLUTE,
    WORLD,
    Body,
    GraphJoint,
    JointGraph,
    Pose,
    inertia_tensor,
    numbers,
    parse_xml,
    quat_matrix,
    rpy_matrix,
)

JOINT_KINDS = {"revolute": REVOLUTE, "continuous": REVOLUTE, "prismatic": PRISMATIC,
               "fixed": FIXED}
"""SDFormat joint types the planar model represents; the others are refused."""
MODEL_FRAME = "__model__"


def read_sdformat(path: str) -> JointGraph:
    """The joint graph of the SDFormat file ``path``.

    Raises
    ------
    SceneError
        Malformed XML (line and column), a version outside 1.4-1.11, or an element the planar
        model cannot represent, named.
    """
    root = parse_xml(path)
    if root.tag != "sdf":
        raise SceneError(path, f"<{root.tag}>", "an <sdf> root element", root.tag)
    version = root.get("version", "")
    try:
        major, minor = (int(x) for x in version.split(".")[:2])
    except ValueError:
        raise SceneError(path, "<sdf version>", "a version 1.4 to 1.11", version) from None
    if major != 1 or not 4 <= minor <= 11:
        raise SceneError(path, "<sdf version>", "a version 1.4 to 1.11", version)
    gravity = np.array([0.0, 0.0, -9.8])
    worlds = root.findall("world")
    models = root.findall("model")
    container = root
    if worlds:
        if len(worlds) > 1 or models:
            raise SceneError(path, "<sdf>", "one world or one model", "several")
        container = worlds[0]
        g_el = container.find("gravity") if minor >= 5 else container.find("physics/gravity")
        if g_el is None:
            g_el = container.find("gravity")
        if g_el is not None:
            gravity = np.array(numbers(g_el.text, 3, path, "<world><gravity>"))
        models = container.findall("model")
    if len(models) != 1:
        raise SceneError(path, "<model>", "exactly one model", f"{len(models)} models")
    return _ModelReader(path, minor, models[0], gravity).graph()


class _ModelReader:
    """One ``<model>``: its frames resolved to the model frame, links and joints read."""

    def __init__(self, path: str, minor: int, model: ET.Element, gravity: np.ndarray):
        self.path, self.minor, self.model = path, minor, model
        self.name = model.get("name", "model")
        self.gravity = gravity
        for tag in ("model", "include"):
            if model.find(tag) is not None:
                raise self.fail(f"<{tag}>", "a model without nested models or includes "
                                "(flatten it first, e.g. with 'gz sdf -p')", tag)
        self.links = {el.get("name"): el for el in model.findall("link")}
        self.joints = {el.get("name"): el for el in model.findall("joint")}
        self.frames = {el.get("name"): el for el in model.findall("frame")}
        self.cache: dict[str, Pose] = {}
        self.ignored = [what for what, tags in (
            ("collision and visual geometry", ("link/collision", "link/visual")),
            ("sensors", ("link/sensor",)), ("plugins", ("plugin",)))
            if any(model.find(t) is not None for t in tags)]
        if model.find("pose") is not None:
            pose = self.pose(model.find("pose"), "<model><pose>")
            self.gravity = pose.rotation.T @ gravity  # the model frame is the scene's world

    def fail(self, where: str, expected: str, found: object = ...) -> SceneError:
        return SceneError(self.path, f"model '{self.name}' {where}", expected, found)

    # ------------------------------------------------------------------ poses and frames
    def pose(self, el: ET.Element | None, where: str) -> Pose:
        """The transform a ``<pose>`` element writes (identity when absent)."""
        if el is None:
            return Pose.identity()
        values = (el.text or "").split()
        fmt = el.get("rotation_format", "euler_rpy")
        count = 7 if fmt == "quat_xyzw" else 6
        v = numbers(el.text, count, self.path, f"model '{self.name}' {where}",
                    default=[0.0] * 6 if not values else None)
        if fmt == "quat_xyzw":
            rot = quat_matrix(v[6], v[3], v[4], v[5])
        else:
            angles = v[3:6]
            if el.get("degrees", "false").strip().lower() in ("true", "1"):
                angles = [math.radians(a) for a in angles]
            rot = rpy_matrix(*angles)
        return Pose(rot, np.array(v[:3]))

    def relative_to(self, el: ET.Element | None, default: str, where: str) -> str:
        """The frame a pose is written in: its ``relative_to`` (1.7+) or ``default``."""
        if el is None:
            return default
        if self.minor < 7:
            frame = el.get("frame", "")
            if frame:
                raise self.fail(f"{where} frame", "no 'frame' attribute (its meaning before "
                                "1.7 is not specified)", frame)
            return default
        return el.get("relative_to", "") or default

    def frame_pose(self, name: str, where: str, seen: tuple = ()) -> Pose:
        """The pose of the frame ``name`` (link, joint, frame or the model) in the model frame."""
        if name in (MODEL_FRAME, WORLD) and name not in self.links:
            return Pose.identity()
        if name in self.cache:
            return self.cache[name]
        if name in seen:
            raise self.fail(where, "poses whose relative_to frames do not form a cycle",
                            " -> ".join([*seen, name]))
        seen = (*seen, name)
        if name in self.links:
            el = self.links[name].find("pose")
            rel = self.relative_to(el, MODEL_FRAME, f"link '{name}' <pose>")
            where_el = f"link '{name}' <pose>"
        elif name in self.joints:
            el = self.joints[name].find("pose")
            child = (self.joints[name].findtext("child") or "").strip()
            rel = self.relative_to(el, child, f"joint '{name}' <pose>")
            where_el = f"joint '{name}' <pose>"
        elif name in self.frames:
            el = self.frames[name].find("pose")
            attached = self.frames[name].get("attached_to", "") or MODEL_FRAME
            rel = self.relative_to(el, attached, f"frame '{name}' <pose>")
            where_el = f"frame '{name}' <pose>"
        else:
            raise self.fail(where, "a frame of the model (a link, joint, frame or __model__)",
                            name)
        pose = self.frame_pose(rel, where_el, seen) @ self.pose(el, where_el)
        self.cache[name] = pose
        return pose

    def attached_link(self, name: str, seen: tuple = ()) -> str | None:
        """The link a frame is attached to, or None for the model frame."""
        if name in self.links:
            return name
        if name in self.frames and name not in seen:
            return self.attached_link(self.frames[name].get("attached_to", "") or MODEL_FRAME,
                                      (*seen, name))
        if name in self.joints and name not in seen:
            return self.attached_link((self.joints[name].findtext("child") or "").strip(),
                                      (*seen, name))
        return None

    # ------------------------------------------------------------------ links and joints
    def body(self, name: str) -> Body:
        el = self.links[name]
        frame = self.frame_pose(name, f"link '{name}'")
        inertial = el.find("inertial")
        where = f"link '{name}' <inertial>"
        mass, tensor, local = 1.0, np.eye(3), Pose.identity()
        if inertial is not None:
            if inertial.get("auto", "false").strip().lower() in ("true", "1"):
                raise self.fail(where, "mass and inertia written out (auto=\"true\" computes "
                                "them from collision geometry)", "auto")
            mass = float(numbers(inertial.findtext("mass"), 1, self.path, f"{where} <mass>",
                                 default=[1.0])[0])
            local = self.pose(inertial.find("pose"), f"{where} <pose>")
            tensor = inertia_tensor(inertial.find("inertia"), self.path, where, moment=1.0)
        if mass < 0:
            raise self.fail(f"{where} <mass>", "a mass >= 0", mass)
        rot = frame.rotation @ local.rotation
        return Body(name=name, mass=mass, com=frame.apply(local.position),
                    inertia=rot @ tensor @ rot.T, origin=frame.position.copy(),
                    element=f"model '{self.name}' link '{name}'")

    def joint(self, name: str) -> GraphJoint:
        el = self.joints[name]
        where = f"joint '{name}'"
        kind_text = el.get("type", "")
        if kind_text not in JOINT_KINDS:
            raise self.fail(where, "a revolute, continuous, prismatic or fixed joint (the "
                            "planar model has no other kind)", kind_text)
        parent = (el.findtext("parent") or "").strip()
        child = (el.findtext("child") or "").strip()
        for role, link in (("parent", parent), ("child", child)):
            if link not in self.links and link != WORLD:
                raise self.fail(f"{where} <{role}>", "a link of the model or 'world'", link)
        frame = self.frame_pose(name, where)
        kind = JOINT_KINDS[kind_text]
        axis = np.array([0.0, 0.0, 1.0])
        start = 0.0
        axis_el = el.find("axis")
        if kind != FIXED:
            if axis_el is None and self.minor < 7:
                raise self.fail(f"{where} <axis>", "an axis", "missing")
            axis = self.axis(axis_el, frame, where)
            start = float(numbers(axis_el.findtext("initial_position")
                                  if axis_el is not None else None,
                                  1, self.path, f"{where} <initial_position>", default=[0.0])[0])
        point = frame.position.copy()
        losses = [float(numbers(axis_el.findtext(f"dynamics/{k}") if axis_el is not None
                                else None, 1, self.path, f"{where} <dynamics><{k}>",
                                default=[0.0])[0]) for k in ("damping", "friction")]
        return GraphJoint(name=name, kind=kind, parent=parent, child=child, point=point,
                          child_point=point.copy(), axis=axis, role=GRAPH, start=start,
                          element=f"model '{self.name}' {where}", damping=losses[0],
                          friction=losses[1])

    def axis(self, axis_el: ET.Element | None, frame: Pose, where: str) -> np.ndarray:
        """The unit axis of a joint in the model frame."""
        xyz_el = axis_el.find("xyz") if axis_el is not None else None
        xyz = np.array(numbers(xyz_el.text if xyz_el is not None else None, 3, self.path,
                               f"{where} <axis><xyz>", default=[0.0, 0.0, 1.0]))
        norm = float(np.linalg.norm(xyz))
        if norm < 1e-12:
            raise self.fail(f"{where} <axis><xyz>", "a non-zero vector", xyz.tolist())
        xyz = xyz / norm
        if self.minor == 4:
            return xyz
        if self.minor < 7:
            use_model = (axis_el.findtext("use_parent_model_frame") or "").strip().lower()
            return xyz if use_model in ("true", "1") else frame.rotation @ xyz
        expressed = xyz_el.get("expressed_in", "") if xyz_el is not None else ""
        if not expressed:
            return frame.rotation @ xyz
        return self.frame_pose(expressed, f"{where} <axis><xyz> expressed_in").rotation @ xyz

    def graph(self) -> JointGraph:
        if not self.links:
            raise self.fail("<link>", "at least one link", "none")
        bodies = {name: self.body(name) for name in self.links}
        for fname in self.frames:
            link = self.attached_link(fname)
            if link is not None:
                bodies[link].points[fname] = self.frame_pose(fname, f"frame '{fname}'").position
        joints = [self.joint(name) for name in self.joints]
        return JointGraph(source=self.path, format=f"SDFormat 1.{self.minor}", name=self.name,
                          bodies=bodies, joints=joints, gravity=self.gravity,
                          ignored=list(self.ignored))
