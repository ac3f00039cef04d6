"""The joint graph every model format is read into, and the rigid-body maths the readers share.

A reader (:mod:`~vjm_ros.formats.sdformat`, :mod:`~vjm_ros.formats.urdf_in`,
:mod:`~vjm_ros.formats.mjcf_in`) turns a file into a :class:`JointGraph`: bodies with their mass
properties and named points, joints between bodies (or between a body and :data:`WORLD`), loop
constraints, gravity and actuators, all in **world coordinates at the zero pose** (every joint
position 0). :func:`~vjm_ros.formats.joint_graph.reduce_graph` turns the graph into a scene document.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from vjm_ros.core.errors import SceneError

WORLD = "world"
"""Body name of the ground (the fixed world frame)."""

REVOLUTE, PRISMATIC, FIXED, CONNECT = "revolute", "prismatic", "fixed", "connect"
"""Joint kinds of the graph: a ``connect`` keeps two points together (a point constraint)."""

TREE, GRAPH, LOOP, CONSTRAINT = "tree", "graph", "loop", "constraint"
"""Roles of a joint: a joint of the file's kinematic tree (URDF, MJCF), of a joint graph without
a declared tree (SDFormat), a loop-closing joint (URDF ``<gazebo>``), a constraint that is never a
chain joint (MJCF ``<equality>``, URDF ``<constraint>``)."""


@dataclass
class Body:
    """A rigid body at the zero pose.

    Attributes
    ----------
    name : str
        The file's link or body name.
    mass : float
        kg.
    com : ndarray, shape (3,)
        Mass centre, world frame, m.
    inertia : ndarray, shape (3, 3)
        Inertia tensor about the mass centre, world axes, kg m^2.
    origin : ndarray, shape (3,)
        Origin of the body's own frame, world frame, m.
    points : dict of str to ndarray
        Named points (sites, frames), world frame, m.
    element : str
        Where the body is written, for messages.
    turn : ndarray, shape (3, 3)
        The body's rotation from the zero pose to the pose at which the file's constraints are
        defined (identity but for MJCF, whose equalities hold at ``qpos0``).
    """

    name: str
    mass: float
    com: np.ndarray
    inertia: np.ndarray
    origin: np.ndarray
    points: dict = field(default_factory=dict)
    element: str = ""
    turn: np.ndarray = field(default_factory=lambda: np.eye(3))


@dataclass
class GraphJoint:
    """A joint or loop constraint between two bodies, at the zero pose.

    Attributes
    ----------
    name : str
        The file's name.
    kind : str
        :data:`REVOLUTE`, :data:`PRISMATIC`, :data:`FIXED` or :data:`CONNECT`.
    parent, child : str
        Body names (:data:`WORLD` for the ground).
    point : ndarray, shape (3,)
        The joint's position on the parent, world frame at the zero pose, m.
    child_point : ndarray, shape (3,)
        The same point on the child (equal to ``point`` for a joint; a constraint may hold two
        points that meet only at the start pose).
    axis : ndarray, shape (3,)
        Unit axis, world frame (revolute: rotation of the child about it for a positive
        position; prismatic: translation of the child along it).
    role : str
        :data:`TREE`, :data:`GRAPH`, :data:`LOOP` or :data:`CONSTRAINT`.
    start : float
        Joint position at the start, rad or m.
    velocity : float
        Joint rate at the start, rad/s or m/s.
    damping, armature, friction : float
        Viscous damping (N m s/rad or N s/m), reflected inertia (kg m^2 or kg) and Coulomb
        friction bound (N m or N) of the joint.
    turn : ndarray, shape (3, 3), or None
        A fixed or prismatic constraint's rotation of the child relative to the parent, from
        the zero pose to where the constraint holds (None: the bodies' own ``turn``).
    element : str
        Where the joint is written, for messages.
    """

    name: str
    kind: str
    parent: str
    child: str
    point: np.ndarray
    child_point: np.ndarray
    axis: np.ndarray
    role: str
    start: float = 0.0
    element: str = ""
    velocity: float = 0.0
    turn: np.ndarray | None = None
    damping: float = 0.0
    armature: float = 0.0
    friction: float = 0.0


@dataclass
class GraphActuator:
    """An effort source on a joint: joint effort = ``gear`` x command, ``limit`` on the command
    (N m or N per unit of gear; None: unlimited)."""

    joint: str
    limit: float | None = None
    element: str = ""
    gear: float = 1.0


@dataclass
class JointGraph:
    """A model read from a file, before its planar reduction.

    Attributes
    ----------
    source : str
        The file, for messages.
    format : str
        ``"SDFormat 1.7"``, ``"URDF"``, ``"MJCF"``.
    name : str
        The model's name.
    bodies : dict of str to Body
        In file order; the ground is not among them.
    joints : list of GraphJoint
    gravity : ndarray, shape (3,)
        m/s^2, world frame.
    actuators : list of GraphActuator
    ignored : list of str
        What the file holds that the scene does not represent, said once.
    """

    source: str
    format: str
    name: str
    bodies: dict
    joints: list
    gravity: np.ndarray
    actuators: list = field(default_factory=list)
    ignored: list = field(default_factory=list)


# ---------------------------------------------------------------------------------- rotations
def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rotation of fixed-axis roll, pitch, yaw (x, then y, then z; URDF and SDFormat), (3, 3)."""
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def quat_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    """Rotation matrix of the quaternion ``w + x i + y j + z k`` (normalized here), (3, 3)."""
    q = np.array([w, x, y, z], dtype=float)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


@dataclass(frozen=True)
class Pose:
    """A rigid transform: ``p_world = rotation @ p_local + position``."""

    rotation: np.ndarray
    position: np.ndarray

    @staticmethod
    def identity() -> Pose:
        return Pose(np.eye(3), np.zeros(3))

    def __matmul__(self, other: Pose) -> Pose:
        """The composition ``self`` after ``other`` (``other`` expressed in ``self``)."""
        return Pose(self.rotation @ other.rotation,
                    self.rotation @ other.position + self.position)

    def apply(self, point: np.ndarray) -> np.ndarray:
        """A local point in the outer frame, (3,)."""
        return self.rotation @ np.asarray(point, dtype=float) + self.position

    def inverse(self) -> Pose:
        rt = self.rotation.T
        return Pose(rt, -rt @ self.position)


# ---------------------------------------------------------------------------------- XML
def parse_xml(path: str) -> ET.Element:
    """The root element of an XML file; malformed XML names its line and column.

    Raises
    ------
    SceneError
        Unreadable file, or XML that does not parse (``line L, column C``).
    """
    try:
        tree = ET.parse(path)
    except ET.ParseError as exc:
        line, column = exc.position
        raise SceneError(path, f"line {line}, column {column + 1}", "well-formed XML",
                         str(exc).split(":")[0]) from None
    except OSError as exc:
        raise SceneError(path, "(file)", "a readable file", exc.strerror or str(exc)) from None
    return tree.getroot()


def numbers(text: str | None, count: int, path: str, where: str,
            default: Sequence[float] | None = None) -> list[float]:
    """``count`` numbers written in ``text`` separated by spaces (``default`` if absent)."""
    if text is None or not text.strip():
        if default is None:
            raise SceneError(path, where, f"{count} numbers", "nothing")
        return list(default)
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        raise SceneError(path, where, f"{count} numbers", text.strip()) from None
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise SceneError(path, where, f"{count} finite numbers", text.strip())
    return values


def inertia_tensor(el: ET.Element | None, path: str, where: str, moment: float) -> np.ndarray:
    """The symmetric tensor an SDFormat ``<inertia>`` element writes (``<ixx>`` to ``<izz>``),
    kg m^2, (3, 3): a moment it does not write (or no element) is ``moment``, a product 0."""
    ixx, ixy, ixz, iyy, iyz, izz = (
        float(numbers(el.findtext(k) if el is not None else None, 1, path, f"{where} <{k}>",
                      default=[moment if k in ("ixx", "iyy", "izz") else 0.0])[0])
        for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], dtype=float)
