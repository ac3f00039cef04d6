"""The package's layering holds (docs/design.md section 7), checked by import-linter.

The contracts live in ``setup.cfg`` (``[importlinter]``): each module imports only from the
layers below it, and only ``vjm_ros.ros`` imports rclpy and the ROS message packages (the
physics, scenes, simulator and logs run without ROS). import-linter builds the import graph from
the source itself, so a new import that crosses a layer fails here with the chain of imports that
does it. The contracts themselves are held to the package: every layer and every module of
``core`` has its place in them, and every ROS interface package ``vjm_ros.ros`` imports is
forbidden to the layers below.
"""

from __future__ import annotations

import ast
import configparser
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "vjm_ros"


def _contract(name: str) -> configparser.SectionProxy:
    config = configparser.ConfigParser()
    config.read(REPO / "setup.cfg")
    return config[f"importlinter:contract:{name}"]


def _listed(contract: configparser.SectionProxy, key: str) -> set[str]:
    """The modules a contract's ``key`` names (one line each, ``|`` between siblings)."""
    return {name.strip() for line in contract[key].splitlines() for name in line.split("|")
            if name.strip()}


def _children(folder: Path) -> set[str]:
    """The modules and packages directly in ``folder``, as dotted names."""
    prefix = folder.relative_to(REPO).as_posix().replace("/", ".")
    return {f"{prefix}.{p.stem}" for p in folder.iterdir()
            if (p.suffix == ".py" and p.stem != "__init__")
            or (p.is_dir() and (p / "__init__.py").is_file())}


def test_import_contracts_are_kept():
    out = subprocess.run(
        [str(Path(sys.executable).with_name("lint-imports")), "setup.cfg", "--no-cache"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,  # a hang guard: the check takes ~1 s
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "0 broken" in out.stdout


def test_every_layer_and_every_core_module_has_its_place_in_the_contracts():
    """A module missing from a layers contract is checked by none of its rules."""
    layers = _listed(_contract("layers"), "layers")
    assert _children(PACKAGE) == layers, _children(PACKAGE) ^ layers
    core = _listed(_contract("core"), "layers")
    assert _children(PACKAGE / "core") == core, _children(PACKAGE / "core") ^ core
    below_ros = layers - {"vjm_ros.ros"}
    for name in ("rclpy", "ros-interfaces"):
        assert _listed(_contract(name), "source_modules") == below_ros, name


def test_every_ros_interface_package_the_node_imports_is_forbidden_below_it():
    """The ROS message and service packages ``vjm_ros.ros`` imports (found in its sources:
    ``from x.msg``, ``from x.srv``, ``import x.msg``) are each forbidden to the other layers."""
    imported = set()
    for path in (PACKAGE / "ros").rglob("*.py"):
        imported |= set(re.findall(r"^\s*(?:from|import)\s+(\w+)\.(?:msg|srv|action)\b",
                                   path.read_text(), re.MULTILINE))
    assert {"std_msgs", "sensor_msgs"} <= imported  # the scan does find the node's imports
    forbidden = _listed(_contract("ros-interfaces"), "forbidden_modules")
    assert imported <= forbidden, imported - forbidden


JIT_SURFACE = {"jit", "variant", "HAVE_NUMBA", "tiers"}
"""What ``core`` may take from ``vjm_ros.jit``: the decorators and the flag (the physics), and the
tiered entry points (``mechanism`` wraps the kernel and the pipeline in them)."""


def test_core_takes_only_the_public_surface_of_jit():
    """The compiling machinery (numba's internals, the cache keys, the compile server) stays in
    ``vjm_ros.jit``: ``core`` imports ``from vjm_ros.jit import ...`` these names only."""
    taken = {}
    for path in (PACKAGE / "core").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("vjm_ros.jit"):
                names = {a.name if node.module == "vjm_ros.jit" else f"{node.module}.{a.name}"
                         for a in node.names}
                taken.setdefault(path.name, set()).update(names)
            elif isinstance(node, ast.Import):
                assert not any(a.name.startswith("vjm_ros.jit") for a in node.names), path
    assert "jit" in taken.get("kernels.py", set())  # the scan does find the imports
    wider = {name: names - JIT_SURFACE for name, names in taken.items() if names - JIT_SURFACE}
    assert wider == {}
