"""The layering rule of docs/architecture.md, read from the code: no module imports from a higher layer, and
the numerical core imports only numpy, scipy and the standard library. Every import counts, also one inside a
function (a lazy import is still a dependency)."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

CORE, ADAPTER, SERVICE, CLI = 0, 1, 2, 3
LAYER_NAMES = {CORE: "core", ADAPTER: "adapter", SERVICE: "service/fleet", CLI: "cli"}
#: module prefix -> layer; the longest matching prefix decides (docs/architecture.md, "Who may import whom")
LAYERS = {
    "companion": CORE,  # samples, units, errors, timebase, timespans, the package itself
    "companion.allan": CORE,
    "companion.estimators": CORE,
    "companion.sim": CORE,  # synthesis, body motion, the vehicle simulator
    "companion.gap": CORE,
    "companion.compensation": CORE,
    "companion.health": CORE,
    "companion.analysis": CORE,
    "companion.redundancy": CORE,  # in-flight noise per IMU from redundant IMUs
    "companion.analysis.source": ADAPTER,  # loads a source (sources.load) before the analysis
    "companion.gap.from_log": ADAPTER,  # loads a log (sources.load) and a model file before the gap workflow
    "companion.sources": ADAPTER,
    "companion.config": ADAPTER,  # the configuration schema and its YAML loader
    "companion.mavlink": ADAPTER,
    "companion.plots": ADAPTER,
    "companion.webview": ADAPTER,  # HTML reports and the live page's server (data in, pages out)
    "companion.sim.model": ADAPTER,  # model YAML
    "companion.sim.preset": ADAPTER,  # preset YAML
    "companion.datasheets": ADAPTER,  # the datasheet YAML (companion/datasheets.yaml)
    "companion.sim.dataflash_writer": ADAPTER,
    "companion.sim.ulog_writer": ADAPTER,
    "companion.service": SERVICE,
    "companion.fleet": SERVICE,
    "companion.cli": CLI,
    "companion.__main__": CLI,
}
CORE_THIRD_PARTY = {"numpy", "scipy"}


def layer_of(module: str, layers=LAYERS) -> int:
    parts = module.split(".")
    for k in range(len(parts), 0, -1):
        prefix = ".".join(parts[:k])
        if prefix in layers:
            return layers[prefix]
    raise KeyError(module)


def module_name(path: Path, root: Path) -> str:
    rel = path.relative_to(root).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path, module: str) -> list[tuple[int, str]]:
    """(line, imported module) of every import statement, relative imports resolved."""
    tree = ast.parse(path.read_text(), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            if node.module is None or name in ("companion",):  # from companion import units: the submodules
                out += [(node.lineno, f"{name}.{a.name}") for a in node.names]
            else:
                out.append((node.lineno, name))
    return out


def violations(root: Path, package: str = "companion", layers=LAYERS) -> list[str]:
    """Imports that run up the layers, and third-party imports of the core other than numpy/scipy."""
    stdlib = set(sys.stdlib_module_names)
    bad = []
    for path in sorted((root / package).rglob("*.py")):
        mod = module_name(path, root)
        own = layer_of(mod, layers)
        for line, name in imports_of(path, mod):
            top = name.split(".")[0]
            where = f"{path.relative_to(root)}:{line}"
            if top == package:
                try:
                    other = layer_of(name, layers)
                except KeyError:
                    continue
                if other > own:
                    bad.append(f"{where}: {mod} ({LAYER_NAMES[own]}) imports {name} ({LAYER_NAMES[other]})")
            elif own == CORE and top not in stdlib and top not in CORE_THIRD_PARTY and top != "__future__":
                bad.append(f"{where}: {mod} (core) imports {name} (only numpy, scipy and the standard library)")
    return bad


def test_no_import_runs_up_the_layers():
    assert violations(ROOT) == []


def test_every_module_has_a_layer():
    for path in (ROOT / "companion").rglob("*.py"):
        layer_of(module_name(path, ROOT))  # KeyError: a new top-level package needs a row in LAYERS


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        p = tmp_path / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return tmp_path


@pytest.mark.parametrize("bad, expect", [
    ("from companion.cli.main import main\n", "imports companion.cli.main (cli)"),
    ("def f():\n    from companion.service import run_session\n", "imports companion.service (service/fleet)"),
    ("from ..sources import load\n", "imports companion.sources (adapter)"),
    ("import companion.mavlink.link\n", "imports companion.mavlink.link (adapter)"),
    ("import yaml\n", "imports yaml (only numpy, scipy"),
    ("from companion import cli\n", "imports companion.cli (cli)"),
])
def test_a_bad_import_is_found(tmp_path, bad, expect):
    """A synthetic tree: the checker fails on each kind of wrong import in a core module, and names it."""
    root = _tree(tmp_path, {
        "companion/__init__.py": "",
        "companion/allan/__init__.py": "",
        "companion/allan/good.py": "import math\nimport numpy as np\nfrom scipy import stats\nfrom companion.units import x\n",
        "companion/allan/bad.py": bad,
        "companion/sources/__init__.py": "from companion.allan.good import x\n",
        "companion/cli/main.py": "from companion.service.run_session import x\nfrom companion.sources import load\n",
    })
    found = violations(root)
    assert len(found) == 1 and "companion/allan/bad.py:" in found[0] and expect in found[0], found


def test_a_clean_synthetic_tree_passes(tmp_path):
    root = _tree(tmp_path, {
        "companion/__init__.py": "",
        "companion/allan/x.py": "import numpy\nfrom . import y\n",
        "companion/sources/x.py": "import pymavlink\nfrom companion.allan import x\n",
        "companion/service/x.py": "from companion.sources import x\n",
        "companion/cli/x.py": "from companion.service import x\n",
    })
    assert violations(root) == []
