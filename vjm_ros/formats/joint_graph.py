"""Planar reduction of a :class:`~vjm_ros.formats.graph.JointGraph` into a scene document.

The steps (``docs/models.md`` says the same for users):

1. **Plane.** The normal ``N`` is the common axis of the revolute joints (prismatic axes must be
   perpendicular to it); the in-plane basis ``(e1, e2)``, ``e1 x e2 = N``, puts the projected
   gravity along ``-e2``.
2. **Rigid groups.** Bodies joined by fixed joints of the file's tree (or graph) become one link
   (masses, mass centres and inertias about ``N`` combined; the other bodies' origins become named
   points); a group fixed to the world is ground.
3. **Chains.** The links are covered by paths that start at the ground (a search over the joint
   graph); a revolute joint is walked from parent to child when its axis is ``+N`` and from child
   to parent when it is ``-N``, so that the scene's coordinate (``theta_child - theta_pred`` about
   ``+N``) equals the file's joint position either way. The joints left over become closures.
4. **Frames.** At the zero pose, links joined by revolute joints share one angle ``psi``, so every
   revolute coordinate is the file's position; a prismatic joint fixes ``psi`` of the links before
   it (``n(psi)`` along its axis). A link's origin is the joint in front of it.
"""

from __future__ import annotations

import math

import numpy as np

from vjm_ros.core.errors import SceneError
from vjm_ros.formats.carriages import SLIDE, collapse_carriages
from vjm_ros.formats.graph import (
    CONSTRAINT,
    FIXED,
    GRAPH,
    PRISMATIC,
    REVOLUTE,
    TREE,
    WORLD,
    JointGraph,
)
from vjm_ros.formats.scene_document import SceneWriter

PARALLEL_TOLERANCE = 1e-6
"""Largest ``|sin|`` of the angle between axes that count as parallel (and ``|cos|`` for
perpendicular): a file's axes are written to 6-17 digits, and a larger tilt is a 3-D model."""
SEARCH_BUDGET = 20_000
"""Largest number of steps of the search for chains before the model is refused."""
MAX_COVERS = 64
"""Largest number of covers by chains tried for link frames (step 4) before the model is
refused with the first one's reason."""


class _Reducer(SceneWriter):
    """One reduction (the steps of the module docstring); :meth:`document` runs them."""

    def __init__(self, graph: JointGraph, actuate: tuple[str, ...]):
        self.g = graph
        self.path = graph.source
        self.extra = tuple(actuate)
        self.actuated = {a.joint for a in graph.actuators} | set(actuate)

    def fail(self, where: str, expected: str, found: object = ...) -> SceneError:
        return SceneError(self.path, where, expected, found)

    # ---------------------------------------------------------------------- 1. plane
    def plane(self) -> None:
        g = self.g
        revolute = [j for j in g.joints if j.kind == REVOLUTE]
        prismatic = [j for j in g.joints if j.kind in (PRISMATIC, SLIDE)]
        if revolute:
            chain_like = [j for j in revolute if j.role != CONSTRAINT] or revolute
            ref = chain_like[0].axis
            votes = sum(1 if float(j.axis @ ref) > 0 else -1 for j in chain_like
                        if j.role == TREE)
            normal = ref if votes >= 0 else -ref
        elif len(prismatic) >= 1:
            normal = None
            for j in prismatic[1:]:
                c = np.cross(prismatic[0].axis, j.axis)
                if np.linalg.norm(c) > PARALLEL_TOLERANCE:
                    normal = c / np.linalg.norm(c)
                    break
            if normal is None:  # one direction of sliding: the plane holds it and gravity
                c = np.cross(prismatic[0].axis, g.gravity)
                if np.linalg.norm(c) < PARALLEL_TOLERANCE:
                    c = np.cross(prismatic[0].axis, [1.0, 0.0, 0.0])
                    if np.linalg.norm(c) < PARALLEL_TOLERANCE:
                        c = np.cross(prismatic[0].axis, [0.0, 1.0, 0.0])
                normal = c / np.linalg.norm(c)
        else:
            raise self.fail("(model)", "at least one revolute or prismatic joint", "none")
        for j in revolute:
            if np.linalg.norm(np.cross(j.axis, normal)) > PARALLEL_TOLERANCE:
                raise self.fail(
                    j.element, f"a revolute axis parallel to the others ({_vec(normal)}): the "
                    "planar model turns every link about one normal", _vec(j.axis))
        for j in prismatic:
            if abs(float(j.axis @ normal)) > PARALLEL_TOLERANCE:
                raise self.fail(
                    j.element, f"a prismatic axis in the plane of motion (perpendicular to "
                    f"{_vec(normal)})", _vec(j.axis))
        self.set_normal(normal)

    def set_normal(self, normal: np.ndarray) -> None:
        """``N``, ``e1``, ``e2`` and the gravity in the plane."""
        self.normal = normal / np.linalg.norm(normal)
        g_in = self.g.gravity - (self.g.gravity @ self.normal) * self.normal
        if np.linalg.norm(g_in) > 1e-12 * max(1.0, float(np.linalg.norm(self.g.gravity))):
            e2 = -g_in / np.linalg.norm(g_in)
        else:  # a horizontal plane: e1 along the world axis closest to the plane
            k = int(np.argmin(np.abs(self.normal)))
            e1 = np.eye(3)[k] - self.normal[k] * self.normal
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(self.normal, e1)
        self.e2 = e2
        self.e1 = np.cross(e2, self.normal)

    def flat(self, p) -> np.ndarray:
        """A world point (or direction) in the plane's coordinates, (2,)."""
        p = np.asarray(p, dtype=float)
        return np.array([p @ self.e1, p @ self.e2])

    # ---------------------------------------------------------------------- 2. rigid groups
    def groups(self) -> None:
        g = self.g
        parent = {name: name for name in [WORLD, *g.bodies]}

        def find(x):
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        for j in g.joints:
            for end in (j.parent, j.child):
                if end != WORLD and end not in g.bodies:
                    raise self.fail(j.element, "a link or body of the model (or 'world')", end)
            if j.kind == FIXED and j.role in (TREE, GRAPH):
                a, b = find(j.parent), find(j.child)
                if a != b:
                    if b == WORLD:
                        a, b = b, a
                    parent[b] = a
        self.group_of = {name: find(name) for name in parent}
        members: dict[str, list[str]] = {}
        for name in g.bodies:
            members.setdefault(self.group_of[name], []).append(name)
        self.members = members
        self.links = [k for k in members if k != WORLD]
        self.props = {}
        for k in self.links:
            bodies = [g.bodies[b] for b in members[k]]
            m = sum(b.mass for b in bodies)
            c2 = [self.flat(b.com) for b in bodies]
            com = (sum(b.mass * c for b, c in zip(bodies, c2, strict=True)) / m if m > 0
                   else c2[0])
            inertia = sum(float(self.normal @ b.inertia @ self.normal)
                          + b.mass * float((c - com) @ (c - com))
                          for b, c in zip(bodies, c2, strict=True))
            self.props[k] = (m, com, inertia)
        ground = [b for b in members.get(WORLD, [])]
        if ground:
            self.g.ignored.append(
                "the mass of the bodies fixed to the world (" + ", ".join(ground) + ")")
        self.edges = []
        for j in g.joints:
            if j.kind == FIXED and j.role in (TREE, GRAPH):
                continue
            a, b = self.group_of[j.parent], self.group_of[j.child]
            if a == b:
                raise self.fail(j.element, "a joint between two different rigid parts (it joins "
                                "bodies already fixed to each other)", f"{j.parent}, {j.child}")
            self.edges.append(j)

    # ---------------------------------------------------------------------- 3. chains
    def may_walk(self, j, forward: bool) -> bool:
        """Whether joint ``j`` may be a chain joint walked parent-to-child (``forward``)."""
        if j.role == CONSTRAINT or j.kind not in (REVOLUTE, PRISMATIC):
            return False
        if j.kind == PRISMATIC:
            return True
        return (float(j.axis @ self.normal) > 0) == forward

    def chains(self) -> None:
        """Ground-rooted paths covering every link (depth-first search, tree joints first)."""
        reached, frontier = {WORLD}, [WORLD]
        while frontier:
            k = frontier.pop()
            for j in self.edges:
                a, b = self.group_of[j.parent], self.group_of[j.child]
                for src, dst in ((a, b), (b, a)):
                    if src == k and dst not in reached:
                        reached.add(dst)
                        frontier.append(dst)
        for k in self.links:
            if k not in reached:
                raise self.fail(self.g.bodies[k].element or f"link '{k}'",
                                "a link joined to the world through joints or constraints (a "
                                "floating base has no planar chain)", f"link '{k}' floating")
        moves: dict[str, list] = {k: [] for k in [WORLD, *self.links]}
        for order, j in enumerate(self.edges):
            a, b = self.group_of[j.parent], self.group_of[j.child]
            # a tree's joints first; in a joint graph (SDFormat) the actuated ones, then the
            # ones written first, so that the joints written last close the loops
            rank = ((0, 0, 0) if j.role == TREE else
                    (0, j.name not in self.actuated, order) if j.role == GRAPH else
                    (1, j.name not in self.actuated, 0))
            for src, dst, forward in ((a, b, True), (b, a, False)):
                if self.may_walk(j, forward):
                    moves[src].append(((*rank, not forward, order), dst, j, forward))
        for k in moves:
            moves[k].sort(key=lambda m: m[0])
        self.moves = moves
        self.steps, self.covers, self.frame_error = 0, 0, None
        self.best: set[str] = set()
        found = self._search([], set(), None)
        if found is None and self.frame_error is not None:
            raise self.frame_error
        if found is None and self.steps <= SEARCH_BUDGET:
            self.sign_refusal(moves)
        if found is None:
            missing = [k for k in self.links if k not in self.best]
            name = missing[0] if missing else self.links[0]
            why = ("the search for chains ran out of steps" if self.steps > SEARCH_BUDGET else
                   "hangs off a moving link with no way back to the ground (a branch): the "
                   "planar model's chains start at the ground and each link belongs to one")
            raise self.fail(self.g.bodies[name].element or f"link '{name}'",
                            "a link reached by a chain from the ground through its own joints "
                            "(close the branch with a loop joint, or weld it to its parent)",
                            f"link '{name}' {why}")

    def sign_refusal(self, moves: dict) -> None:
        """Refuse naming the joint whose axis sign is what leaves no chains, if it is one."""
        signed = self.moves
        self.moves = {k: [] for k in moves}
        for order, j in enumerate(self.edges):
            if j.role == CONSTRAINT or j.kind not in (REVOLUTE, PRISMATIC):
                continue
            a, b = self.group_of[j.parent], self.group_of[j.child]
            self.moves[a].append(((0, order), b, j, True))
            self.moves[b].append(((1, order), a, j, False))
        for k in self.moves:
            self.moves[k].sort(key=lambda m: m[0])
        self.steps, best = 0, self.best
        found = self._search([], set(), None, place=False)
        self.moves, self.best = signed, best
        if found is None:
            return
        for ch in found:
            for j, forward, _ in ch:
                if not self.may_walk(j, forward):
                    raise self.fail(
                        j.element, f"a revolute axis along the plane normal {_vec(self.normal)} "
                        "like the other joints' (or a loop through the joint, which then closes "
                        "it): the scene's coordinate would be minus the file's position",
                        f"the opposite axis {_vec(j.axis)}")

    def _search(self, chains: list, covered: set, end: str | None, place: bool = True):
        """A cover of the links by chains from ground (depth first), whose link frames can be
        placed (step 4) when ``place``; None when there is none within the budgets."""
        self.steps += 1
        if len(covered) > len(self.best):
            self.best = set(covered)
        if self.steps > SEARCH_BUDGET or self.covers >= MAX_COVERS:
            return None
        if len(covered) == len(self.links):
            cover = [list(c) for c in chains]
            if not place:
                return cover
            try:
                self.place(cover)
            except SceneError as exc:  # another cover may place them: keep looking
                self.covers += 1
                self.frame_error = self.frame_error or exc
                return None
            return cover
        options = []
        if end is not None:
            options += [(m, False) for m in self.moves[end] if m[1] not in covered]
        options += [(m, True) for m in self.moves[WORLD] if m[1] not in covered]
        # by rank; among equals a chain goes on before another starts (a tree is followed)
        options.sort(key=lambda o: (o[0][0][:3], o[1], o[0][0][3:]))
        for (_, dst, j, forward), new_chain in options:
            if new_chain:
                chains.append([])
            chains[-1].append((j, forward, dst))
            covered.add(dst)
            out = self._search(chains, covered, dst, place)
            if out is not None:
                return out
            covered.discard(dst)
            chains[-1].pop()
            if new_chain:
                chains.pop()
            if self.steps > SEARCH_BUDGET or self.covers >= MAX_COVERS:
                return None
        return None

    # ---------------------------------------------------------------------- 4. frames
    def oriented_axis(self, j, forward: bool) -> np.ndarray:
        """A prismatic joint's in-plane axis, as the motion of the link in front of it, (2,)."""
        d = self.flat(j.axis)
        d = d / np.linalg.norm(d)
        return d if forward else -d

    def chain_frames(self, ch: list) -> tuple[float, np.ndarray, list]:
        """Ground angle, ground origin and ``[(joint, forward, link, origin, psi, length)]``.

        Joint ``k`` of the chain sits in front of link ``k``. A run of links ``[i, r)`` starts at
        the chain's first joint or at a prismatic joint; the joints inside it are revolute, and
        joint ``r`` (if any) is prismatic and fixes the run's ``psi`` by its axis.
        """
        m = len(ch)
        # where each joint sits on the link in front of it, walked forward or backward
        points = [self.flat(j.point if fwd else j.child_point) for j, fwd, _ in ch]
        out = []
        ground_origin = points[0]
        first = ch[0][0]
        ground_psi = (_psi_normal(self.oriented_axis(first, ch[0][1]))
                      if first.kind == PRISMATIC else None)
        origin = ground_origin
        i = 0
        while i < m:
            r = i + 1
            while r < m and ch[r][0].kind == REVOLUTE:
                r += 1
            starts = [origin] + points[i + 1:r]
            if r < m:
                psi = _psi_normal(self.oriented_axis(ch[r][0], ch[r][1]))
            else:
                psi = self.free_psi(ch, i, r, starts, points)
            if ground_psi is None:
                ground_psi = psi
            u = np.array([math.cos(psi), math.sin(psi)])
            for k in range(i, r):
                o = starts[k - i]
                link = ch[k][2]
                if k + 1 < m:
                    s = float((points[k + 1] - o) @ u)
                    if ch[k + 1][0].kind == REVOLUTE and s < -1e-9:
                        raise self.fail(
                            ch[k + 1][0].element,
                            f"a joint ahead of link '{link}' along the link's x axis (shared by "
                            "the links joined to it by revolute joints; a scene link's next "
                            "joint lies at a length >= 0 along it)",
                            f"joint '{ch[k + 1][0].name}' {-s:.6g} m behind")
                    length = max(s, 0.0)
                else:
                    length = max(float((self.far_point(link, o) - o) @ u), 0.0)
                out.append((ch[k][0], ch[k][1], link, o, psi, length))
                self.frame[link] = (o, psi)
            origin = starts[-1] + out[-1][5] * u
            i = r
        return ground_psi, ground_origin, out

    def far_point(self, link: str, o: np.ndarray) -> np.ndarray:
        """The closure anchor of ``link`` farthest from ``o`` (its mass centre without one), (2,)."""
        pts = self.anchors[link] or [self.props[link][1]]
        return max(pts, key=lambda p: float(np.hypot(*(p - o))))

    def free_psi(self, ch, i: int, r: int, starts: list, points: list) -> float:
        """``psi`` of the chain's last run, which no prismatic joint fixes: the first link points
        at its next joint if the others' next joints then lie ahead too (else the closest angle
        that makes them), or at its farthest closure anchor."""
        vectors = [points[k + 1] - starts[k - i] for k in range(i, r - 1)]
        vectors = [v for v in vectors if np.hypot(*v) > 1e-12]
        if not vectors:
            v = self.far_point(ch[i][2], starts[0]) - starts[0]
            return math.atan2(v[1], v[0]) if np.hypot(*v) > 1e-12 else 0.0
        ref = math.atan2(vectors[0][1], vectors[0][0])
        rel = [math.remainder(math.atan2(v[1], v[0]) - ref, 2 * math.pi) for v in vectors]
        lo, hi = max(x - math.pi / 2 for x in rel), min(x + math.pi / 2 for x in rel)
        return ref + (min(max(0.0, lo), hi) if lo <= hi else 0.0)

    def reduce(self) -> None:
        """Steps 1-4 (a model whose chains need the other sign of ``N`` gets it)."""
        self.plane()
        self.groups()
        try:
            self.chains()
        except SceneError as first:
            if not any(j.kind == REVOLUTE for j in self.edges):
                raise
            self.set_normal(-self.normal)
            self.groups()
            try:
                self.chains()
            except SceneError:
                raise first from None

    def place(self, cover: list) -> None:
        """Step 4 for one cover: closures, link frames and lengths (a SceneError if a link's
        next joint lies behind it)."""
        self.chain_list = cover
        self.frame = {}
        in_chain = {j.name for ch in cover for j, _, _ in ch}
        self.closure_joints = [j for j in self.edges if j.name not in in_chain]
        self.anchors = {k: [] for k in self.links}
        for j in self.closure_joints:
            for body, p in ((j.parent, j.point), (j.child, j.child_point)):
                if self.group_of[body] != WORLD:
                    self.anchors[self.group_of[body]].append(self.flat(p))
        self.chain_docs = [self.chain_frames(ch) for ch in cover]

def reduce_graph(graph: JointGraph, actuate: tuple[str, ...] = ()) -> dict:
    """The scene document of ``graph``, with actuators on the joints named in ``actuate``.

    Parameters
    ----------
    graph : JointGraph
        A model read by one of the format readers.
    actuate : tuple of str
        Joints to actuate besides those the file actuates (unlimited effort).

    Returns
    -------
    dict
        A scene document (``docs/design.md`` section 4), angles in radians.

    Raises
    ------
    SceneError
        Naming the file and the element the planar model cannot represent.
    """
    return _Reducer(collapse_carriages(graph), tuple(actuate)).document()


def _psi_normal(d: np.ndarray) -> float:
    """The angle ``psi`` whose normal ``n(psi) = (-sin psi, cos psi)`` is the unit vector ``d``."""
    return math.atan2(-d[0], d[1])


def _vec(v) -> str:
    return "(" + ", ".join(f"{float(x):.6g}" for x in v) + ")"
