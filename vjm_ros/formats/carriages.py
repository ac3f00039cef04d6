"""Massless carriages of a joint graph as the closures they stand for.

Formats without a point-on-line or a fixed-angle constraint write them with a carriage: a body
of negligible mass between two links, joined to one by slides and to the other by a pin or a
weld (Gazebo's way, and ``vjm export``'s in ``<gazebo>`` and in MJCF). Such a body adds
coordinates and a mass the mechanism does not have; this module replaces it by the constraint:

* a carriage joined to link ``A`` by a prismatic joint (axis ``d``) and to link ``B`` by a
  revolute joint or a ``connect``: ``B``'s point stays on the line along ``d`` carried by ``A``
  (:data:`SLIDE`, the scene's ``slider`` closure);
* carriages joined to ``A`` and ``B`` only by prismatic joints of two directions and welds:
  ``B`` keeps its angle to ``A`` (:data:`ALIGN`, the scene's ``angle`` closure).

A body is a carriage when its mass is at most :data:`CARRIAGE_FRACTION` of the model's: dropping
it changes the dynamics by less than that fraction. Light bodies in other arrangements stay
links. The closure takes the name of the carriage's joint or constraint towards ``B`` (the one
whose parent is the carriage).
"""

from __future__ import annotations

import numpy as np

from vjm_ros.formats.graph import (
    CONNECT,
    CONSTRAINT,
    FIXED,
    PRISMATIC,
    REVOLUTE,
    WORLD,
    GraphJoint,
    JointGraph,
)

SLIDE, ALIGN = "slide", "align"
"""Kinds of the constraints a carriage stands for: a point on a line, a fixed relative angle."""
CARRIAGE_FRACTION = 1e-6
"""Largest mass of a carriage over the model's total mass."""


def collapse_carriages(graph: JointGraph) -> JointGraph:
    """``graph`` with every carriage replaced by its constraint (the graph is changed in place).

    Returns
    -------
    JointGraph
    """
    total = sum(b.mass for b in graph.bodies.values())
    light = {n for n, b in graph.bodies.items() if b.mass <= CARRIAGE_FRACTION * total}
    if not light:
        return graph
    done: set[str] = set()
    for start in list(light):
        if start in done:
            continue
        group, frontier = {start}, [start]
        while frontier:
            k = frontier.pop()
            for j in graph.joints:
                for a, b in ((j.parent, j.child), (j.child, j.parent)):
                    if a == k and b in light and b not in group:
                        group.add(b)
                        frontier.append(b)
        done |= group
        replacement = _constraint(graph, group)
        if replacement is not None:
            inner = [j for j in graph.joints if j.parent in group or j.child in group]
            graph.joints = [j for j in graph.joints if j not in inner] + [replacement]
            for name in group:
                del graph.bodies[name]
    return graph


def _constraint(graph: JointGraph, group: set) -> GraphJoint | None:
    """The constraint a group of carriages stands for, or None."""
    touching = [j for j in graph.joints if j.parent in group or j.child in group]
    boundary = [j for j in touching if (j.parent in group) != (j.child in group)]
    if len(boundary) != 2:
        return None
    outer = [j.child if j.parent in group else j.parent for j in boundary]
    if outer[0] == outer[1]:
        return None
    kinds = [j.kind for j in touching]
    slides = [j for j in touching if j.kind == PRISMATIC]
    pins = [j for j in touching if j.kind in (REVOLUTE, CONNECT)]
    if any(k not in (PRISMATIC, REVOLUTE, CONNECT, FIXED) for k in kinds) or not slides:
        return None
    # towards B: the boundary joint whose parent is a carriage (the later one if both are)
    towards_b = [k for k, j in enumerate(boundary) if j.parent in group]
    kb = towards_b[-1] if towards_b else 1
    a, b = outer[1 - kb], outer[kb]
    named = boundary[kb]
    if len(pins) == 1 and len(slides) == 1 and pins[0] in boundary:
        pin, slide = pins[0], slides[0]
        # the pinned link carries the point; the other carries the line
        pinned = pin.child if pin.parent in group else pin.parent
        line_side = a if pinned == b else b
        point_on_pinned = pin.child_point if pin.child == pinned else pin.point
        point_on_line = pin.point if pin.child == pinned else pin.child_point
        return GraphJoint(name=named.name, kind=SLIDE, parent=line_side, child=pinned,
                          point=point_on_line.copy(), child_point=point_on_pinned.copy(),
                          axis=slide.axis.copy(), role=CONSTRAINT, element=named.element)
    # slides along two directions that are not parallel span the plane: only the angle is held
    if not pins and any(np.linalg.norm(np.cross(slides[0].axis, j.axis)) > 1e-6
                        for j in slides[1:]):
        p = (graph.bodies[b].origin if b != WORLD else np.zeros(3)).copy()
        return GraphJoint(name=named.name, kind=ALIGN, parent=a, child=b, point=p,
                          child_point=p.copy(), axis=slides[0].axis.copy(), role=CONSTRAINT,
                          element=named.element)
    return None
