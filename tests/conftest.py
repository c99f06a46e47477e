"""Shared fixtures. Tests that need the real recordings in ../shared skip cleanly when it is absent.

The layout mirrors companion/ (tests/<package>/test_<module or behaviour>.py, each folder a package so that
``from tests.support...`` imports under plain ``pytest`` too); loopback/ holds the multi-process tests over
UDP. Tests marked ``soak`` (long soaks and seed scans) run from benchmarks/soak_checks.py, not from the
README's command; reference outputs are in tests/golden/ (tests/cli/test_golden.py)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import companion  # noqa: F401  (first: it sets one BLAS thread per process before numpy loads)

ROOT = Path(__file__).resolve().parent.parent
SHARED = Path(os.environ.get("COMPANION_SHARED", ROOT.parent / "shared"))


@pytest.fixture
def shared_data() -> Path:
    """Path to ../shared/data; skips the test when it does not exist (a user's fresh clone)."""
    data = SHARED / "data"
    if not data.is_dir():
        pytest.skip("../shared/data not present")
    return data


@pytest.fixture
def repo_root() -> Path:
    return ROOT


@pytest.hookimpl(optionalhook=True)  # an xdist hook: without xdist (``-p no:xdist``) pytest must not reject it
def pytest_xdist_auto_num_workers(config):
    """``-n auto``: one worker more than the cores. The loopback tests spend part of their time waiting on the
    processes they start (a worker then idles); the extra worker fills those gaps (on 2 cores, idle: 389 s
    against 433 s with two workers). PYTEST_XDIST_AUTO_NUM_WORKERS still sets the number."""
    env = os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS")
    if env:
        return int(env)
    return (os.cpu_count() or 1) + 1


def pytest_configure(config):
    """Byte-compile the package once before the workers start. Where PYTHONDONTWRITEBYTECODE is set (some CI
    images), no process writes ``__pycache__``, so every ``python -m companion`` the tests start (well over a
    hundred) compiled the modules it imports again: 0.1-0.2 s of CPU each. Nothing is written where the tree
    is read-only."""
    if hasattr(config, "workerinput") or not os.environ.get("PYTHONDONTWRITEBYTECODE"):
        return
    import compileall

    try:
        compileall.compile_dir(str(ROOT / "companion"), quiet=2, workers=1)
    except OSError:
        pass
