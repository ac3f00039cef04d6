"""Scene files: YAML to :class:`~vjm_ros.model.Model` plus run defaults.

This is the one place that reports schema errors; each names the file, the key path, what was
expected and what was found (:class:`~vjm_ros.errors.SceneError`). See ``docs/scenes.md`` for the
format; the built-in scenes under ``vjm_ros/scenes/`` are complete examples.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
import yaml

from .assembly import assemble, closure_residual
from .dynamics import mass_matrix
from .errors import SceneError
from .model import (
    ANGLE,
    CLOSURE_KINDS,
    GROUND,
    HINGE,
    JOINT_KINDS,
    SLIDER,
    Actuator,
    Chain,
    Closure,
    Joint,
    Link,
    Model,
    NamedPoint,
    PointRef,
)

MAX_SCENE_BYTES = 1_000_000
"""Largest scene file read, bytes."""
MAX_MAGNITUDE = 1e6
"""Largest magnitude accepted for any number in a scene (SI units)."""
MAX_LINKS = 512
"""Largest number of links in one scene."""
DEFAULT_CLOSURE_TOLERANCE = 1e-6
"""Largest closure residual accepted at t = 0 without assembly, m or rad."""



class _SceneLoader(yaml.SafeLoader):
    """Safe loader that reads ``1e5`` and ``1.0e5`` as floats (YAML 1.2), as users write them."""


_SceneLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+][0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)

TOP_KEYS = {
    "name", "description", "provenance", "units", "gravity", "chains", "closures", "actuators",
    "points", "closure_method", "assemble", "defaults",
}


@dataclass
class Scene:
    """A loaded scene.

    Attributes
    ----------
    model : Model
        Closed (assembled) initial state included.
    source : str
        File path or built-in name.
    text : str
        The YAML text.
    gains : dict
        Default closure method and gains (``method``, ``kp``, ``kv``, ``omega_n``, ``zeta``,
        ``alpha``, ``beta``, ``projection``).
    defaults : dict
        Default run settings (``integrator``, ``rate``, ``substeps``, ``duration``).
    assembly_residual : float
        ``max |C|`` at t = 0 after loading, m or rad.
    """

    model: Model
    source: str
    text: str
    gains: dict = field(default_factory=dict)
    defaults: dict = field(default_factory=dict)
    assembly_residual: float = 0.0

    @property
    def name(self) -> str:
        """Scene name."""
        return self.model.name


def builtin_scenes() -> list[str]:
    """Names of the scenes shipped with the package."""
    root = resources.files("vjm_ros") / "scenes"
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".yaml"))


def builtin_scene_text(name: str) -> str:
    """YAML text of a built-in scene."""
    return (resources.files("vjm_ros") / "scenes" / f"{name}.yaml").read_text(encoding="utf-8")


def load_scene(spec: str | Path) -> Scene:
    """Load a built-in scene by name, or a YAML file by path.

    Raises
    ------
    SceneError
        With file, key path, expected and found value.
    """
    spec_s = str(spec)
    if spec_s in builtin_scenes():
        return parse_scene(builtin_scene_text(spec_s), source=f"<builtin {spec_s}>")
    path = Path(spec_s)
    if not path.exists():
        raise SceneError(
            spec_s, "", f"a built-in scene name ({', '.join(builtin_scenes())}) or a YAML file path",
            "no such scene or file",
        )
    try:
        size = path.stat().st_size
        if size > MAX_SCENE_BYTES:
            raise SceneError(spec_s, "", f"a file of at most {MAX_SCENE_BYTES} bytes", f"{size} bytes")
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(spec_s, "", "UTF-8 text", f"undecodable byte at {exc.start}") from None
    except OSError as exc:
        raise SceneError(spec_s, "", "a readable file", exc.strerror or str(exc)) from None
    return parse_scene(text, source=spec_s)


def parse_scene(text: str, source: str = "<string>") -> Scene:
    """Parse and validate scene YAML text.

    Parameters
    ----------
    text : str
    source : str
        Used in error messages.

    Returns
    -------
    Scene
    """
    if len(text) > MAX_SCENE_BYTES:
        raise SceneError(source, "", f"at most {MAX_SCENE_BYTES} characters", f"{len(text)}")
    try:
        doc = yaml.load(text, Loader=_SceneLoader)  # noqa: S506 (safe loader subclass)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise SceneError(source, where, "valid YAML", str(getattr(exc, "problem", exc))) from None
    except RecursionError:
        raise SceneError(source, "", "a YAML document of reasonable nesting depth", "too deep") from None
    return _Builder(source, text).build(doc)


class _Builder:
    """Walks the document once, validating as it goes."""

    def __init__(self, source: str, text: str):
        self.source = source
        self.text = text
        self.angle_scale = 1.0

    # -------------------------------------------------------------- primitives
    def fail(self, key: str, expected: str, found: object = ...) -> SceneError:
        return SceneError(self.source, key, expected, found)

    def mapping(self, value, key: str, allowed: set[str] | None = None) -> dict:
        if not isinstance(value, dict):
            raise self.fail(key, "a mapping", value)
        for k in value:
            if not isinstance(k, str):
                raise self.fail(key, "string keys", k)
            if allowed is not None and k not in allowed:
                raise self.fail(f"{key}.{k}" if key else k, f"one of the keys {sorted(allowed)}", k)
        return value

    def sequence(self, value, key: str, min_len: int = 0, max_len: int = MAX_LINKS) -> list:
        if not isinstance(value, list):
            raise self.fail(key, "a list", value)
        if len(value) < min_len:
            raise self.fail(key, f"a list of at least {min_len} entries", value)
        if len(value) > max_len:
            raise self.fail(key, f"a list of at most {max_len} entries", f"{len(value)} entries")
        return value

    def number(self, value, key: str, minimum: float | None = None, positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(key, "a number", value)
        v = float(value)
        if not math.isfinite(v) or abs(v) > MAX_MAGNITUDE:
            raise self.fail(key, f"a finite number of magnitude at most {MAX_MAGNITUDE:g}", value)
        if positive and v <= 0:
            raise self.fail(key, "a number > 0", value)
        if minimum is not None and v < minimum:
            raise self.fail(key, f"a number >= {minimum:g}", value)
        return v

    def angle(self, value, key: str) -> float:
        return self.number(value, key) * self.angle_scale

    def vector(self, value, key: str) -> tuple[float, float]:
        if not isinstance(value, list) or len(value) != 2:
            raise self.fail(key, "a list of two numbers [x, y]", value)
        return (self.number(value[0], f"{key}[0]"), self.number(value[1], f"{key}[1]"))

    def string(self, value, key: str) -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.fail(key, "a non-empty string", value)
        if len(value) > 200:
            raise self.fail(key, "a string of at most 200 characters", value)
        return value

    def name(self, value, key: str) -> str:
        s = self.string(value, key)
        if not all(ch.isalnum() or ch == "_" for ch in s) or s[0].isdigit():
            raise self.fail(key, "a name of letters, digits and '_' (not starting with a digit)", s)
        return s

    # -------------------------------------------------------------- document
    def build(self, doc) -> Scene:
        doc = self.mapping(doc, "", TOP_KEYS)
        for req in ("name", "chains"):
            if req not in doc:
                raise self.fail(req, "a required key", "missing")
        name = self.name(doc["name"], "name")
        units = self.mapping(doc.get("units", {}), "units", {"angle"})
        unit = units.get("angle", "radians")
        if unit not in ("degrees", "radians"):
            raise self.fail("units.angle", "'degrees' or 'radians'", unit)
        self.angle_scale = math.pi / 180.0 if unit == "degrees" else 1.0
        for k in ("description", "provenance"):
            if k in doc and not isinstance(doc[k], str):
                raise self.fail(k, "a string", doc[k])
        gravity = self.vector(doc.get("gravity", [0.0, -9.81]), "gravity")

        chains, links, joints = self.chains(doc["chains"])
        self.link_index = {lk.name: i for i, lk in enumerate(links)}
        self.joint_index = {j.name: i for i, j in enumerate(joints)}
        self.links = links
        closures = self.closures(doc.get("closures", []) or [])
        actuators = self.actuators(doc.get("actuators", []) or [])
        points = self.points(doc.get("points", []) or [], chains, links)
        gains = self.gains(doc.get("closure_method", {}) or {})
        defaults = self.defaults(doc.get("defaults", {}) or {})
        model = Model.build(
            name, tuple(chains), tuple(links), tuple(joints), tuple(closures), tuple(actuators),
            tuple(points), gravity, self.text,
            {"description": doc.get("description", ""), "provenance": doc.get("provenance", "")},
        )
        self.check_inertia(model)
        model, residual = self.close(model, doc.get("assemble"))
        return Scene(model, self.source, self.text, gains, defaults, residual)

    def chains(self, value):
        value = self.sequence(value, "chains", min_len=1)
        chains, links, joints = [], [], []
        chain_names, link_names, joint_names = set(), set(), set()
        for c, ch in enumerate(value):
            key = f"chains[{c}]"
            ch = self.mapping(ch, key, {"name", "origin", "angle", "length", "links"})
            if "links" not in ch:
                raise self.fail(f"{key}.links", "a required key", "missing")
            cname = self.name(ch.get("name", f"chain{c + 1}"), f"{key}.name")
            if cname in chain_names:
                raise self.fail(f"{key}.name", "a chain name used once", cname)
            chain_names.add(cname)
            origin = self.vector(ch.get("origin", [0.0, 0.0]), f"{key}.origin")
            base_angle = self.angle(ch.get("angle", 0.0), f"{key}.angle")
            base_len = self.number(ch.get("length", 0.0), f"{key}.length", minimum=0.0)
            lks = self.sequence(ch["links"], f"{key}.links", min_len=1)
            if len(links) + len(lks) > MAX_LINKS:
                raise self.fail(f"{key}.links", f"at most {MAX_LINKS} links in a scene", len(links) + len(lks))
            idx = []
            prev_angle = base_angle
            for i, lk in enumerate(lks):
                lkey = f"{key}.links[{i}]"
                lk = self.mapping(lk, lkey, {"name", "length", "mass", "inertia", "com", "joint"})
                lname = self.name(lk.get("name", f"{cname}_link{i + 2}"), f"{lkey}.name")
                if lname in link_names:
                    raise self.fail(f"{lkey}.name", "a link name used once in the scene", lname)
                link_names.add(lname)
                for req in ("length", "joint"):
                    if req not in lk:
                        raise self.fail(f"{lkey}.{req}", "a required key", "missing")
                length = self.number(lk["length"], f"{lkey}.length", minimum=0.0)
                mass = self.number(lk.get("mass", 1.0), f"{lkey}.mass", minimum=0.0)
                inertia = self.number(lk.get("inertia", 0.0), f"{lkey}.inertia", minimum=0.0)
                com = self.vector(lk.get("com", [length / 2.0, 0.0]), f"{lkey}.com")
                jkey = f"{lkey}.joint"
                jt = self.mapping(lk["joint"], jkey, {"name", "type", "angle", "slide", "velocity"})
                jname = self.name(jt.get("name", f"{cname}_joint{i + 1}"), f"{jkey}.name")
                if jname in joint_names:
                    raise self.fail(f"{jkey}.name", "a joint name used once in the scene", jname)
                joint_names.add(jname)
                kind = jt.get("type")
                if kind not in JOINT_KINDS:
                    raise self.fail(f"{jkey}.type", f"one of {list(JOINT_KINDS)}", kind)
                absolute = self.angle(jt.get("angle", 0.0), f"{jkey}.angle")
                slide = self.number(jt.get("slide", 0.0), f"{jkey}.slide")
                rate_raw = jt.get("velocity", 0.0)
                rate = (
                    self.angle(rate_raw, f"{jkey}.velocity")
                    if kind == "revolute"
                    else self.number(rate_raw, f"{jkey}.velocity")
                )
                joints.append(Joint(jname, kind, absolute - prev_angle, slide, rate))
                links.append(Link(lname, c, length, mass, inertia, com))
                idx.append(len(links) - 1)
                prev_angle = absolute
            chains.append(Chain(cname, origin, base_angle, base_len, tuple(idx)))
        return chains, links, joints

    def link_ref(self, value, key: str) -> int:
        lname = self.string(value, key)
        if lname not in self.link_index:
            raise self.fail(key, f"a link of the scene ({', '.join(self.link_index)})", lname)
        return self.link_index[lname]

    def point(self, value, key: str) -> PointRef:
        value = self.mapping(value, key, {"link", "at", "ground"})
        if "ground" in value:
            if "link" in value or "at" in value:
                raise self.fail(key, "either 'ground' or 'link'/'at', not both", sorted(value))
            return PointRef(GROUND, self.vector(value["ground"], f"{key}.ground"))
        if "link" not in value:
            raise self.fail(f"{key}.link", "a required key (or 'ground: [x, y]')", "missing")
        li = self.link_ref(value["link"], f"{key}.link")
        at = value.get("at", "tip")
        length = self.links[li].length
        if at == "tip":
            local = (length, 0.0)
        elif at == "origin":
            local = (0.0, 0.0)
        elif at == "com":
            local = self.links[li].com
        elif isinstance(at, list):
            local = self.vector(at, f"{key}.at")
        else:
            raise self.fail(f"{key}.at", "'tip', 'origin', 'com' or [s, w] in the link frame", at)
        return PointRef(li, local)

    def closures(self, value):
        value = self.sequence(value, "closures")
        out, names = [], set()
        for k, cl in enumerate(value):
            key = f"closures[{k}]"
            cl = self.mapping(
                cl, key, {"name", "type", "point", "target", "line", "link", "offset", "gains"}
            )
            kind = cl.get("type")
            if kind not in CLOSURE_KINDS:
                raise self.fail(f"{key}.type", f"one of {list(CLOSURE_KINDS)}", kind)
            cname = self.name(cl.get("name", f"{kind}{k + 1}"), f"{key}.name")
            if cname in names:
                raise self.fail(f"{key}.name", "a closure name used once", cname)
            names.add(cname)
            if "gains" in cl:
                raise self.fail(f"{key}.gains", "gains under the top-level 'closure_method'", cl["gains"])
            if kind == HINGE:
                for req in ("point", "target"):
                    if req not in cl:
                        raise self.fail(f"{key}.{req}", "a required key", "missing")
                pa = self.point(cl["point"], f"{key}.point")
                pb = self.point(cl["target"], f"{key}.target")
                if pa.link == GROUND:
                    raise self.fail(f"{key}.point", "a point on a link", "ground")
                out.append(Closure(cname, kind, pa, pb))
            elif kind == SLIDER:
                for req in ("point", "line"):
                    if req not in cl:
                        raise self.fail(f"{key}.{req}", "a required key", "missing")
                pa = self.point(cl["point"], f"{key}.point")
                line = self.mapping(cl["line"], f"{key}.line", {"ground", "link", "at", "direction"})
                if "direction" not in line:
                    raise self.fail(f"{key}.line.direction", "a required key [dx, dy]", "missing")
                d = np.array(self.vector(line["direction"], f"{key}.line.direction"))
                norm = float(np.hypot(*d))
                if norm < 1e-12:
                    raise self.fail(f"{key}.line.direction", "a non-zero vector", line["direction"])
                p0 = self.point({k: v for k, v in line.items() if k != "direction"}, f"{key}.line")
                out.append(Closure(cname, kind, pa, p0, tuple(d / norm)))
            else:
                if "link" not in cl:
                    raise self.fail(f"{key}.link", "a required key", "missing")
                la = self.link_ref(cl["link"], f"{key}.link")
                tgt = self.mapping(cl.get("target", {"ground": True}), f"{key}.target", {"ground", "link"})
                lb = GROUND if "link" not in tgt else self.link_ref(tgt["link"], f"{key}.target.link")
                offset = self.angle(cl.get("offset", 0.0), f"{key}.offset")
                out.append(Closure(cname, kind, PointRef(la, (0.0, 0.0)), PointRef(lb, (0.0, 0.0)),
                                   offset=offset))
        return out

    def actuators(self, value):
        value = self.sequence(value, "actuators")
        out, seen = [], set()
        for k, ac in enumerate(value):
            key = f"actuators[{k}]"
            ac = self.mapping(ac, key, {"joint", "limit", "effort"})
            if "joint" not in ac:
                raise self.fail(f"{key}.joint", "a required key", "missing")
            jname = self.string(ac["joint"], f"{key}.joint")
            if jname not in self.joint_index:
                raise self.fail(f"{key}.joint", f"a joint of the scene ({', '.join(self.joint_index)})", jname)
            if jname in seen:
                raise self.fail(f"{key}.joint", "a joint actuated once", jname)
            seen.add(jname)
            limit = self.number(ac.get("limit", MAX_MAGNITUDE), f"{key}.limit", positive=True)
            effort = self.number(ac.get("effort", 0.0), f"{key}.effort")
            if abs(effort) > limit:
                raise self.fail(f"{key}.effort", f"a value within the limit +-{limit:g}", effort)
            out.append(Actuator(self.joint_index[jname], limit, effort))
        return out

    def points(self, value, chains, links):
        out = [
            NamedPoint(f"{ch.name}_tip", PointRef(ch.links[-1], (links[ch.links[-1]].length, 0.0)))
            for ch in chains
        ]
        names = {p.name for p in out}
        value = self.sequence(value, "points")
        for k, pt in enumerate(value):
            key = f"points[{k}]"
            pt = self.mapping(pt, key, {"name", "link", "at"})
            pname = self.name(pt.get("name"), f"{key}.name")
            if pname in names:
                raise self.fail(f"{key}.name", "a point name used once (chain tips are '<chain>_tip')", pname)
            names.add(pname)
            ref = self.point({k2: v for k2, v in pt.items() if k2 != "name"}, key)
            out.append(NamedPoint(pname, ref))
        return out

    def gains(self, value) -> dict:
        allowed = {"method", "kp", "kv", "omega_n", "zeta", "alpha", "beta", "projection"}
        value = self.mapping(value, "closure_method", allowed)
        out = {}
        method = value.get("method", "penalty")
        if method not in ("penalty", "exact"):
            raise self.fail("closure_method.method", "'penalty' or 'exact'", method)
        out["method"] = method
        for k in ("kp", "kv", "omega_n", "zeta", "alpha", "beta"):
            if k in value:
                out[k] = self.number(value[k], f"closure_method.{k}", minimum=0.0)
        if "kp" in out and "omega_n" in out:
            raise self.fail("closure_method", "either kp/kv or omega_n/zeta, not both", sorted(value))
        if "projection" in value:
            if not isinstance(value["projection"], bool):
                raise self.fail("closure_method.projection", "true or false", value["projection"])
            out["projection"] = value["projection"]
        return out

    def defaults(self, value) -> dict:
        from .integrators import INTEGRATORS

        value = self.mapping(value, "defaults", {"integrator", "rate", "substeps", "duration"})
        out = {}
        if "integrator" in value:
            if value["integrator"] not in INTEGRATORS:
                raise self.fail("defaults.integrator", f"one of {list(INTEGRATORS)}", value["integrator"])
            out["integrator"] = value["integrator"]
        if "rate" in value:
            out["rate"] = self.number(value["rate"], "defaults.rate", positive=True)
        if "substeps" in value:
            s = value["substeps"]
            if isinstance(s, bool) or not isinstance(s, int) or s < 1 or s > 10000:
                raise self.fail("defaults.substeps", "a whole number from 1 to 10000", s)
            out["substeps"] = s
        if "duration" in value:
            out["duration"] = self.number(value["duration"], "defaults.duration", positive=True)
        return out

    def check_inertia(self, model: Model) -> None:
        q, _ = model.initial_state()
        with np.errstate(all="ignore"):
            m = mass_matrix(model, q)
            ok = bool(np.all(np.isfinite(m)))
            ev = np.linalg.eigvalsh(m) if ok else np.array([np.nan])
        if not ok or not ev[0] > 1e-12 * max(float(ev[-1]), 1e-300):
            which = [lk.name for lk in model.links if lk.mass == 0 and lk.inertia == 0]
            raise self.fail(
                "chains",
                "masses and inertias that give every joint some inertia (a positive definite mass "
                f"matrix); links without mass or inertia: {which or 'none'}",
                f"smallest eigenvalue {float(ev[0]):.3g}",
            )

    def close(self, model: Model, spec) -> tuple[Model, float]:
        if spec is None:
            q, _ = model.initial_state()
            res = closure_residual(model, q)
            err = float(np.max(np.abs(res))) if res.size else 0.0
            if not err <= DEFAULT_CLOSURE_TOLERANCE:
                worst = int(np.argmax(np.abs(res))) if res.size else 0
                rows = [c.name for c in model.closures for _ in range(c.rows)]
                raise self.fail(
                    f"closures ({rows[worst] if rows else ''})",
                    f"closures that hold at t = 0 within {DEFAULT_CLOSURE_TOLERANCE:g} "
                    "(or an 'assemble' section)",
                    f"residual {err:.3g}",
                )
            return model, err
        spec = self.mapping(spec, "assemble", {"fixed", "tolerance"})
        fixed_names = self.sequence(spec.get("fixed", []), "assemble.fixed")
        fixed = []
        for k, jn in enumerate(fixed_names):
            jn = self.string(jn, f"assemble.fixed[{k}]")
            if jn not in self.joint_index:
                raise self.fail(f"assemble.fixed[{k}]", f"a joint of the scene ({', '.join(self.joint_index)})", jn)
            fixed.append(self.joint_index[jn])
        tol = self.number(spec.get("tolerance", 1e-10), "assemble.tolerance", positive=True)
        with np.errstate(all="ignore"):
            q, qd, err = assemble(model, fixed, tol)
        if not err <= tol:
            raise self.fail(
                "assemble",
                f"geometry that can be assembled to within {tol:g} from the given guesses",
                f"residual {err:.3g} after assembly",
            )
        return model.with_state(q, qd), err
