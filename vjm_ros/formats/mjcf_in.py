"""MJCF models (MuJoCo ``.xml``) read into a :class:`~vjm_ros.formats.graph.JointGraph`.

The file goes through MuJoCo's own compiler (:class:`mujoco.MjModel`), so masses, mass centres
and inertias are those MuJoCo computes from the geoms (or the ``<inertial>`` elements), defaults
and includes applied. Then:

* hinge and slide joints are the joints (several in one body: a massless link between each
  two); a body without joints is fixed to its parent; ball and free joints are refused;
* the coordinate of a joint is MuJoCo's ``qpos``: the link frames are placed at ``qpos = 0`` and
  the scene starts at the first keyframe (``qpos``, ``qvel``) or, without one, at ``qpos0`` (the
  pose the file writes, shifted by each joint's ``ref``) at rest;
* ``<equality>``: ``connect`` (``body1`` + ``anchor``, or ``site1``/``site2``) keeps two points
  together, ``weld`` (at its ``relpose``, or the relative pose at ``qpos0``) also keeps the
  relative angle;
  inactive equalities are left out; ``joint``, ``tendon`` and ``flex`` equalities are refused;
* ``<actuator><motor>`` on a joint: an actuator whose command is MuJoCo's control (``gear``
  becomes the actuator's ``gear``; a negative gear is folded into the limit of the joint effort),
  limited by ``ctrlrange`` or ``forcerange``; other actuator kinds are left out and said;
* sites become named points.
"""

from __future__ import annotations

import numpy as np

from vjm_ros.core.errors import SceneError
from vjm_ros.formats.graph import (
    CONNECT,
    CONSTRAINT,
    FIXED,
    PRISMATIC,
    REVOLUTE,
    TREE,
    WORLD,
    Body,
    GraphActuator,
    GraphJoint,
    JointGraph,
    parse_xml,
)


def read_mjcf(path: str) -> JointGraph:
    """The joint graph of the MJCF file ``path``.

    Raises
    ------
    SceneError
        Malformed XML (line and column), a model MuJoCo refuses (its message), or an element the
        planar model cannot represent.
    """
    import mujoco

    root = parse_xml(path)
    if root.tag != "mujoco":
        raise SceneError(path, f"<{root.tag}>", "a <mujoco> root element", root.tag)
    try:
        m = mujoco.MjModel.from_xml_path(str(path))
    except ValueError as exc:
        raise SceneError(path, "<mujoco>", "a model MuJoCo compiles",
                         " ".join(str(exc).split())) from None
    return _MjcfReader(path, root, m, mujoco).graph()


class _MjcfReader:
    def __init__(self, path, root, m, mujoco):
        self.path, self.m, self.mj = path, m, mujoco
        self.name = root.get("model", "mujoco")

    def obj_name(self, kind, i: int) -> str:
        return self.mj.mj_id2name(self.m, kind, i) or ""

    def body_name(self, b: int) -> str:
        if b == 0:
            return WORLD
        return self.obj_name(self.mj.mjtObj.mjOBJ_BODY, b) or f"body{b}"

    def fail(self, where: str, expected: str, found: object = ...) -> SceneError:
        return SceneError(self.path, where, expected, found)

    def kinematics(self, qpos: np.ndarray):
        d = self.mj.MjData(self.m)
        d.qpos[:] = qpos
        self.mj.mj_kinematics(self.m, d)
        return d

    def graph(self) -> JointGraph:
        m, mj = self.m, self.mj
        for i in range(m.njnt):
            kind = int(m.jnt_type[i])
            if kind not in (int(mj.mjtJoint.mjJNT_HINGE), int(mj.mjtJoint.mjJNT_SLIDE)):
                name = self.obj_name(mj.mjtObj.mjOBJ_JOINT, i) or f"joint{i}"
                what = "a floating base" if kind == int(mj.mjtJoint.mjJNT_FREE) else "a ball joint"
                raise self.fail(f"joint '{name}'", "hinge and slide joints (the planar model "
                                f"cannot represent {what})",
                                "free" if kind == int(mj.mjtJoint.mjJNT_FREE) else "ball")
        zero = self.kinematics(np.zeros(m.nq))      # the frames of the scene
        start = self.kinematics(m.qpos0.copy())     # the pose the file writes
        self.qpos_start, self.qvel_start = m.qpos0.copy(), np.zeros(m.nv)
        if m.nkey:  # the first keyframe, when there is one, is the start
            self.qpos_start, self.qvel_start = m.key_qpos[0].copy(), m.key_qvel[0].copy()
        self.zero, self.start = zero, start
        bodies = {}
        for b in range(1, m.nbody):
            name = self.body_name(b)
            rot = zero.ximat[b].reshape(3, 3)
            tensor = rot @ np.diag(m.body_inertia[b]) @ rot.T
            turn = start.xmat[b].reshape(3, 3) @ zero.xmat[b].reshape(3, 3).T
            bodies[name] = Body(name=name, mass=float(m.body_mass[b]),
                                com=zero.xipos[b].copy(), inertia=tensor,
                                origin=zero.xpos[b].copy(), element=f"body '{name}'", turn=turn)
        for s in range(m.nsite):
            b = int(m.site_bodyid[s])
            if b != 0:
                sname = self.obj_name(mj.mjtObj.mjOBJ_SITE, s) or f"site{s}"
                bodies[self.body_name(b)].points[sname] = zero.site_xpos[s].copy()
        joints = []
        for b in range(1, m.nbody):
            adr, num = int(m.body_jntadr[b]), int(m.body_jntnum[b])
            parent = self.body_name(int(m.body_parentid[b]))
            if num == 0:
                p = zero.xpos[b].copy()
                joints.append(GraphJoint(f"{self.body_name(b)}_weld", FIXED, parent,
                                         self.body_name(b), p, p.copy(),
                                         np.array([0.0, 0.0, 1.0]), TREE))
                continue
            # several joints in one body: a massless link between each two of them
            for k in range(num - 1):
                name = f"{self.body_name(b)}_{self.obj_name(mj.mjtObj.mjOBJ_JOINT, adr + k)}"
                if name in bodies:
                    raise self.fail(f"body '{self.body_name(b)}'", "joint names that do not "
                                    "clash with body names", name)
                bodies[name] = Body(name=name, mass=0.0, com=zero.xpos[b].copy(),
                                    inertia=np.zeros((3, 3)), origin=zero.xpos[b].copy(),
                                    element=f"body '{self.body_name(b)}'",
                                    turn=bodies[self.body_name(b)].turn)
                joints.append(self.joint(adr + k, parent, name))
                parent = name
            joints.append(self.joint(adr + num - 1, parent, self.body_name(b)))
        joints += self.equalities()
        ignored = ["collision and visual geometry (contacts)", "solver settings"]
        if np.any(m.jnt_limited):
            ignored.append("joint ranges")
        return JointGraph(source=self.path, format="MJCF", name=self.name, bodies=bodies,
                          joints=joints, gravity=np.array(m.opt.gravity, dtype=float),
                          actuators=self.actuators(ignored), ignored=ignored)

    def joint(self, i: int, parent: str, child: str) -> GraphJoint:
        m, mj = self.m, self.mj
        name = self.obj_name(mj.mjtObj.mjOBJ_JOINT, i) or f"joint{i}"
        kind = REVOLUTE if int(m.jnt_type[i]) == int(mj.mjtJoint.mjJNT_HINGE) else PRISMATIC
        p = self.zero.xanchor[i].copy()
        axis = self.zero.xaxis[i].copy()
        return GraphJoint(name=name, kind=kind, parent=parent, child=child, point=p,
                          child_point=p.copy(), axis=axis / np.linalg.norm(axis), role=TREE,
                          start=float(self.qpos_start[m.jnt_qposadr[i]]),
                          velocity=float(self.qvel_start[m.jnt_dofadr[i]]),
                          element=f"joint '{name}'",
                          damping=float(m.dof_damping[m.jnt_dofadr[i]]),
                          armature=float(m.dof_armature[m.jnt_dofadr[i]]),
                          friction=float(m.dof_frictionloss[m.jnt_dofadr[i]]))

    def to_zero(self, b: int, p_start: np.ndarray) -> np.ndarray:
        """A point of body ``b`` given at the start pose, where it is at the zero pose, (3,)."""
        r0, r1 = self.zero.xmat[b].reshape(3, 3), self.start.xmat[b].reshape(3, 3)
        return self.zero.xpos[b] + r0 @ (r1.T @ (p_start - self.start.xpos[b]))

    def equalities(self) -> list:
        m, mj = self.m, self.mj
        out = []
        kinds = {int(mj.mjtEq.mjEQ_CONNECT): CONNECT, int(mj.mjtEq.mjEQ_WELD): FIXED}
        for e in range(m.neq):
            name = self.obj_name(mj.mjtObj.mjOBJ_EQUALITY, e) or f"equality{e + 1}"
            where = f"<equality> '{name}'"
            kind = int(m.eq_type[e])
            if kind not in kinds:
                raise self.fail(where, "a connect or weld equality (the scene closes loops "
                                "only by points and angles)", str(mj.mjtEq(kind)).split(".")[-1])
            if not m.eq_active0[e]:
                continue
            o1, o2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
            sites = int(m.eq_objtype[e]) == int(mj.mjtObj.mjOBJ_SITE)
            if sites:
                b1, b2 = int(m.site_bodyid[o1]), int(m.site_bodyid[o2])
                p1 = self.to_zero(b1, self.start.site_xpos[o1])
                p2 = self.to_zero(b2, self.start.site_xpos[o2])
            else:
                b1, b2 = o1, o2
                if kinds[kind] == CONNECT:  # anchor in body1's frame
                    world = self.start.xpos[b1] + self.start.xmat[b1].reshape(3, 3) @ m.eq_data[e, :3]
                    p1, p2 = self.to_zero(b1, world), self.to_zero(b2, world)
            turn = None
            if kinds[kind] == FIXED and not sites:
                p1, p2, turn = self.weld(b1, b2, m.eq_data[e])
            out.append(GraphJoint(name=name, kind=kinds[kind], parent=self.body_name(b2),
                                  child=self.body_name(b1), point=p2, child_point=p1,
                                  axis=np.array([0.0, 0.0, 1.0]), role=CONSTRAINT,
                                  element=where, turn=turn))
        return out

    def weld(self, b1: int, b2: int, data: np.ndarray):
        """A body weld's two points at the zero pose and body1's turn relative to body2.

        MuJoCo holds body2 at ``relpose`` in body1's frame (``eq_data[3:10]``, filled from
        ``qpos0`` when the file leaves it out) and its anchor (``eq_data[:3]``, body2's frame)
        at the same place of body1.
        """
        r1, r2 = self.zero.xmat[b1].reshape(3, 3), self.zero.xmat[b2].reshape(3, 3)
        rel = np.zeros(9)
        self.mj.mju_quat2Mat(rel, np.asarray(data[6:10], dtype=float))
        rel = rel.reshape(3, 3)
        anchor = np.asarray(data[:3], dtype=float)
        p2 = self.zero.xpos[b2] + r2 @ anchor
        p1 = self.zero.xpos[b1] + r1 @ (np.asarray(data[3:6], dtype=float) + rel @ anchor)
        # at the weld r1' = T1 r1, r2' = T2 r2 (turns about the normal) and r1'^T r2' = rel,
        # so T1^T T2 = r1 rel r2^T: body1's turn relative to body2 is its transpose
        return p1, p2, r2 @ rel.T @ r1.T

    def actuators(self, ignored: list) -> list:
        m, mj = self.m, self.mj
        out = []
        for a in range(m.nu):
            name = self.obj_name(mj.mjtObj.mjOBJ_ACTUATOR, a) or f"actuator{a}"
            plain = (int(m.actuator_trntype[a]) == int(mj.mjtTrn.mjTRN_JOINT)
                     and int(m.actuator_dyntype[a]) == int(mj.mjtDyn.mjDYN_NONE)
                     and int(m.actuator_gaintype[a]) == int(mj.mjtGain.mjGAIN_FIXED)
                     and int(m.actuator_biastype[a]) == int(mj.mjtBias.mjBIAS_NONE))
            if not plain:
                ignored.append(f"actuator '{name}' (not a motor on a joint)")
                continue
            joint = self.obj_name(mj.mjtObj.mjOBJ_JOINT, int(m.actuator_trnid[a, 0]))
            gain, gear = float(m.actuator_gainprm[a, 0]), float(m.actuator_gear[a, 0])
            bounds = []  # on the command (MuJoCo's control)
            if m.actuator_ctrllimited[a]:
                bounds.append(float(np.max(np.abs(m.actuator_ctrlrange[a]))))
            if m.actuator_forcelimited[a] and gain != 0:
                bounds.append(float(np.max(np.abs(m.actuator_forcerange[a]))) / abs(gain))
            limit = min(bounds) if bounds else None
            scale = gain * gear  # joint effort per unit of control
            if scale > 0:
                out.append(GraphActuator(joint, limit, f"<actuator> '{name}'", gear=scale))
            elif scale < 0:  # the scene's gear is positive: the command becomes the effort
                out.append(GraphActuator(joint, None if limit is None else -scale * limit,
                                         f"<actuator> '{name}'"))
        return out
