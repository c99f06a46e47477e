"""Reference outputs of the shipped sample log (tests/golden/, as allantools and pyulog keep theirs): the JSON
of `inspect`, `analyze` and `gap` on tlogs/sample.tlog must stay what it is. Strings, keys, booleans and
counts exactly; floating-point numbers within a relative 1e-9 (a platform's last-bit differences in BLAS or
libm do not fail, a changed result does).

Regenerate after an intended change of the output, and say why in the commit:

    COMPANION_REGEN_GOLDEN=1 python -m pytest -q -n 0 tests/cli/test_golden.py
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest

from companion.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
GOLDEN = ROOT / "tests" / "golden"
REL = 1e-9  #: relative tolerance of a float: last-bit differences between platforms, no real change
ABS = 1e-300  #: an exact zero against a denormal
REGEN = os.environ.get("COMPANION_REGEN_GOLDEN") == "1"

#: golden file -> command line (paths relative to the repository root, as they appear in the JSON)
COMMANDS = {
    "inspect_sample.json": ["inspect", "tlogs/sample.tlog", "--json", "{out}"],
    "analyze_sample.json": ["analyze", "tlogs/sample.tlog", "--quiet", "--json", "{out}"],
    "gap_sample.json": ["gap", "tlogs/sample.tlog", "--model", "companion/examples/sample_model.yaml", "--json", "{out}"],
}


def differences(new, old, where="$"):
    """Where ``new`` differs from ``old``: paths into the JSON with both values; floats within REL."""
    if isinstance(old, dict) and isinstance(new, dict):
        if set(new) != set(old):
            return [(where, sorted(set(new) ^ set(old)))]
        return [d for k in old for d in differences(new[k], old[k], f"{where}.{k}")]
    if isinstance(old, list) and isinstance(new, list):
        if len(new) != len(old):
            return [(where, f"length {len(new)} != {len(old)}")]
        return [d for i, (a, b) in enumerate(zip(new, old)) for d in differences(a, b, f"{where}[{i}]")]
    if isinstance(old, float) and isinstance(new, (int, float)) and not isinstance(new, bool):
        if math.isclose(new, old, rel_tol=REL, abs_tol=ABS) or (math.isnan(new) and math.isnan(old)):
            return []
        return [(where, new, old)]
    if type(new) is not type(old) or new != old:
        return [(where, new, old)]
    return []


def test_differences_sees_a_change_beyond_the_tolerance():
    assert differences({"a": [1.0, "x"]}, {"a": [1.0 + 1e-12, "x"]}) == []
    assert differences({"a": [1.0 + 1e-6]}, {"a": [1.0]})
    assert differences({"a": 1}, {"a": 2}) and differences({"a": True}, {"a": 1})
    assert differences({"a": 1}, {"b": 1}) and differences([1.0], [1.0, 2.0])


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_output_equals_its_golden_file(name, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    out = tmp_path / name
    assert main([a.format(out=out) for a in COMMANDS[name]]) == 0
    new = json.loads(out.read_text())
    golden = GOLDEN / name
    if REGEN:
        golden.write_text(json.dumps(new, indent=1, sort_keys=True) + "\n")
    assert golden.exists(), f"{golden} missing: regenerate (see this module's docstring)"
    diff = differences(new, json.loads(golden.read_text()))
    assert not diff, diff[:20]
