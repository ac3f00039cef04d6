"""``vjm export SCENE (--urdf FILE | --mjcf FILE)``: a scene as URDF or MJCF.

    vjm export four_bar --urdf four_bar.urdf                     # robot_state_publisher, RViz
    vjm export four_bar --urdf four_bar_gz.urdf --zero initial   # Gazebo (zero pose closed)
    vjm export slider_crank --mjcf slider_crank.xml              # MuJoCo
    vjm export five_bar --urdf -                                 # to standard output

The URDF (:mod:`vjm_ros.formats.urdf_out`) holds the scene's chains as a tree with the scene's
joint names, joint positions equal to the joint coordinates (``--zero initial``: the zero pose
is the initial state), the closures as SDFormat joints in ``<gazebo>``. The MJCF
(:mod:`vjm_ros.formats.mjcf_out`) holds bodies nested per chain, closures as equality
constraints, motors, and the scene's step and integrator as ``<option>`` (``--timestep``,
``--integrator``, ``--solref`` override them). Exit codes: 0 written; 2 bad input (scene,
argument, a name the file format reserves, a path that cannot be written).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vjm_ros.core.errors import ConfigurationError

MUJOCO_INTEGRATORS = {
    "rk4": "RK4",
    "semi_implicit_euler": "Euler",
    "explicit_euler": "Euler",
    "implicit_euler": "implicitfast",
}
"""MuJoCo's integrator for a scene's default one (MuJoCo's ``Euler`` is semi-implicit; adaptive
methods map to ``RK4``)."""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``vjm export`` on the ``vjm`` subparsers."""
    from vjm_ros.formats.urdf_out import ZERO_POSES

    p = sub.add_parser("export", help="write a scene as URDF or MJCF",
                       description="Write a scene as URDF (for robot_state_publisher, RViz, "
                       "Gazebo) or MJCF (for MuJoCo); FILE '-' is standard output.")
    p.add_argument("scene", help="built-in scene name or scene path")
    out = p.add_mutually_exclusive_group(required=True)
    out.add_argument("--urdf", metavar="FILE", help="write URDF to FILE")
    out.add_argument("--mjcf", metavar="FILE", help="write MJCF to FILE")
    p.add_argument("--zero", choices=list(ZERO_POSES), default="coordinates",
                   help="URDF: zero pose at q = 0, positions = joint coordinates (default), or "
                   "at the initial state, positions = q - q0 (Gazebo builds closures there)")
    p.add_argument("--timestep", type=float, metavar="S",
                   help="MJCF: MuJoCo step, s (default: the scene's tick over its substeps)")
    p.add_argument("--integrator", choices=["Euler", "implicitfast", "implicit", "RK4"],
                   help="MJCF: MuJoCo integrator (default: the scene's, mapped)")
    p.add_argument("--solref", type=float, nargs=2, metavar=("A", "B"),
                   help="MJCF: equality solref (timeconst dampratio, or -stiffness -damping)")


def run(args: argparse.Namespace) -> int:
    """Write the export; return the exit code (errors raise :class:`ConfigurationError`)."""
    from vjm_ros.scene.loader import load_scene

    scene = load_scene(args.scene)
    if args.urdf is not None:
        if any(v is not None for v in (args.timestep, args.integrator, args.solref)):
            raise ConfigurationError("--timestep, --integrator and --solref: MJCF options, "
                                     "given with --urdf")
        from vjm_ros.formats.urdf_out import scene_urdf

        text, target = _written(lambda: scene_urdf(scene.model, args.zero, scene.plant)), args.urdf
    else:
        if args.zero != "coordinates":
            raise ConfigurationError(f"--zero {args.zero}: a URDF option, given with --mjcf "
                                     "(the MJCF's qpos is always the joint coordinate)")
        text, target = _written(lambda: _mjcf(scene, args)), args.mjcf
    _write(text, target)
    return 0


def _written(make) -> str:
    try:
        return make()
    except ValueError as exc:
        raise ConfigurationError(str(exc)) from None


def _mjcf(scene, args) -> str:
    from vjm_ros.formats.mjcf_out import DEFAULT_SOLREF, MjcfSettings, scene_mjcf

    d = scene.defaults
    rate, substeps = float(d.get("rate", 1000.0)), int(d.get("substeps", 1))
    timestep = args.timestep if args.timestep is not None else 1.0 / (rate * substeps)
    if not timestep > 0.0:
        raise ConfigurationError(f"--timestep: expected a positive step in s, found {timestep}")
    integrator = args.integrator or MUJOCO_INTEGRATORS.get(d.get("integrator", "rk4"), "RK4")
    solref = tuple(args.solref) if args.solref else DEFAULT_SOLREF
    return scene_mjcf(scene.model, MjcfSettings(timestep=timestep, integrator=integrator,
                                                solref=solref), scene.plant)


def _write(text: str, target: str) -> None:
    if target == "-":
        sys.stdout.write(text)
        return
    try:
        Path(target).write_text(text, encoding="utf-8")
    except OSError as exc:
        raise ConfigurationError(f"{target}: cannot write ({exc.strerror or exc})") from None
