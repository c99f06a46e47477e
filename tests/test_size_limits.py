"""Size limits of the product code (issue 46): no module in companion/ over 500 lines, no function or method
over 80 lines (end_lineno - lineno + 1 of its ast node: from the `def` line, docstring included). A file or function
that grows past them is split by role, not allowed an exception here."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "companion"
MAX_FILE_LINES = 500  #: a module a reader takes in at one sitting
MAX_FUNCTION_LINES = 80  #: a function a reader sees on one screen and a half


def _modules():
    return sorted(p for p in PKG.rglob("*.py") if "__pycache__" not in p.parts)


def test_the_package_has_modules():
    assert len(_modules()) > 50  # the walk finds the package (not an empty glob passing by default)


def test_no_module_over_500_lines():
    long = {str(p.relative_to(PKG.parent)): n for p in _modules()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_FILE_LINES}
    assert not long, long


def test_no_function_over_80_lines():
    long = {}
    for p in _modules():
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"), str(p))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long[f"{p.relative_to(PKG.parent)}:{node.lineno} {node.name}"] = n
    assert not long, long


def test_module_names_are_unique_across_packages():
    """A module is named for its role (issue 46: three report.py, two runner.py ... read alike in a traceback
    and an import list); only package markers repeat."""
    seen = {}
    for p in _modules():
        if p.name != "__init__.py":
            seen.setdefault(p.name, []).append(str(p.relative_to(PKG.parent)))
    assert not {k: v for k, v in seen.items() if len(v) > 1}
