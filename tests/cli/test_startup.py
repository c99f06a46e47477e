"""Start-up stays light: what the CLI imports before any work, and the numpy-only solvers of the live path.

Deterministic guards (module lists, not timings); the timings are in benchmarks/bench_startup.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("scipy", "matplotlib", "pymavlink", "dask", "pyulog")


def _modules_after(code: str) -> set[str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys, json\nprint(json.dumps(sorted(sys.modules)))"],
                         env=env, capture_output=True, text=True, timeout=300, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def _heavy(mods: set[str]) -> list[str]:
    return sorted(m for m in mods if m.split(".")[0] in HEAVY)


def test_cli_parser_imports_no_heavy_module():
    """`companion --help`/`--version` and argument parsing of every subcommand load no scipy, matplotlib,
    pymavlink (they cost seconds and tens of MB on a small board)."""
    mods = _modules_after("from companion.cli.main import build_parser\nbuild_parser()")
    assert _heavy(mods) == []


def test_live_run_path_loads_no_scipy():
    """Everything `companion run` needs on a live link up to its readiness line, and the pipeline fed with
    enough still data to fit and report, loads no scipy (the fit there is numpy-only)."""
    code = """
import numpy as np
from companion.cli import run
from companion.mavlink.link import Link
from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.state import save_state, load_state
class Sink:
    def send_named_value_float(self, *a): pass
    def send_statustext(self, *a, **kw): pass
p = Pipeline(PipelineConfig.from_mapping({"baseline_s": 60}), Reporter(Sink(), 1.0))
rng = np.random.default_rng(0)
key = StreamKey(1, 1, "RAW_IMU", 0)
for k in range(100 * 150):
    p.on_sample(key, 1.0 + k / 100.0, rng.normal(0, 0.03, 3), (0.0, 0.0, -9.80665))
assert p.channels[0].fed_s > 60 and p.summary()[0]["axes"]
"""
    mods = _modules_after(code)
    assert [m for m in _heavy(mods) if m.startswith("scipy")] == []


def test_numpy_nnls_matches_scipy():
    from scipy.optimize import nnls as scipy_nnls

    from companion.allan.lsq import nnls

    rng = np.random.default_rng(7)
    for t in range(2000):
        m, n = int(rng.integers(3, 25)), int(rng.integers(1, 9))
        A = rng.normal(size=(m, n)) * np.exp(3 * rng.normal(size=n))
        if t % 3 == 0:
            A = np.abs(A)  # the estimators' design matrices are non-negative
        if t % 7 == 0 and n > 1:
            A[:, -1] = 2 * A[:, 0]  # rank deficient
        b = 10 * rng.normal(size=m)
        x, r = nnls(A, b)
        xs, rs = scipy_nnls(A, b)
        assert np.all(x >= 0)
        assert r <= rs + 1e-8 * np.linalg.norm(b)
        assert r == pytest.approx(np.linalg.norm(A @ x - b))


def test_exp_sum_is_lfilter_bit_for_bit():
    from scipy.signal import lfilter

    from companion.allan.lsq import exp_sum

    rng = np.random.default_rng(3)
    for _ in range(200):
        x = rng.random(int(rng.integers(0, 2000))) * 10 ** rng.normal()
        lam, s0 = 1 - 10 ** rng.uniform(-7, -0.1), float(rng.random())
        ref = lfilter([1.0], [1.0, -lam], x, zi=[lam * s0])[0][-1] if x.size else s0
        assert exp_sum(x, lam, s0) == ref
