"""The scene document of a reduced joint graph: chains, closures, actuators, named points.

:class:`SceneWriter` is the second half of :class:`~vjm_ros.formats.joint_graph._Reducer`: once
the plane, the rigid groups, the chains and the link frames are known (``frame``, ``group_of``,
``props``, ``chain_docs``, ``closure_joints``), it writes them as a scene document
(docs/design.md section 4), a plain dict: the start pose as absolute angles and slides, loop
joints and constraints as hinge, slider and angle closures, the file's actuators and
``--actuate``'s, sites and frames as named points, and the provenance.
"""

from __future__ import annotations

import math
import re

import numpy as np

from vjm_ros.formats.carriages import ALIGN, SLIDE
from vjm_ros.formats.graph import CONNECT, FIXED, PRISMATIC, REVOLUTE, WORLD


def scene_name(text: str) -> str:
    """``text`` as a scene identifier: letters, digits and ``_``, not starting with a digit."""
    out = re.sub(r"\W", "_", text, flags=re.ASCII) or "model"
    return out if not out[0].isdigit() else f"n_{out}"


def plain(x: float) -> float:
    """A plain float, with the round-off of the projection (below 1e-15 m) cleared."""
    x = float(x)
    return 0.0 if abs(x) < 1e-15 else x


class SceneWriter:
    """The document-writing half of the reduction (attributes set by the reducer)."""

    def local(self, link: str, p2: np.ndarray) -> list[float]:
        """A point of the plane in ``link``'s frame at the zero pose, ``[s, w]``."""
        o, psi = self.frame[link]
        d = np.asarray(p2) - o
        c, s = math.cos(psi), math.sin(psi)
        return [plain(d[0] * c + d[1] * s), plain(-d[0] * s + d[1] * c)]

    def document(self) -> dict:
        """The scene document (a plain dict, as a scene YAML file holds)."""
        self.reduce()
        g = self.g
        self.names = {j.name: scene_name(j.name) for j in g.joints}
        self.theta = {WORLD: 0.0}
        chains = [self.chain_doc(c, doc) for c, doc in enumerate(self.chain_docs)]
        doc = {
            "name": scene_name(g.name),
            "description": f"{g.format} model '{g.name}' imported from {g.source}",
            "provenance": self.provenance(),
            "units": {"angle": "radians"},
            "gravity": [plain(x) for x in self.flat(g.gravity)],
            "chains": chains,
        }
        closures = self.closures()
        if closures:
            doc["closures"] = closures
        actuators = self.actuators()
        if actuators:
            doc["actuators"] = actuators
        points = self.points(len(chains))
        if points:
            doc["points"] = points
        doc["closure_method"] = {"method": "exact"}
        doc["defaults"] = {"integrator": "rk4", "rate": 1000, "duration": 10}
        return doc

    def chain_doc(self, c: int, frames: tuple[float, np.ndarray, list]) -> dict:
        ground_psi, ground_origin, rows = frames
        links = []
        theta, psi_prev = ground_psi, ground_psi
        o_prev, a_prev = ground_origin, 0.0
        for j, _fwd, link, o, psi, length in rows:
            if j.kind == REVOLUTE:
                theta += j.start
                tip = o_prev + a_prev * np.array([math.cos(psi_prev), math.sin(psi_prev)])
                slide = float((o - tip) @ np.array([-math.sin(psi_prev), math.cos(psi_prev)]))
            else:
                theta += psi - psi_prev
                slide = j.start
            self.theta[link] = theta
            mass, com, inertia = self.props[link]
            joint = {"name": self.names[j.name], "type": j.kind, "angle": plain(theta),
                     "slide": plain(slide)}
            if j.velocity:
                joint["velocity"] = plain(j.velocity)
            for key in ("damping", "armature", "friction"):
                if getattr(j, key):
                    joint[key] = plain(getattr(j, key))
            links.append({
                "name": scene_name(link), "length": plain(length), "mass": plain(mass),
                "inertia": plain(inertia), "com": self.local(link, com), "joint": joint,
            })
            psi_prev, o_prev, a_prev = psi, o, length
        return {"name": f"chain{c + 1}", "origin": [plain(x) for x in ground_origin],
                "angle": plain(ground_psi), "length": 0.0, "links": links}

    def end(self, body: str, p: np.ndarray) -> dict:
        """A closure end: a link point, or a ground point."""
        k = self.group_of[body]
        if k == WORLD:
            return {"ground": [plain(x) for x in self.flat(p)]}
        return {"link": scene_name(k), "at": self.local(k, self.flat(p))}

    def closures(self) -> list:
        out = []
        for j in self.closure_joints:
            name = self.names[j.name]
            b = self.group_of[j.child]
            # the constrained point on the child, unless the child is the ground
            (pb, qb), (pa, qa) = (((j.child, j.child_point), (j.parent, j.point)) if b != WORLD
                                  else ((j.parent, j.point), (j.child, j.child_point)))
            if j.kind in (REVOLUTE, CONNECT, FIXED):
                out.append({"name": name, "type": "hinge", "point": self.end(pb, qb),
                            "target": self.end(pa, qa)})
            elif j.kind in (PRISMATIC, SLIDE):
                line = self.end(pa, qa)
                d = self.flat(j.axis)
                d = d / np.linalg.norm(d)
                ka = self.group_of[pa]
                if ka != WORLD:
                    psi = self.frame[ka][1]
                    c, s = math.cos(psi), math.sin(psi)
                    d = np.array([d[0] * c + d[1] * s, -d[0] * s + d[1] * c])
                line["direction"] = [plain(x) for x in d]
                out.append({"name": name, "type": "slider", "point": self.end(pb, qb),
                            "line": line})
            if j.kind in (PRISMATIC, FIXED, ALIGN):
                la, lb = self.group_of[pb], self.group_of[pa]
                target = {"ground": True} if lb == WORLD else {"link": scene_name(lb)}
                if j.turn is None:
                    offset = self.constraint_angle(la) - self.constraint_angle(lb)
                else:  # the child's turn relative to the parent where the constraint holds
                    t = j.turn @ self.e1
                    turn = math.atan2(float(t @ self.e2), float(t @ self.e1))
                    psi = {k: (0.0 if k == WORLD else self.frame[k][1]) for k in (la, lb)}
                    offset = psi[la] - psi[lb] + (turn if la == b else -turn)
                out.append({"name": name if j.kind == ALIGN else f"{name}_angle",
                            "type": "angle", "link": scene_name(la), "target": target,
                            "offset": plain(offset)})
        return out

    def constraint_angle(self, link: str) -> float:
        """The scene angle of ``link`` at the pose where the file's constraints hold, rad."""
        if link == WORLD:
            return 0.0
        turn = self.g.bodies[link].turn @ self.e1
        return self.frame[link][1] + math.atan2(float(turn @ self.e2), float(turn @ self.e1))

    def actuators(self) -> list:
        chain_joints = {j.name for ch in self.chain_list for j, _, _ in ch}
        by_name = {j.name: j for j in self.g.joints}
        sanitized = {v: k for k, v in self.names.items()}
        out, seen = [], set()
        wanted = [(a.joint, a.limit, a.element, a.gear) for a in self.g.actuators]
        wanted += [(sanitized.get(n, n), None, "--actuate", 1.0) for n in self.extra]
        for name, limit, element, gear in wanted:
            if name not in by_name:
                raise self.fail(element, "a joint of the model ("
                                + ", ".join(by_name) + ")", name)
            if name not in chain_joints:
                raise self.fail(element, "an actuated joint that is a coordinate of the scene "
                                f"(joint '{name}' closes a loop, or is fixed)", name)
            if name in seen:
                continue
            seen.add(name)
            entry = {"joint": self.names[name]}
            if gear != 1.0:
                entry["gear"] = plain(gear)
            if limit is not None and limit > 0 and math.isfinite(limit):
                entry["limit"] = plain(limit)
            out.append(entry)
        return out

    def points(self, n_chains: int) -> list:
        out = []
        taken = {f"chain{c + 1}_tip" for c in range(n_chains)}
        for k in self.links:
            for body_name in self.members[k]:
                body = self.g.bodies[body_name]
                named = dict(body.points)
                if body_name != k:
                    named = {body_name: body.origin, **named}
                for pname, p in named.items():
                    name = scene_name(pname)
                    if name in taken:
                        continue
                    taken.add(name)
                    out.append({"name": name, "link": scene_name(k),
                                "at": self.local(k, self.flat(p))})
        return out

    def provenance(self) -> str:
        g = self.g
        renamed = {k: v for k, v in self.names.items() if k != v}
        lines = [f"Imported by vjm import from {g.source} ({g.format}). Joint coordinates are "
                 "the file's joint positions; link frames are placed at the file's zero pose."]
        closing = [j.name for j in self.closure_joints]
        lossy = [j.name for j in self.closure_joints if j.damping or j.armature or j.friction]
        if lossy:
            g.ignored.append("damping, armature and friction of the loop joints "
                             + ", ".join(lossy))
        if closing:
            lines.append("Loop joints and constraints closed as closures: "
                         + ", ".join(closing) + ".")
        if renamed:
            lines.append("Renamed: " + ", ".join(f"{k} -> {v}" for k, v in renamed.items()) + ".")
        if g.ignored:
            lines.append("Not represented: " + "; ".join(dict.fromkeys(g.ignored)) + ".")
        return "\n".join(lines)


