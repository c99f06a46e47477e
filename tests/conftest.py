"""Shared fixtures. Tests that need the real recordings in ../shared skip cleanly when it is absent."""

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
