"""Every third-party module the package imports is declared where its users install it from.

A module imported anywhere in ``vjm_ros/`` must come from a distribution that ``setup.py`` names
(``install_requires`` or an extra), or be a ROS 2 package that ``package.xml`` depends on; an
import guarded by ``except ImportError`` is optional and needs neither. Being installed here as
the dependency of a dependency (``zstandard`` and ``lz4`` came with ``mcap``) is not enough: that
dependency may drop it, or allow versions the package does not work with.
"""

from __future__ import annotations

import ast
import importlib.metadata as md
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]


def setup_py_requirements() -> set[str]:
    """Names of the distributions in ``setup.py``'s ``install_requires`` and extras (read from
    the file's source, so an edit counts without reinstalling)."""
    tree = ast.parse((ROOT / "setup.py").read_text())
    call = next(n for n in ast.walk(tree) if isinstance(n, ast.Call)
                and getattr(n.func, "id", None) == "setup")
    keywords = {k.arg: k.value for k in call.keywords}
    specs = list(ast.literal_eval(keywords["install_requires"]))
    for extra in ast.literal_eval(keywords["extras_require"]).values():
        specs += extra
    return {canonicalize_name(Requirement(s).name) for s in specs}


def package_xml_depends() -> set[str]:
    """ROS package names ``package.xml`` depends on (run, build or test)."""
    root = ET.parse(ROOT / "package.xml").getroot()
    tags = ("depend", "exec_depend", "build_depend", "test_depend")
    return {e.text.strip() for tag in tags for e in root.iter(tag)}


def _optional(handlers: list[ast.ExceptHandler]) -> bool:
    names = set()
    for h in handlers:
        types = h.type.elts if isinstance(h.type, ast.Tuple) else [h.type]
        names |= {getattr(t, "id", None) for t in types}
    return bool(names & {"ImportError", "ModuleNotFoundError"})


def imports_of(source: str) -> set[str]:
    """Top-level third-party modules ``source`` imports outside ``try ... except ImportError``."""
    tree = ast.parse(source)
    optional: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Try) and _optional(node.handlers):
            optional |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    found = set()
    for node in ast.walk(tree):
        if id(node) in optional:
            continue
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        found |= {n.split(".")[0] for n in names}
    return {m for m in found if m not in sys.stdlib_module_names and m != "vjm_ros"}


def imported_modules() -> dict[str, set[str]]:
    """:func:`imports_of` every module of ``vjm_ros/``, with the files that import each."""
    found: dict[str, set[str]] = {}
    for path in sorted((ROOT / "vjm_ros").rglob("*.py")):
        for module in imports_of(path.read_text()):
            found.setdefault(module, set()).add(str(path.relative_to(ROOT)))
    return found


@pytest.fixture(scope="module")
def imported() -> dict[str, set[str]]:
    """:func:`imported_modules` of the checkout, parsed once for the two tests that read it."""
    return imported_modules()


def test_every_imported_distribution_is_declared(imported):
    declared = setup_py_requirements()
    ros = package_xml_depends()
    providers = md.packages_distributions()
    undeclared = []
    for module, files in sorted(imported.items()):
        if module in ros:
            continue
        dists = {canonicalize_name(d) for d in providers.get(module, [])}
        if not dists & declared:
            undeclared.append(f"{module} (from {sorted(dists) or 'no installed distribution'}, "
                              f"imported by {', '.join(sorted(files))})")
    assert not undeclared, "imported but not in setup.py or package.xml: " + "; ".join(undeclared)


def test_the_check_sees_the_imports_it_judges(imported):
    """Direct imports count, also inside functions and ``from`` imports; guarded ones and the
    standard library do not (else the test above could pass by finding nothing)."""
    source = """
import json
import numpy as np
from mcap.writer import Writer
from vjm_ros.logs import cdr
from . import sibling


def compress(data):
    import lz4.frame
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        threadpool_limits = None
    try:
        import yaml
    except OSError:
        pass
"""
    assert imports_of(source) == {"numpy", "mcap", "lz4", "yaml"}
    modules = imported
    assert "vjm_ros/logs/mcap_block.py" in modules["zstandard"]
    assert "vjm_ros/logs/mcap_block.py" in modules["lz4"]
