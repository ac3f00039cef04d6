"""``vjm model SCENE``: the closed-chain model's quantities at a state, without writing code.

    vjm model five_bar                                   # at the scene's initial state
    vjm model five_bar --state left_elbow=1.4 right_elbow=-1.4 --rates left_base=0.5 right_base=0
    vjm model three_chain --udd 0.5 -0.2 --preload 10 --no-limits --json
    vjm model five_bar --state left_elbow=1.4 right_elbow=-1.4 --point left_tip --xdd 0.0 -1.0

Joints named in ``--state`` are held (rad or m) and the others assembled; ``--rates`` gives the
independent coordinates' rates (the others follow from the closures). Prints the named points,
the task Jacobian of ``--point`` (default: the first named point), the reduced mass matrix,
Coriolis and gravity terms, and the actuator efforts for ``--udd`` (default zero: the efforts
that hold the mechanism still against gravity) or, instead, for ``--xdd``, the acceleration of
``--point`` (``--udd`` and ``--xdd`` together are refused). five_bar's initial state has both
arms stretched: its pin cannot be accelerated there (``--xdd`` exits with 1), hence the bent
elbows above.

The output (``--json``: one JSON object on one line; otherwise one ``key  value`` line each) has
the keys of :data:`KEYS`. Exit codes: :data:`EXIT_CODES`.
"""

from __future__ import annotations

import json
import textwrap
from typing import TYPE_CHECKING

import numpy as np

from vjm_ros.core.errors import ConfigurationError

if TYPE_CHECKING:
    import argparse

KEYS = {
    "scene": "the scene's name",
    "dof": "degrees of freedom d",
    "independent": "the independent coordinates' joints (d names)",
    "q": "{joint: coordinate}, rad or m (the state, assembled)",
    "qd": "{joint: rate}, rad/s or m/s",
    "points": "{point: [x, y]}, m",
    "singularity_measure": "smallest singular value of A_v (0 at a singular configuration; "
                           "null without closures)",
    "task_point": "the named point of the task quantities (null without points)",
    "task_jacobian": "J_t: xd = J_t ud, rows x and y of d values, m per rad or m per m",
    "task_bias": "[x, y] acceleration at udd = 0, m/s^2",
    "task_singularity_measure": "smallest singular value of J_t, m per rad or m per m "
                                "(0 where the point cannot move in some direction)",
    "reduced_mass_matrix": "M_r, d x d, kg m^2 or kg",
    "coriolis": "c_r, d values, N m or N",
    "gravity": "g_r, d values, N m or N",
    "asked": "{udd: [...]} or {point: name, xdd: [x, y]}, rad/s^2 or m/s^2",
    "efforts": "{actuated joint: effort}, N m or N",
}
"""The output's keys, in order, and what each holds."""

EXIT_CODES = {
    0: "done",
    1: "no answer at this state: a singular configuration (of the mechanism, or of --point "
       "for --xdd) or efforts beyond the actuators' limits (--no-limits gives them); the "
       "message says which",
    2: "bad input: scene, joint, point or number, --state the closures cannot meet, a "
       "preload without one redundant actuator, --udd with --xdd",
}
"""Exit codes of ``vjm model``."""


def _epilog() -> str:
    def rows(items: dict, width: int) -> str:
        return "\n".join(textwrap.fill(str(v), 96, initial_indent=f"  {k!s:<{width}}",
                                        subsequent_indent=" " * (2 + width))
                          for k, v in items.items())

    return (f"output keys (--json: one JSON object on one line):\n{rows(KEYS, 26)}\n\n"
            f"exit codes:\n{rows(EXIT_CODES, 3)}")


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``vjm model`` on the ``vjm`` sub-command parser."""
    import argparse

    p = sub.add_parser("model", help="closed-chain model quantities at a state",
                       description="The closed-chain model's quantities at a state: points, "
                       "task Jacobian, reduced dynamics,\nand the efforts for --udd or --xdd "
                       "(one of the two).",
                       epilog=_epilog(), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", help="built-in scene name or YAML path")
    p.add_argument("--state", nargs="+", default=[], metavar="JOINT=VALUE",
                   help="joints held at these values (rad or m); the others are assembled")
    p.add_argument("--rates", nargs="+", default=[], metavar="JOINT=VALUE",
                   help="rates of independent coordinates (rad/s or m/s; others zero)")
    p.add_argument("--independent", nargs="+", metavar="JOINT",
                   help="independent coordinates (default: the first actuated joints)")
    asked = p.add_mutually_exclusive_group()
    asked.add_argument("--udd", type=float, nargs="+",
                       help="independent accelerations, rad/s^2 or m/s^2 (default zero)")
    p.add_argument("--point", help="named point of the task Jacobian and of --xdd")
    asked.add_argument("--xdd", type=float, nargs=2, metavar=("AX", "AY"),
                       help="acceleration of --point instead of --udd, m/s^2")
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


def run(args: argparse.Namespace) -> int:
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
    measure = cm.singularity_measure(q)
    out = {
        "scene": model.name,
        "dof": cm.dof,
        "independent": ind,
        "q": dict(zip(names, q.tolist(), strict=True)),
        "qd": dict(zip(names, qd.tolist(), strict=True)),
        "points": {p.name: cm.forward_kinematics(q, p.name).tolist() for p in model.points},
        "singularity_measure": measure if np.isfinite(measure) else None,  # JSON has no inf
        "task_point": point,
        "task_jacobian": cm.task_jacobian(q, point).tolist() if point else None,
        "task_bias": cm.task_bias(q, qd, point).tolist() if point else None,
        "task_singularity_measure": cm.singularity_measure(q, point=point) if point else None,
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
