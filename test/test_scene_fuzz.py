"""Scene fuzzing: whatever a scene file holds, loading it ends well and soon.

Every generated file must load into a :class:`~vjm_ros.scene.loader.Scene` or raise a
:class:`~vjm_ros.core.errors.SceneError` that names the file and a key path, within ``CASE_SECONDS``
(measured per case, and enforced by an alarm so that a hang fails instead of stalling the run).
The key path must name something real: a line and column inside the file, the file itself
(``FILE_KEY``), the top level (``TOP_KEY``), or a path that exists in the document (its last part
may be the missing key that the error is about).

Cases come from four sources:

* the built-in scenes mutated at random key paths (keys dropped, types swapped, junk or extreme
  values inserted, names duplicated, references broken, values shared through YAML aliases);
* plausible scenes generated from scratch, half of them mutated in the same ways;
* YAML-level attacks: alias "billion laughs", merge-key bombs, deep nesting, large documents;
* text and byte junk: edited scene text, malformed or tagged YAML scalars (``!!int x``,
  ``2020-02-30``), random YAML-ish text, non-UTF-8 bytes, binary data.

The default suite runs ``FAST_CASES`` derandomized cases; ``-m slow`` runs ``SLOW_CASES`` random
ones. Run with ``-s`` to see the case counts, outcomes and the slowest case.
"""

from __future__ import annotations

import copy
import math
import re
import signal
import time
from collections import Counter
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vjm_ros.core.errors import SceneError
from vjm_ros.scene.limits import FILE_KEY, MAX_LINKS, MAX_SCENE_BYTES, TOP_KEY
from vjm_ros.scene.loader import Scene, builtin_scene_text, builtin_scenes, load_scene
from vjm_ros.scene.safe_yaml import SceneLoader

# A hang guard, not a speed target: the slowest fuzz case loads in ~0.04 s here and the largest
# scene in ~0.01 s, so 20 s (500x) only trips on a runaway (super-linear) load, on any machine.
CASE_SECONDS = 20.0
FAST_CASES = 150
SLOW_CASES = 1200

BUILTINS = builtin_scenes()
BUILTIN_DOCS = {
    name: yaml.load(builtin_scene_text(name), Loader=SceneLoader)  # noqa: S506 (safe loader)
    for name in BUILTINS
}

LINE_KEY = re.compile(r"line (\d+), column (\d+)")


class _Dumper(yaml.SafeDumper):
    """Writes strings that the scene loader would read as numbers (``1e5``) in quotes."""


_Dumper.yaml_implicit_resolvers = SceneLoader.yaml_implicit_resolvers


def dump(doc, flow: bool = False) -> bytes:
    """YAML bytes of ``doc`` (shared or recursive values become anchors and aliases)."""
    return yaml.dump(
        doc, Dumper=_Dumper, sort_keys=False, allow_unicode=True, default_flow_style=flow
    ).encode("utf-8")


# --------------------------------------------------------------------------- values

# fmt: off
TRICKY_NUMBERS = [
    0, 0.0, -0.0, -1, -0.5, -1e-300, 1e-300, 1e6, 1e6 + 1, -1e6, 1e300, -1e300, 10**400, -(10**30),
    math.inf, -math.inf, math.nan, True, False,
]
TRICKY_STRINGS = [
    "", " ", "tip", "origin", "com", "ground", "revolute", "prismatic", "spherical", "hinge",
    "slider", "angle", "weld", "penalty", "exact", "rk4", "nope", "degrees", "grads", "1e5",
    "0x10", "yes", "~", ".nan", "2020-02-30", "crank", "chain1", "é", "a" * 300, "two words",
    "9lives", "<<", "*alias", "\t", "a\nb", "\x7f",
]
# fmt: on

junk_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.floats(),
    st.sampled_from(TRICKY_NUMBERS),
    st.text(max_size=12),
    st.sampled_from(TRICKY_STRINGS),
    st.binary(max_size=6),
)
junk_keys = st.one_of(
    st.sampled_from(["name", "type", "link", "at", "ground", "joint", "length", "mass", "junk"]),
    st.text(max_size=8),
    st.integers(-3, 3),
    st.none(),
)
junk = st.recursive(
    junk_scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(junk_keys, inner, max_size=4)
    ),
    max_leaves=10,
)
tricky = st.one_of(st.sampled_from(TRICKY_NUMBERS), st.sampled_from(TRICKY_STRINGS))

ident = st.from_regex(r"[a-z][a-z0-9_]{0,5}", fullmatch=True)
length = st.floats(0.05, 3.0)
mass = st.floats(0.1, 5.0)
small = st.floats(-3.0, 3.0)
vec = st.lists(small, min_size=2, max_size=2)


# --------------------------------------------------------------------------- cases


@dataclass
class Case:
    """One generated scene file.

    Attributes
    ----------
    kind : str
        Where it came from (for the statistics).
    data : bytes
        The file contents.
    doc : object
        The document it encodes, when known (else it is read back for the key-path check).
    """

    kind: str
    data: bytes
    doc: object = None

    def __repr__(self) -> str:
        shown = self.data if len(self.data) <= 2000 else self.data[:2000] + b"..."
        return f"Case({self.kind!r}, {len(self.data)} bytes: {shown!r})"


@st.composite
def scratch_scenes(draw):
    """A plausible scene built from nothing; half of them then mutated like the built-ins."""
    doc: dict = {"name": draw(ident)}
    if draw(st.booleans()):
        doc["units"] = {"angle": draw(st.sampled_from(["degrees", "radians"]))}
    if draw(st.integers(0, 4)) == 0:
        doc["gravity"] = draw(vec)
    links, joints, chains = [], [], []
    for _ in range(draw(st.integers(1, 3))):
        chain: dict = {}
        if draw(st.booleans()):
            chain["name"] = draw(ident)
        for key, strategy in (("origin", vec), ("angle", small), ("length", length)):
            if draw(st.integers(0, 2)) == 0:
                chain[key] = draw(strategy)
        chain["links"] = []
        for _ in range(draw(st.integers(1, 4))):
            link: dict = {"name": draw(ident), "length": draw(length)}
            links.append(link["name"])
            for key, strategy in (("mass", mass), ("inertia", mass), ("com", vec)):
                if draw(st.integers(0, 2)) == 0:
                    link[key] = draw(strategy)
            joint: dict = {"type": draw(st.sampled_from(["revolute", "prismatic"]))}
            for key, strategy in (
                ("name", ident),
                ("angle", small),
                ("slide", small),
                ("velocity", small),
            ):
                if draw(st.booleans()):
                    joint[key] = draw(strategy)
            joints.append(joint.get("name", "nope"))
            link["joint"] = joint
            chain["links"].append(link)
        chains.append(chain)
    doc["chains"] = chains
    link_ref, joint_ref = st.sampled_from(links), st.sampled_from(joints)
    point = st.one_of(
        st.fixed_dictionaries({"ground": vec}),
        st.fixed_dictionaries(
            {"link": link_ref},
            optional={"at": st.one_of(st.sampled_from(["tip", "origin", "com"]), vec)},
        ),
    )
    closures = []
    for _ in range(draw(st.integers(0, 2))):
        kind = draw(st.sampled_from(["hinge", "slider", "angle"]))
        closure: dict = {"type": kind}
        if draw(st.booleans()):
            closure["name"] = draw(ident)
        if kind == "slider":
            closure["point"] = draw(point)
            closure["line"] = {**draw(point), "direction": draw(vec)}
        elif kind == "angle":
            closure["link"] = draw(link_ref)
            closure["target"] = draw(
                st.one_of(st.just({"ground": True}), st.fixed_dictionaries({"link": link_ref}))
            )
            closure["offset"] = draw(small)
        else:
            closure["point"] = draw(point)
            closure["target"] = draw(point)
        closures.append(closure)
    if closures:
        doc["closures"] = closures
        if draw(st.booleans()):
            doc["assemble"] = {"fixed": draw(st.lists(joint_ref, max_size=2, unique=True))}
    if draw(st.booleans()):
        doc["actuators"] = draw(
            st.lists(
                st.fixed_dictionaries(
                    {"joint": joint_ref}, optional={"limit": mass, "effort": st.floats(-0.1, 0.1)}
                ),
                max_size=2,
            )
        )
    if draw(st.integers(0, 3)) == 0:
        doc["closure_method"] = draw(
            st.fixed_dictionaries(
                {"method": st.sampled_from(["penalty", "exact"])},
                optional={"kp": mass, "kv": mass, "alpha": mass, "beta": mass},
            )
        )
    if draw(st.integers(0, 3)) == 0:
        doc["defaults"] = draw(
            st.fixed_dictionaries(
                {},
                optional={
                    "integrator": st.sampled_from(["rk4", "dop853", "implicit_euler"]),
                    "rate": st.floats(1.0, 5000.0),
                    "substeps": st.integers(1, 20),
                    "duration": mass,
                },
            )
        )
    if draw(st.integers(0, 3)) == 0:
        doc["points"] = [{"name": draw(ident), "link": draw(link_ref)}]
    ops = mutate(draw, doc) if draw(st.booleans()) else []
    return Case(f"scratch:{'+'.join(ops)}", dump(doc, flow=draw(st.booleans())), doc)


def _paths(node, out):
    """``(container, key)`` of every value below ``node`` (each container once)."""
    seen = set()
    stack = [node]
    while stack:
        cur = stack.pop()
        if id(cur) in seen:
            continue
        seen.add(id(cur))
        items = cur.items() if isinstance(cur, dict) else enumerate(cur)
        for key, value in list(items):
            out.append((cur, key))
            if isinstance(value, (dict, list)):
                stack.append(value)
    return out


def _swapped(value, variant: int):
    """``value`` turned into another type."""
    if isinstance(value, bool):
        return [str(value).lower(), int(value), None][variant]
    if isinstance(value, (int, float)):
        return [str(value), [value], {"value": value}][variant]
    if isinstance(value, str):
        return [[value], {value: value}, len(value)][variant]
    if isinstance(value, list):
        return [{str(i): v for i, v in enumerate(value)}, value[0] if value else None, value * 2][
            variant
        ]
    if isinstance(value, dict):
        return [list(value.values()), list(value), str(value)][variant]
    return [{}, [], "none"][variant]


def _strings(node, out):
    """Every string value below ``node`` (to break references with names that exist elsewhere)."""
    for cont, key in _paths(node, []):
        if isinstance(cont[key], str) and len(cont[key]) < 40:
            out.append(cont[key])
    return out


MUTATIONS = [
    "drop", "junk", "swap", "duplicate", "tricky", "insert", "rename", "alias", "self", "extreme",
]  # fmt: skip


def mutate(draw, doc) -> list[str]:
    """Apply one to three mutations at uniformly chosen key paths of ``doc``; their names."""
    ops = []
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(doc, [])
        if not paths:
            break
        rng = draw(st.randoms(use_true_random=False))
        cont, key = rng.choice(paths)  # uniform: sampled_from favours the first entries
        op = draw(st.sampled_from(MUTATIONS))
        numbers = [(c, k) for c, k in paths if type(c[k]) in (int, float)]
        if op == "extreme" and numbers:  # a number field gets a negative, zero, huge or NaN value
            cont, key = rng.choice(numbers)
        ops.append(op)
        value = cont[key]
        if op == "drop":
            del cont[key]
        elif op == "junk":
            cont[key] = draw(junk)
        elif op == "swap":
            cont[key] = _swapped(value, draw(st.integers(0, 2)))
        elif op == "duplicate" and isinstance(cont, list):
            cont.insert(key, copy.deepcopy(value))
        elif op == "tricky":
            cont[key] = draw(tricky)
        elif op == "extreme":
            cont[key] = draw(st.sampled_from(TRICKY_NUMBERS))
        elif op == "insert" and isinstance(cont, dict):
            cont[draw(junk_keys)] = draw(junk)
        elif op == "insert":
            cont.insert(key, draw(junk))
        elif op == "alias":  # the same object twice: the dump writes an anchor and an alias
            other_cont, other_key = rng.choice(paths)
            cont[key] = other_cont[other_key]
        elif op == "self":  # a recursive document
            cont[key] = cont
        else:  # rename: a name that exists elsewhere, or none at all
            cont[key] = draw(st.sampled_from(_strings(doc, ["nope"])))
    return ops


@st.composite
def mutated_builtins(draw):
    """A built-in scene with one to three mutations at random key paths."""
    name = draw(st.sampled_from(BUILTINS))
    doc = copy.deepcopy(BUILTIN_DOCS[name])
    ops = mutate(draw, doc)
    return Case(f"mutated:{name}:{'+'.join(ops)}", dump(doc, flow=draw(st.booleans())), doc)


@st.composite
def text_edits(draw):
    """Built-in scene text cut, spliced or sprinkled with YAML punctuation or invalid bytes."""
    data = builtin_scene_text(draw(st.sampled_from(BUILTINS))).encode("utf-8")
    for _ in range(draw(st.integers(1, 3))):
        pos = draw(st.integers(0, len(data)))
        op = draw(st.sampled_from(["truncate", "delete", "insert", "byte"]))
        if op == "truncate":
            data = data[:pos]
        elif op == "delete":
            data = data[:pos] + data[pos + draw(st.integers(1, 40)) :]
        elif op == "insert":
            bit = draw(st.text(alphabet=":-[]{}&*!|>'\"#%@`,?\n\t ~0123456789.ae<", max_size=8))
            data = data[:pos] + bit.encode("utf-8") + data[pos:]
        else:
            data = data[:pos] + bytes([draw(st.integers(0x80, 0xFF))]) + data[pos:]
    return Case("text_edit", data)


# fmt: off
TRICKY_YAML = [
    "!!int x", "!!int ''", "!!float abc", "!!bool maybe", "!!timestamp x", "2020-02-30",
    "2020-13-01 25:61:00", "!!binary '==='", "!!python/object/apply:os.system ['true']",
    "!!set {a, b}", "!!omap [a]", "!!pairs [1]", "!!str [a]", "!!map [1]", "!!seq {a: 1}",
    "*undefined", "&a", "!<tag:x> 1", "!local 1", "1" * 5000, "0x" + "f" * 300, "1e99999", "-.inf",
    ".NaN", "190:20:30", "0b102", "0o9", "{<<: 5}", "{<<: [1]}", "? [1, 2]\n", "'unterminated",
    '"\\xZZ"', "|\n  block", "[1, 2", "}", "%YAML 1.1", "--- a", "...",
]
# fmt: on


@st.composite
def tagged_values(draw):
    """A built-in scene with one value replaced by a tagged, malformed or odd YAML scalar."""
    lines = builtin_scene_text(draw(st.sampled_from(BUILTINS))).split("\n")
    candidates = [i for i, line in enumerate(lines) if ": " in line]
    rng = draw(st.randoms(use_true_random=False))
    i = rng.choice(candidates)
    cut = [m.end() for m in re.finditer(": ", lines[i])]
    at = rng.choice(cut)
    lines[i] = (
        lines[i][:at]
        + draw(st.sampled_from(TRICKY_YAML))
        + (
            lines[i][at:][lines[i][at:].find(",") :]
            if draw(st.booleans()) and "," in lines[i][at:]
            else ""
        )
    )
    return Case("tagged", "\n".join(lines).encode("utf-8"))


def billion_laughs(levels: int, width: int, where: str) -> bytes:
    """Each level lists the previous one ``width`` times: ``width ** levels`` leaves."""

    def refs(i):
        return ", ".join([f"*l{i - 1}"] * width)

    if where == "key":
        lines = ["_l0: &l0 [lol]"] + [f"_l{i}: &l{i} [{refs(i)}]" for i in range(1, levels + 1)]
        return ("\n".join(lines) + "\nname: x\n").encode()
    value = "[&l0 [lol], " + ", ".join(f"&l{i} [{refs(i)}]" for i in range(1, levels + 1)) + "]"
    if where == "links":
        return f"name: x\nchains:\n  - links: {value}\n".encode()
    return f"name: x\n{where}: {value}\nchains: []\n".encode()


def merge_bomb(levels: int, fan: int) -> bytes:
    """Each level merges the previous one ``fan`` times (``fan ** levels`` entries unchecked)."""
    lines = ["name: x", "_m0: &m0 {a: 1, b: 2}"]
    for i in range(1, levels + 1):
        refs = ", ".join([f"*m{i - 1}"] * fan)
        lines.append(f"_m{i}: &m{i} {{<<: [{refs}], k{i}: {i}}}")
    lines.append(f"chains: [{{links: [{{<<: *m{levels}, length: 1, joint: {{type: revolute}}}}]}}]")
    return ("\n".join(lines) + "\n").encode()


def deep(depth: int, style: str, where: str) -> bytes:
    """A value nested ``depth`` levels deep, in flow or block style."""
    if style == "flow":
        value = "[" * depth + "1" + "]" * depth
        return f"name: x\n{where}: {value}\nchains: []\n".encode()
    depth = min(depth, 300)  # block indentation grows as depth squared (300: 90 kB, too large)
    body = "".join("  " * i + "- \n" for i in range(depth)) + "  " * depth + "- 1\n"
    return f"name: x\nchains: []\n{where}:\n{body}".encode()


def large(kind: str, n: int) -> bytes:
    """Documents near and beyond the size limits."""
    if kind == "links":
        links = "".join(
            f"      - {{length: 0.1, mass: 1.0, joint: {{type: revolute, angle: {i % 7}}}}}\n"
            for i in range(n)
        )
        return f"name: x\nchains:\n  - links:\n{links}".encode()
    if kind == "closures":
        links = "".join(
            f"      - {{name: l{i}, length: 0.5, mass: 1.0, inertia: 0.1, "
            f"joint: {{type: revolute}}}}\n"
            for i in range(min(n, 60))
        )
        closures = "".join(
            f"  - {{type: hinge, point: {{link: l{i % min(n, 60)}, at: tip}}, "
            f"target: {{ground: [0.3, 0.2]}}}}\n"
            for i in range(n)
        )
        return (
            f"name: x\nchains:\n  - links:\n{links}closures:\n{closures}assemble: {{}}\n".encode()
        )
    if kind == "description":
        return f"name: x\ndescription: '{'d' * n * 700}'\nchains: []\n".encode()
    if kind == "list":
        return f"name: x\ngravity: [{', '.join(['0'] * n * 300)}]\nchains: []\n".encode()
    return ("name: x\n" + "".join(f"k{i}: {i}\n" for i in range(n * 60))).encode()


def crowded(chains: int, links: int, closures: int, seed: int) -> bytes:
    """Up to the link and closure limits, random geometry, all to be assembled (the slow path)."""
    rng = np.random.default_rng(seed)
    doc: dict = {"name": "crowded", "chains": []}
    names = []
    for _chain in range(chains):
        chain = {"origin": rng.uniform(-1, 1, 2).tolist(), "links": []}
        for _ in range(links):
            names.append(f"l{len(names)}")
            chain["links"].append(
                {
                    "name": names[-1],
                    "length": float(rng.uniform(0.1, 1.0)),
                    "inertia": float(rng.uniform(0.0, 0.1)),
                    "joint": {
                        "type": str(rng.choice(["revolute", "prismatic"])),
                        "angle": float(rng.uniform(-3, 3)),
                        "slide": float(rng.uniform(-1, 1)),
                    },
                }
            )
        doc["chains"].append(chain)
    doc["closures"] = []
    for _ in range(closures):
        a, b = rng.choice(names, 2)
        target = (
            {"link": str(b)} if rng.random() < 0.5 else {"ground": rng.uniform(-2, 2, 2).tolist()}
        )
        kind = str(rng.choice(["hinge", "slider", "angle"]))
        if kind == "hinge":
            doc["closures"].append({"type": kind, "point": {"link": str(a)}, "target": target})
        elif kind == "slider":
            doc["closures"].append(
                {
                    "type": kind,
                    "point": {"link": str(a)},
                    "line": {**target, "direction": rng.uniform(-1, 1, 2).tolist()},
                }
            )
        else:
            doc["closures"].append(
                {"type": kind, "link": str(a), "offset": float(rng.uniform(-1, 1))}
            )
    doc["assemble"] = {"fixed": [f"chain{i + 1}_joint1" for i in range(min(chains, 2))]}
    return dump(doc, flow=True)


attacks = st.one_of(
    st.builds(
        lambda lv, w, where: Case(f"laughs:{where}", billion_laughs(lv, w, where)),
        st.integers(1, 12),
        st.integers(2, 9),
        st.sampled_from(["name", "description", "gravity", "chains", "closures", "links", "key"]),
    ),
    st.builds(
        lambda lv, fan: Case("merge_bomb", merge_bomb(lv, fan)),
        st.integers(1, 40),
        st.integers(1, 4),
    ),
    st.builds(
        lambda d, style, where: Case(f"deep:{style}", deep(d, style, where)),
        st.sampled_from([3, 10, 31, 33, 200, 5000, 30000]),
        st.sampled_from(["flow", "block"]),
        st.sampled_from(["gravity", "description", "closures"]),
    ),
    st.builds(
        lambda kind, n: Case(f"large:{kind}", large(kind, n)),
        st.sampled_from(["links", "closures", "description", "list", "keys"]),
        st.integers(1, 130),
    ),
    st.builds(
        lambda c, n, m, seed: Case("crowded", crowded(c, n, m, seed)),
        st.integers(1, 4),
        st.integers(1, 20),
        st.integers(1, 70),
        st.integers(0, 2**32 - 1),
    ),
)

junk_files = st.one_of(
    st.builds(lambda b: Case("binary", b), st.binary(max_size=300)),
    st.builds(
        lambda t: Case("text", t.encode("utf-8")),
        st.text(alphabet=st.characters(codec="utf-8"), max_size=120),
    ),
    st.builds(
        lambda t: Case("yamlish", t.encode("utf-8")),
        st.text(alphabet="name:chains-links[]{}&*!|>'\"#%@`,?\n ~01.e<", max_size=120),
    ),
    st.builds(
        lambda name, enc: Case(
            f"encoding:{enc}", builtin_scene_text(name).replace("deg", "dég").encode(enc)
        ),
        st.sampled_from(BUILTINS),
        st.sampled_from(["latin-1", "utf-16", "cp1252"]),
    ),
)

CASES = st.one_of(
    mutated_builtins(),
    mutated_builtins(),
    mutated_builtins(),
    scratch_scenes(),
    scratch_scenes(),
    text_edits(),
    tagged_values(),
    attacks,
    junk_files,
)


# --------------------------------------------------------------------------- the check


class CaseTimeout(BaseException):
    """Raised by the alarm; a BaseException so that no ``except Exception`` can swallow it."""


@contextmanager
def deadline(seconds: float):
    """Interrupt the block after ``seconds`` of wall time (main thread only)."""

    def _expired(signum, frame):
        raise CaseTimeout(f"case still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, _expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


class Stats:
    """Counts and timings over one test run."""

    def __init__(self):
        self.cases = 0
        self.outcomes: Counter = Counter()
        self.slowest = (0.0, "")

    def add(self, case: Case, outcome: str, seconds: float) -> None:
        self.cases += 1
        self.outcomes[f"{case.kind.split(':')[0]} -> {outcome}"] += 1
        if seconds > self.slowest[0]:
            self.slowest = (seconds, case.kind)

    def report(self, title: str) -> str:
        lines = [
            f"{title}: {self.cases} cases, slowest {self.slowest[0]:.3f} s ({self.slowest[1]})"
        ]
        lines += [f"  {n:5d}  {k}" for k, n in sorted(self.outcomes.items())]
        return "\n".join(lines)


def _reference(case: Case):
    """The document the file holds (``None`` if it is not readable YAML)."""
    if case.doc is not None:
        return case.doc
    try:
        return yaml.load(case.data.decode("utf-8"), Loader=SceneLoader)  # noqa: S506
    except (UnicodeDecodeError, yaml.YAMLError, RecursionError):
        return None


def _check_key(exc: SceneError, case: Case) -> None:
    """The key path locates the fault: a line, the file, the top level or a path in the document."""
    key = exc.key
    assert key, f"empty key path: {exc}"
    if key in (FILE_KEY, TOP_KEY):
        return
    m = LINE_KEY.fullmatch(key)
    if m:
        line, column = int(m[1]), int(m[2])
        assert 1 <= line <= case.data.count(b"\n") + 2 and column >= 1, exc
        return
    doc = _reference(case)
    assert isinstance(doc, dict), f"key path {key!r} but the file holds no mapping: {exc}"
    if exc.expected.startswith("one of the keys"):  # the key itself is the unknown one
        found = str(exc.found)
        quoted = f"[{found!r}]"
        assert key.endswith((quoted, found)), exc
        key = key[: -len(quoted)] if key.endswith(quoted) else key[: -len(found)].rstrip(".")
        if not key:
            return
    node = doc
    parts = re.findall(r"\[\d+\]|[^.\[\]]+", key)
    for i, part in enumerate(parts):
        if part.startswith("["):
            index = int(part[1:-1])
            assert isinstance(node, list) and index < len(node), (
                f"{key!r} not in the document: {exc}"
            )
            node = node[index]
        else:
            assert isinstance(node, dict), f"{key!r} not in the document: {exc}"
            if part not in node:
                assert i == len(parts) - 1 and exc.found == "missing", f"{key!r}: {exc}"
                return
            node = node[part]


def _check_scene(scene: Scene, path: str) -> None:
    q, qd = scene.model.initial_state()
    assert scene.source == path
    assert scene.model.n >= 1
    assert np.all(np.isfinite(q)) and np.all(np.isfinite(qd))
    assert math.isfinite(scene.assembly_residual)


def run_case(case: Case, path, stats: Stats) -> None:
    """Load ``case`` from ``path``; check the outcome and the time it took."""
    path.write_bytes(case.data)
    start = time.perf_counter()
    with deadline(CASE_SECONDS):
        try:
            scene = load_scene(path)
        except SceneError as exc:
            scene, error = None, exc
    seconds = time.perf_counter() - start
    if scene is not None:
        _check_scene(scene, str(path))
        stats.add(case, "Scene", seconds)
    else:
        assert error.source == str(path)
        _check_key(error, case)
        assert str(error).startswith(f"{path}: {error.key}: expected "), error
        assert len(str(error)) < 2000, f"message of {len(str(error))} characters"
        stats.add(case, "SceneError", seconds)
    assert seconds < CASE_SECONDS, f"{seconds:.2f} s for {case!r}"


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    """One file that every case overwrites; the built-ins are loaded once first (imports, BLAS)."""
    for name in BUILTINS:
        load_scene(name)
    return tmp_path_factory.mktemp("fuzz") / "scene.yaml"


COMMON = {
    "deadline": None,  # timed per case by run_case, with an alarm
    "database": None,
    "suppress_health_check": list(HealthCheck),
    "print_blob": True,
}


def test_fuzz_fast(scene_file):
    """A fixed set of generated cases in the default suite."""
    stats = Stats()

    @settings(max_examples=FAST_CASES, derandomize=True, **COMMON)
    @given(CASES)
    def check(case):
        run_case(case, scene_file, stats)

    check()
    print("\n" + stats.report("scene fuzz (fast)"))
    assert stats.cases >= FAST_CASES
    assert stats.outcomes.total() == stats.cases


@pytest.mark.slow
def test_fuzz_slow(scene_file):
    """At least 1000 fresh random cases."""
    stats = Stats()

    @settings(max_examples=SLOW_CASES, **COMMON)
    @given(CASES)
    def check(case):
        run_case(case, scene_file, stats)

    check()
    print("\n" + stats.report("scene fuzz (slow)"))
    assert stats.cases >= 1000


@pytest.mark.parametrize("name", BUILTINS)
@pytest.mark.parametrize("flow", [False, True])
def test_builtin_round_trip(scene_file, name, flow):
    """A built-in scene written back by a YAML dumper loads to the same initial state."""
    scene_file.write_bytes(dump(BUILTIN_DOCS[name], flow=flow))
    again, ref = load_scene(scene_file), load_scene(name)
    assert again.model.joints == ref.model.joints
    assert again.model.closures == ref.model.closures
    assert np.array_equal(again.model.initial_state()[0], ref.model.initial_state()[0])


def test_largest_scene_loads_in_time(scene_file):
    """MAX_LINKS links in one chain: the size limit itself loads within the hang guard."""
    scene_file.write_bytes(large("links", MAX_LINKS))
    assert len(scene_file.read_bytes()) < MAX_SCENE_BYTES
    start = time.perf_counter()
    assert load_scene(scene_file).model.n == MAX_LINKS
    assert time.perf_counter() - start < CASE_SECONDS
