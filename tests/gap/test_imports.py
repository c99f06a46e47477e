"""companion.gap has no import cycle: every module-level *and* function-level import between its modules
points one way (likelihood <- candidates <- compare <- selection <- workflow), read from the source."""

import ast
from pathlib import Path

import companion.gap

PKG = Path(companion.gap.__file__).parent


def _gap_imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            if node.module.startswith("companion.gap."):
                out.add(node.module.split(".")[2])
            elif node.module == "companion.gap":
                out.update(a.name for a in node.names if (PKG / f"{a.name}.py").exists())
        elif isinstance(node, ast.Import):
            out.update(a.name.split(".")[2] for a in node.names if a.name.startswith("companion.gap."))
    return out


def test_no_import_cycle_in_gap():
    graph = {p.stem: _gap_imports(p) - {p.stem} for p in PKG.glob("*.py") if p.stem != "__init__"}
    assert "candidates" in graph["compare"] and "compare" not in graph["candidates"]
    state: dict[str, int] = {}

    def visit(m, stack):
        if state.get(m) == 1:
            raise AssertionError("import cycle: " + " -> ".join(stack + [m]))
        if state.get(m) == 2:
            return
        state[m] = 1
        for d in graph.get(m, ()):
            visit(d, stack + [m])
        state[m] = 2

    for m in graph:
        visit(m, [])


def test_modules_import_on_their_own():
    import importlib
    import subprocess
    import sys

    for m in sorted(p.stem for p in PKG.glob("*.py") if p.stem != "__init__"):
        importlib.import_module(f"companion.gap.{m}")
    # a fresh interpreter importing the leaf-most module first (a cycle would fail here)
    code = "import companion.gap.candidates, companion.gap.compare, companion.gap.workflow"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120).returncode == 0
