"""``vjm model SCENE``: the closed-chain model's quantities at a state, without writing code.

    vjm model five_bar                                   # at the scene's initial state
    vjm model five_bar --state left_base=-0.7 --rates left_base=0.5 right_base=0
    vjm model three_chain --udd 0.5 -0.2 --preload 10 --json
    vjm model five_bar --point pin --xdd 0.0 -1.0

Joints named in ``--state`` are held (rad or m) and the others assembled; ``--rates`` gives the
independent coordinates' rates (the others follow from the closures). Prints the named points,
the task Jacobian of ``--point`` (default: the first named point), the reduced mass matrix,
Coriolis and gravity terms, and the actuator efforts for ``--udd`` (default zero: the efforts
that hold the mechanism still against gravity) or ``--xdd``.
"""

from __future__ import annotations

import json

import numpy as np

from vjm_ros.core.errors import ConfigurationError


def add_parser(sub) -> None:
    """Register ``vjm model`` on the ``vjm`` sub-command parser."""
    p = sub.add_parser("model", help="closed-chain model quantities at a state")
    p.add_argument("scene", help="built-in scene name or YAML path")
    p.add_argument("--state", nargs="+", default=[], metavar="JOINT=VALUE",
                   help="joints held at these values (rad or m); the others are assembled")
    p.add_argument("--rates", nargs="+", default=[], metavar="JOINT=VALUE",
                   help="rates of independent coordinates (rad/s or m/s; others zero)")
    p.add_argument("--independent", nargs="+", metavar="JOINT",
                   help="independent coordinates (default: the first actuated joints)")
    p.add_argument("--udd", type=float, nargs="+", help="independent accelerations")
    p.add_argument("--point", help="named point of the task Jacobian and of --xdd")
    p.add_argument("--xdd", type=float, nargs=2, help="acceleration of --point, m/s^2")
    p.add_argument("--weights", type=float, nargs="+", help="effort weights (redundant)")
    p.add_argument("--preload", type=float, default=0.0, help="internal preload, N m or N")
    p.add_argument("--no-limits", action="store_true", help="ignore the actuators' limits")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _pairs(items: list[str], flag: str) -> dict[str, float]:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            out[name] = float(value)
        except ValueError:
            sep = ""
        if not sep:
            raise ConfigurationError(f"{flag}: expected JOINT=VALUE, found {item!r}")
    return out


def run(args) -> int:
    """The command: returns the exit code."""
    # imported here: every vjm command registers this parser, only `vjm model` needs these
    from vjm_ros.control import ClosedChainModel
    from vjm_ros.scene.description import with_initial_positions
    from vjm_ros.scene.loader import load_scene

    scene = load_scene(args.scene)
    model = with_initial_positions(scene.model, _pairs(args.state, "--state"), name="--state")
    cm = ClosedChainModel(model, args.independent)
    q, _ = model.initial_state()
    rates = _pairs(args.rates, "--rates")
    names = model.joint_names
    ind = [names[i] for i in cm.independent]
    extra = [k for k in rates if k not in ind]
    if extra:
        raise ConfigurationError(f"--rates: expected independent joints ({', '.join(ind)}), "
                                 f"found {extra[0]!r}")
    ud = np.array([rates.get(j, 0.0) for j in ind])
    qd = cm.dependent_velocities(q, ud)
    point = args.point or (model.points[0].name if model.points else None)
    rd = cm.reduced_dynamics(q, qd)
    kw = {"weights": args.weights, "preload": args.preload,
          "respect_limits": not args.no_limits}
    if args.xdd is not None:
        tau = cm.inverse_dynamics(q, qd, point=point, xdd=args.xdd, **kw)
        asked = {"point": point, "xdd": list(args.xdd)}
    else:
        udd = np.zeros(cm.dof) if args.udd is None else np.array(args.udd)
        tau = cm.inverse_dynamics(q, qd, udd, **kw)
        asked = {"udd": udd.tolist()}
    out = {
        "scene": model.name,
        "dof": cm.dof,
        "independent": ind,
        "q": dict(zip(names, q.tolist(), strict=True)),
        "qd": dict(zip(names, qd.tolist(), strict=True)),
        "points": {p.name: cm.forward_kinematics(q, p.name).tolist() for p in model.points},
        "singularity_measure": cm.singularity_measure(q),
        "task_point": point,
        "task_jacobian": cm.task_jacobian(q, point).tolist() if point else None,
        "task_bias": cm.task_bias(q, qd, point).tolist() if point else None,
        "reduced_mass_matrix": rd.mass_matrix.tolist(),
        "coriolis": rd.coriolis.tolist(),
        "gravity": rd.gravity.tolist(),
        "asked": asked,
        "efforts": dict(zip(model.actuator_names, tau.tolist(), strict=True)),
    }
    if args.json:
        print(json.dumps(out))
        return 0
    width = max(len(k) for k in out)
    for key, value in out.items():
        print(f"{key:<{width}}  {_short(value)}")
    return 0


def _short(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, dict):
        return ", ".join(f"{k} = {_short(v)}" for k, v in value.items())
    if isinstance(value, list):
        return "[" + ", ".join(_short(v) for v in value) + "]"
    return str(value)
