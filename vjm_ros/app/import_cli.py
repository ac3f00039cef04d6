"""``vjm import MODEL [--actuate JOINT ...] [-o OUT.yaml]``: a model of another format as a scene.

    vjm import four_bar.sdf --actuate crank_joint -o four_bar.yaml
    vjm import five_bar.xml                       # the scene YAML on standard output

``MODEL`` is an SDFormat ``.sdf``, a ``.urdf`` or a MuJoCo MJCF ``.xml`` file (docs/models.md says
what each element becomes). What the scene does not represent (collision and visual geometry,
solver settings, ...) is said once on standard error. Exit codes: 0 written; 2 the model cannot
be read or represented (the message names the file, the element and why).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``import`` subcommand on the ``vjm`` subparsers ``sub``."""
    p = sub.add_parser("import", help="a .sdf, .urdf or MJCF .xml model as scene YAML")
    p.add_argument("model", type=Path, help="the model file (.sdf, .urdf or MJCF .xml)")
    p.add_argument("--actuate", nargs="+", default=[], metavar="JOINT",
                   help="add an actuator (unlimited effort) to each named joint")
    p.add_argument("-o", "--output", type=Path, help="write the scene YAML here (default: stdout)")


def run(args: argparse.Namespace) -> int:
    """Run ``vjm import``; a :class:`~vjm_ros.core.errors.SceneError` propagates (exit 2)."""
    from vjm_ros.formats.importing import import_model

    imported = import_model(args.model, tuple(args.actuate))
    if imported.ignored:
        print(f"vjm: {args.model}: not represented in the scene: "
              + "; ".join(imported.ignored), file=sys.stderr)
    if args.output is None:
        sys.stdout.write(imported.text)
        return 0
    try:
        args.output.write_text(imported.text, encoding="utf-8")
    except OSError as exc:
        print(f"vjm: error: {args.output}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.output} ({imported.document['name']}: "
          f"{sum(len(c['links']) for c in imported.document['chains'])} links, "
          f"{len(imported.document.get('closures', []))} closures)")
    return 0
