"""Scene documents to models: every key validated, errors naming the key path.

:class:`SceneBuilder` walks a YAML document once (after :mod:`vjm_ros.scene.safe_yaml` has read
it), builds the :class:`~vjm_ros.core.model.Model`, checks the inertia and closes the closures
(assembly); :class:`Scene` is what it returns.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from vjm_ros.core.model import (
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
    Load,
    Model,
    NamedPoint,
    PointRef,
)
from vjm_ros.scene.assembly import assemble, closure_residual
from vjm_ros.scene.keys import KeyReader
from vjm_ros.scene.limits import (
    DEFAULT_CLOSURE_TOLERANCE,
    MAX_CLOSURES,
    MAX_LINKS,
    MAX_MAGNITUDE,
    TOP_KEYS,
)
from vjm_ros.scene.plant import (
    SENSOR_FIELDS,
    ActuatorDynamics,
    JointSensors,
    Plant,
    SensorChannel,
    delay_ticks,
)


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
    plant : Plant
        Actuator dynamics and sensors (:mod:`vjm_ros.scene.plant`); pass it to the simulator.
    """

    model: Model
    source: str
    text: str
    gains: dict = field(default_factory=dict)
    defaults: dict = field(default_factory=dict)
    assembly_residual: float = 0.0
    plant: Plant = field(default_factory=Plant)

    @property
    def name(self) -> str:
        """Scene name."""
        return self.model.name


def _worst_closure(model: Model, residual: np.ndarray) -> tuple[int, float]:
    """Index and residual size (norm over its rows) of the least satisfied closure."""
    rows = [k for k, c in enumerate(model.closures) for _ in range(c.rows)]
    size = np.zeros(len(model.closures))
    with np.errstate(over="ignore"):
        np.add.at(size, rows, np.where(np.isfinite(residual), residual, np.inf) ** 2)
    k = int(np.argmax(size))
    return k, float(np.sqrt(size[k]))


def _listing(names, limit: int = 12) -> str:
    """``a, b, c``: at most ``limit`` names, then the count of the others."""
    names = list(names)
    more = f", ... ({len(names) - limit} more)" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more


class SceneBuilder(KeyReader):
    """Walks the document once, validating as it goes.

    Parameters
    ----------
    source : str
        File name for error messages.
    text : str
        The YAML text, kept with the model.
    """

    def __init__(self, source: str, text: str):
        super().__init__(source)
        self.text = text
        self.links: list[Link] = []
        self.link_index: dict[str, int] = {}
        self.link_key: list[str] = []
        self.joint_index: dict[str, int] = {}

    # -------------------------------------------------------------- document
    def build(self, doc: object) -> Scene:
        """The scene described by the document ``doc``."""
        doc = self.mapping(doc, "", TOP_KEYS)
        name = self.name(self.require(doc, "name", ""), "name")
        self.require(doc, "chains", "")
        units = self.mapping(self.section(doc, "units"), "units", {"angle"})
        unit = units.get("angle", "radians")
        if unit not in ("degrees", "radians"):
            raise self.fail("units.angle", "'degrees' or 'radians'", unit)
        self.angle_scale = math.pi / 180.0 if unit == "degrees" else 1.0
        for k in ("description", "provenance"):
            if k in doc and not isinstance(doc[k], str):
                raise self.fail(k, "a string", doc[k])
        gravity = self.vector(doc.get("gravity", [0.0, -9.81]), "gravity")

        chains, links, joints = self.chains(doc["chains"])
        self.links = links
        self.link_index = {lk.name: i for i, lk in enumerate(links)}
        self.joint_index = {j.name: i for i, j in enumerate(joints)}
        self.stop_names = {f"{j.name}_stop" for j in joints if any(map(math.isfinite, j.range))}
        closures = self.closures(self.section(doc, "closures"))
        actuators, dynamics = self.actuators(self.section(doc, "actuators"))
        sensors = self.sensors(doc.get("sensors"), joints)
        points = self.points(self.section(doc, "points"), chains, links)
        loads = self.loads(self.section(doc, "loads"))
        gains = self.gains(self.section(doc, "closure_method"))
        defaults = self.defaults(self.section(doc, "defaults"))
        plant = self.plant(dynamics, sensors, defaults)
        model = Model.build(
            name, tuple(chains), tuple(links), tuple(joints), tuple(closures), tuple(actuators),
            tuple(points), gravity, self.text,
            {"description": doc.get("description", ""), "provenance": doc.get("provenance", "")},
            loads,
        )
        self.check_inertia(model)
        model, residual = self.close(model, doc.get("assemble"))
        return Scene(model, self.source, self.text, gains, defaults, residual, plant)

    def chains(self, value: object) -> tuple[list[Chain], list[Link], list[Joint]]:
        """Chains, links and joints, in scene order."""
        value = self.sequence(value, "chains", min_len=1)
        chains, links, joints = [], [], []
        chain_names, link_names, joint_names = set(), set(), set()
        for c, ch in enumerate(value):
            key = f"chains[{c}]"
            ch = self.mapping(ch, key, {"name", "origin", "angle", "length", "links"})
            lks = self.require(ch, "links", key)
            cname = self.name(ch.get("name", f"chain{c + 1}"), f"{key}.name")
            if cname in chain_names:
                raise self.fail(f"{key}.name", "a chain name used once", cname)
            chain_names.add(cname)
            origin = self.vector(ch.get("origin", [0.0, 0.0]), f"{key}.origin")
            base_angle = self.angle(ch.get("angle", 0.0), f"{key}.angle")
            base_len = self.number(ch.get("length", 0.0), f"{key}.length", minimum=0.0)
            lks = self.sequence(lks, f"{key}.links", min_len=1)
            if len(links) + len(lks) > MAX_LINKS:
                raise self.fail(
                    f"{key}.links", f"at most {MAX_LINKS} links in a scene",
                    f"{len(links) + len(lks)} links",
                )
            idx = []
            prev_angle = base_angle
            for i, lk in enumerate(lks):
                lkey = f"{key}.links[{i}]"
                lk = self.mapping(lk, lkey, {"name", "length", "mass", "inertia", "com", "joint"})
                lname = self.name(lk.get("name", f"{cname}_link{i + 2}"), f"{lkey}.name")
                if lname in link_names:
                    raise self.fail(f"{lkey}.name", "a link name used once in the scene", lname)
                link_names.add(lname)
                raw_length = self.require(lk, "length", lkey)
                length = self.number(raw_length, f"{lkey}.length", minimum=0.0)
                jt = self.require(lk, "joint", lkey)
                mass = self.number(lk.get("mass", 1.0), f"{lkey}.mass", minimum=0.0)
                inertia = self.number(lk.get("inertia", 0.0), f"{lkey}.inertia", minimum=0.0)
                com = self.vector(lk.get("com", [length / 2.0, 0.0]), f"{lkey}.com")
                jkey = f"{lkey}.joint"
                jt = self.mapping(jt, jkey, {"name", "type", "angle", "slide", "velocity",
                                             "damping", "armature", "friction",
                                             "friction_model", "velocity_scale", "range",
                                             "restitution"})
                jname = self.name(jt.get("name", f"{cname}_joint{i + 1}"), f"{jkey}.name")
                if jname in joint_names:
                    raise self.fail(f"{jkey}.name", "a joint name used once in the scene", jname)
                joint_names.add(jname)
                kind = self.choice(self.require(jt, "type", jkey), f"{jkey}.type", JOINT_KINDS)
                absolute = self.angle(jt.get("angle", 0.0), f"{jkey}.angle")
                slide = self.number(jt.get("slide", 0.0), f"{jkey}.slide")
                rate_raw = jt.get("velocity", 0.0)
                rate = (
                    self.angle(rate_raw, f"{jkey}.velocity")
                    if kind == "revolute"
                    else self.number(rate_raw, f"{jkey}.velocity")
                )
                damping, armature, friction = (
                    self.number(jt.get(k, 0.0), f"{jkey}.{k}", minimum=0.0)
                    for k in ("damping", "armature", "friction"))
                joint = Joint(jname, kind, absolute - prev_angle, slide, rate, damping,
                              armature, friction, self.friction_scale(jt, jkey))
                joints.append(self.stops(joint, jt, jkey))
                links.append(Link(lname, c, length, mass, inertia, com))
                self.link_key.append(lkey)
                idx.append(len(links) - 1)
                prev_angle = absolute
            chains.append(Chain(cname, origin, base_angle, base_len, tuple(idx)))
        return chains, links, joints

    def friction_scale(self, joint: dict, key: str) -> float:
        """0 for sticking friction (``friction_model: stick``, the default), the velocity scale
        of ``friction_model: smooth`` (rad/s, in the file's angle unit, or m/s)."""
        model = self.choice(joint.get("friction_model", "stick"), f"{key}.friction_model",
                            ("stick", "smooth"))
        if model == "stick":
            if "velocity_scale" in joint:
                raise self.fail(f"{key}.velocity_scale", "no velocity_scale with "
                                "friction_model: stick (only smooth friction has one)",
                                joint["velocity_scale"])
            return 0.0
        scale = self.require(joint, "velocity_scale", key, "a required key with "
                             "friction_model: smooth")
        value = (self.angle(scale, f"{key}.velocity_scale") if joint.get("type") == "revolute"
                 else self.number(scale, f"{key}.velocity_scale"))
        if not value > 0:
            raise self.fail(f"{key}.velocity_scale", "a positive rate", scale)
        return value

    def stops(self, joint: Joint, doc: dict, key: str) -> Joint:
        """``joint`` with its ``range: [lo, hi]`` (the file's angle unit, or m) and
        ``restitution`` (0..1); the start must lie within the range."""
        if "range" not in doc:
            if "restitution" in doc:
                raise self.fail(f"{key}.restitution", "a restitution only with a range",
                                doc["restitution"])
            return joint
        bounds = self.sequence(doc["range"], f"{key}.range", min_len=2, max_len=2)
        read = self.angle if joint.kind == "revolute" else self.number
        lo, hi = (read(b, f"{key}.range[{i}]") for i, b in enumerate(bounds))
        if not lo < hi:
            raise self.fail(f"{key}.range", "[lo, hi] with lo < hi", doc["range"])
        if not lo <= joint.position <= hi:
            start = joint.position / (self.angle_scale if joint.kind == "revolute" else 1.0)
            raise self.fail(f"{key}.range", f"a range that holds the joint's start ({start:.6g})",
                            doc["range"])
        e = self.number(doc.get("restitution", 0.0), f"{key}.restitution", minimum=0.0)
        if e > 1.0:
            raise self.fail(f"{key}.restitution", "a number in [0, 1]", doc["restitution"])
        return replace(joint, range=(lo, hi), restitution=e)

    def link_ref(self, value: object, key: str) -> int:
        """Index of the link named ``value``."""
        lname = self.string(value, key)
        if lname not in self.link_index:
            raise self.fail(key, f"a link of the scene ({_listing(self.link_index)})", lname)
        return self.link_index[lname]

    def point(self, value: object, key: str) -> PointRef:
        """A ground point ``{ground: [x, y]}`` or a link point ``{link: L, at: ...}``."""
        value = self.mapping(value, key, {"link", "at", "ground"})
        if "ground" in value:
            if "link" in value or "at" in value:
                raise self.fail(key, "either 'ground' or 'link'/'at', not both", sorted(value))
            return PointRef(GROUND, self.vector(value["ground"], f"{key}.ground"))
        li = self.link_ref(
            self.require(value, "link", key, "a required key (or 'ground: [x, y]')"), f"{key}.link"
        )
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

    def closures(self, value: object) -> list[Closure]:
        """The closures (docs/design.md section 2)."""
        value = self.sequence(value, "closures", max_len=MAX_CLOSURES)
        out, names = [], set()
        for k, cl in enumerate(value):
            key = f"closures[{k}]"
            cl = self.mapping(
                cl, key, {"name", "type", "point", "target", "line", "link", "offset", "gains"}
            )
            kind = self.choice(self.require(cl, "type", key), f"{key}.type", CLOSURE_KINDS)
            cname = self.name(cl.get("name", f"{kind}{k + 1}"), f"{key}.name")
            if cname in names:
                raise self.fail(f"{key}.name", "a closure name used once", cname)
            if cname in self.stop_names:  # a joint's stop is reported under this name
                raise self.fail(f"{key}.name", "a name other than a joint's stop, <joint>_stop",
                                cname)
            names.add(cname)
            if "gains" in cl:
                raise self.fail(
                    f"{key}.gains", "gains under the top-level 'closure_method'", cl["gains"]
                )
            if kind == HINGE:
                point, target = self.require(cl, "point", key), self.require(cl, "target", key)
                pa = self.point(point, f"{key}.point")
                pb = self.point(target, f"{key}.target")
                if pa.link == GROUND:
                    raise self.fail(f"{key}.point", "a point on a link", "ground")
                out.append(Closure(cname, kind, pa, pb))
            elif kind == SLIDER:
                point, line = self.require(cl, "point", key), self.require(cl, "line", key)
                pa = self.point(point, f"{key}.point")
                line = self.mapping(line, f"{key}.line", {"ground", "link", "at", "direction"})
                raw_d = self.require(line, "direction", f"{key}.line", "a required key [dx, dy]")
                d = np.array(self.vector(raw_d, f"{key}.line.direction"))
                norm = float(np.hypot(*d))
                if norm < 1e-12:
                    raise self.fail(f"{key}.line.direction", "a non-zero vector", raw_d)
                p0 = self.point({k: v for k, v in line.items() if k != "direction"}, f"{key}.line")
                out.append(Closure(cname, kind, pa, p0, tuple(d / norm)))
            else:
                la = self.link_ref(self.require(cl, "link", key), f"{key}.link")
                tkey = f"{key}.target"
                tgt = self.mapping(cl.get("target", {"ground": True}), tkey, {"ground", "link"})
                if ("ground" in tgt) == ("link" in tgt):
                    raise self.fail(tkey, "either 'ground: true' or 'link: NAME'", tgt)
                if "ground" in tgt and tgt["ground"] is not True:
                    raise self.fail(f"{tkey}.ground", "true", tgt["ground"])
                lb = GROUND if "link" not in tgt else self.link_ref(tgt["link"], f"{tkey}.link")
                offset = self.angle(cl.get("offset", 0.0), f"{key}.offset")
                out.append(Closure(cname, kind, PointRef(la, (0.0, 0.0)), PointRef(lb, (0.0, 0.0)),
                                   offset=offset))
        return out

    def joint_ref(self, value: object, key: str) -> int:
        """Index of the joint named ``value``."""
        jname = self.string(value, key)
        if jname not in self.joint_index:
            raise self.fail(key, f"a joint of the scene ({_listing(self.joint_index)})", jname)
        return self.joint_index[jname]

    def actuators(self, value: object) -> tuple[list[Actuator], list[ActuatorDynamics]]:
        """Actuators, one per actuated joint, and their dynamics (gear, lag, delay)."""
        value = self.sequence(value, "actuators")
        out, seen, dynamics = [], set(), []
        for k, ac in enumerate(value):
            key = f"actuators[{k}]"
            ac = self.mapping(
                ac, key, {"joint", "limit", "effort", "gear", "time_constant", "delay"})
            joint = self.joint_ref(self.require(ac, "joint", key), f"{key}.joint")
            if joint in seen:
                raise self.fail(f"{key}.joint", "a joint actuated once", ac["joint"])
            seen.add(joint)
            limit = self.number(ac.get("limit", MAX_MAGNITUDE), f"{key}.limit", positive=True)
            effort = self.number(ac.get("effort", 0.0), f"{key}.effort")
            if abs(effort) > limit:
                raise self.fail(f"{key}.effort", f"a value within the limit +-{limit:g}", effort)
            out.append(Actuator(joint, limit, effort))
            dynamics.append(ActuatorDynamics(
                gear=self.number(ac.get("gear", 1.0), f"{key}.gear", positive=True),
                time_constant=self.number(ac.get("time_constant", 0.0), f"{key}.time_constant",
                                          minimum=0.0),
                delay=self.number(ac.get("delay", 0.0), f"{key}.delay", minimum=0.0),
                key=key))
        return out, dynamics

    def sensors(self, value: object, joints: Sequence[Joint]) -> JointSensors | None:
        """The ``sensors`` section: what ``joint_states`` measures (None without it).

        Position and velocity values of a revolute joint are in the file's angle unit (per
        second), of a prismatic joint in m (per second); effort values in N m or N.
        """
        if value is None:
            return None
        value = self.mapping(value, "sensors", {"joint_states"})
        key = "sensors.joint_states"
        spec = self.mapping(self.require(value, "joint_states", "sensors"), key,
                            {*SENSOR_FIELDS, "delay", "seed"})
        channels = []
        for fname in SENSOR_FIELDS:
            fkey = f"{key}.{fname}"
            entry = self.mapping(spec.get(fname) or {}, fkey, {"noise", "bias", "resolution"})
            noise = self.number(entry.get("noise", 0.0), f"{fkey}.noise", minimum=0.0)
            bias = self.number(entry.get("bias", 0.0), f"{fkey}.bias")
            resolution = self.number(entry.get("resolution", 0.0), f"{fkey}.resolution",
                                     minimum=0.0)
            scales = [self.angle_scale if fname != "effort" and j.kind == "revolute" else 1.0
                      for j in joints]
            channels.append(SensorChannel(tuple(noise * c for c in scales),
                                          tuple(bias * c for c in scales),
                                          tuple(resolution * c for c in scales)))
        delay = self.number(spec.get("delay", 0.0), f"{key}.delay", minimum=0.0)
        seed = spec.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
            raise self.fail(f"{key}.seed", "a whole number from 0 to 2**63 - 1", seed)
        return JointSensors(tuple(channels), delay, seed)

    def plant(
        self, dynamics: Sequence[ActuatorDynamics], sensors: JointSensors | None, defaults: dict
    ) -> Plant:
        """The plant keys; delays checked against ``defaults.rate`` when the scene gives it
        (the simulator checks them at the rate it runs)."""
        if "rate" in defaults:
            delays = [(d.delay, f"{d.key}.delay") for d in dynamics]
            if sensors is not None:
                delays.append((sensors.delay, "sensors.joint_states.delay"))
            for delay, key in delays:
                try:
                    delay_ticks(delay, defaults["rate"], "", key)
                except ValueError:
                    ticks = delay * defaults["rate"]
                    raise self.fail(key, "a whole number of ticks at defaults.rate "
                                    f"{defaults['rate']:g} Hz", f"{delay:g} s = {ticks:g} ticks"
                                    ) from None
        if all(not d.dynamic and d.gear == 1.0 for d in dynamics):
            dynamics = []  # the plain actuators of a scene without these keys
        return Plant(tuple(dynamics), sensors, self.source)

    def points(
        self, value: object, chains: Sequence[Chain], links: Sequence[Link]
    ) -> list[NamedPoint]:
        """Chain tips plus the named points of the scene."""
        out = [
            NamedPoint(f"{ch.name}_tip", PointRef(ch.links[-1], (links[ch.links[-1]].length, 0.0)))
            for ch in chains
        ]
        names = {p.name for p in out}
        value = self.sequence(value, "points")
        for k, pt in enumerate(value):
            key = f"points[{k}]"
            pt = self.mapping(pt, key, {"name", "link", "at"})
            pname = self.name(self.require(pt, "name", key), f"{key}.name")
            if pname in names:
                raise self.fail(
                    f"{key}.name", "a point name used once (chain tips are '<chain>_tip')", pname
                )
            names.add(pname)
            ref = self.point({k2: v for k2, v in pt.items() if k2 != "name"}, key)
            out.append(NamedPoint(pname, ref))
        return out

    def loads(self, value: object) -> tuple[Load, ...]:
        """The ``loads`` section: constant forces (world frame, N) and torques (N m) on links."""
        out, names = [], set()
        for k, item in enumerate(self.sequence(value, "loads", max_len=MAX_CLOSURES)):
            key = f"loads[{k}]"
            item = self.mapping(item, key, {"name", "point", "force", "torque"})
            lname = self.name(self.require(item, "name", key), f"{key}.name")
            if lname in names:
                raise self.fail(f"{key}.name", "a load name used once", lname)
            names.add(lname)
            ref = self.point(self.require(item, "point", key), f"{key}.point")
            if ref.link < 0:
                raise self.fail(f"{key}.point", "a point on a moving link (the ground takes no "
                                "load)", item["point"])
            force = self.vector(item.get("force", [0.0, 0.0]), f"{key}.force")
            out.append(Load(lname, ref, force, self.number(item.get("torque", 0.0),
                                                           f"{key}.torque")))
        return tuple(out)

    def gains(self, value: object) -> dict:
        """The ``closure_method`` section."""
        allowed = {"method", "kp", "kv", "omega_n", "zeta", "alpha", "beta", "projection"}
        value = self.mapping(value, "closure_method", allowed)
        out = {}
        out["method"] = self.choice(
            value.get("method", "penalty"), "closure_method.method", ("penalty", "exact")
        )
        for k in ("kp", "kv", "omega_n", "zeta", "alpha", "beta"):
            if k in value:
                out[k] = self.number(value[k], f"closure_method.{k}", minimum=0.0)
        if "kp" in out and "omega_n" in out:
            raise self.fail(
                "closure_method", "either kp/kv or omega_n/zeta, not both", sorted(value)
            )
        for k, needs in (("kv", "kp"), ("zeta", "omega_n")):
            if k in out and needs not in out:
                raise self.fail(f"closure_method.{k}", f"'{k}' together with '{needs}'", value[k])
        if "projection" in value:
            if not isinstance(value["projection"], bool):
                raise self.fail("closure_method.projection", "true or false", value["projection"])
            out["projection"] = value["projection"]
        return out

    def defaults(self, value: object) -> dict:
        """The ``defaults`` section (run settings)."""
        from vjm_ros.core.integrators import INTEGRATORS

        value = self.mapping(value, "defaults", {"integrator", "rate", "substeps", "duration"})
        out = {}
        if "integrator" in value:
            out["integrator"] = self.choice(value["integrator"], "defaults.integrator", INTEGRATORS)
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

    # -------------------------------------------------------------- checks on the model
    def check_inertia(self, model: Model) -> None:
        """Refuse a singular mass matrix, naming the link whose joint has no inertia."""
        q, _ = model.initial_state()
        with np.errstate(all="ignore"):
            m = _mass_matrix(model, q)
            ok = bool(np.all(np.isfinite(m)))
            ev = np.linalg.eigvalsh(m) if ok else np.array([np.nan])
        if ok and ev[0] > 1e-12 * max(float(ev[-1]), 1e-300):
            return
        worst = int(np.argmax(np.abs(np.linalg.eigh(m)[1][:, 0]))) if ok else 0
        which = [lk.name for lk in model.links if lk.mass == 0 and lk.inertia == 0]
        raise self.fail(
            self.link_key[worst],
            f"some mass or inertia moved by joint '{model.joints[worst].name}' (a positive "
            f"definite mass matrix; links without mass or inertia: {_listing(which) or 'none'})",
            f"smallest eigenvalue {float(ev[0]):.3g}",
        )

    def close(self, model: Model, spec: object) -> tuple[Model, float]:
        """Check the closures at t = 0, or assemble them if the scene asks for it."""
        if spec is None:
            q, _ = model.initial_state()
            res = closure_residual(model, q)
            err = float(np.max(np.abs(res))) if res.size else 0.0
            if not err <= DEFAULT_CLOSURE_TOLERANCE:
                k, size = _worst_closure(model, res)
                raise self.fail(
                    f"closures[{k}]",
                    f"closures that hold at t = 0 within {DEFAULT_CLOSURE_TOLERANCE:g} "
                    "(or an 'assemble' section)",
                    f"residual {size:.3g} at '{model.closures[k].name}'",
                )
            return model, err
        spec = self.mapping(spec, "assemble", {"fixed", "tolerance"})
        fixed_names = self.sequence(spec.get("fixed", []), "assemble.fixed")
        fixed = [self.joint_ref(jn, f"assemble.fixed[{k}]") for k, jn in enumerate(fixed_names)]
        tol = self.number(spec.get("tolerance", 1e-10), "assemble.tolerance", positive=True)
        with np.errstate(all="ignore"):
            try:
                q, qd, err = assemble(model, fixed, tol)
            except np.linalg.LinAlgError as exc:
                raise self.fail(
                    "assemble", "geometry that can be assembled", f"linear algebra failure: {exc}"
                ) from None
        if not err <= tol or not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
            k, size = _worst_closure(model, closure_residual(model, q))
            raise self.fail(
                f"closures[{k}]",
                f"geometry that assembly can close to within {tol:g} from the given guesses "
                "(check lengths, targets and the fixed joints)",
                f"residual {size:.3g} at '{model.closures[k].name}' after assembly",
            )
        return model.with_state(q, qd), err


def _mass_matrix(model: Model, q: np.ndarray) -> np.ndarray:
    """``M(q)``, shape (n, n), from the compiled kernel (imported here: only scenes that are
    checked load it)."""
    from vjm_ros.core.mechanism import Mechanism

    return Mechanism.reader(model).mass_matrix(q)
