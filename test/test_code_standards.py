"""Two of the code standards of CONTRIBUTING.md, held on the whole package: every public function
and method has type hints, and no module is over 600 lines (small modules with one job each)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "vjm_ros"
MAX_LINES = 600


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def _unannotated(tree: ast.Module) -> list[str]:
    """Public functions and methods of public classes missing a parameter or return annotation
    (``__init__`` is public for its parameters; ``self`` and ``cls`` need none)."""
    found = []

    def visit(body: list[ast.stmt], owner: str = "") -> None:
        for node in body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                visit(node.body, f"{owner}{node.name}.")
            elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and (
                    not node.name.startswith("_") or node.name == "__init__"):
                args = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
                untyped = [a.arg for a in args
                           if a.annotation is None and a.arg not in ("self", "cls")]
                if node.returns is None and node.name != "__init__":
                    untyped.append("return")
                if untyped:
                    found.append(f"{owner}{node.name}({', '.join(untyped)}) line {node.lineno}")

    visit(tree.body)
    return found


def test_every_public_function_has_type_hints():
    missing = {str(p.relative_to(PACKAGE.parent)): names for p in _modules()
               if (names := _unannotated(ast.parse(p.read_text(encoding="utf-8"))))}
    assert not missing, missing


def test_the_check_sees_what_it_judges():
    tree = ast.parse("class A:\n    def f(self, x): pass\n    def _g(self, y): pass\n"
                     "def h(a: int) -> int: pass\ndef k(b: int): pass\nclass _B:\n"
                     "    def f(self, x): pass\n")
    assert _unannotated(tree) == ["A.f(x, return) line 2", "k(return) line 5"]


def test_no_module_is_over_600_lines():
    long = {str(p.relative_to(PACKAGE.parent)): n for p in _modules()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not long, long
