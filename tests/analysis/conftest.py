"""Fixtures of the analysis tests."""

from __future__ import annotations

import pytest

from tests.support.armed_flight import analyse_armed_flight


@pytest.fixture(scope="session")
def armed_flight(tmp_path_factory):
    """``armed_flight(seed, n_true, seconds, offsets)``: tests.support.armed_flight.analyse_armed_flight, made
    once per test process for each set of arguments (the result is shared: read it, never change it)."""
    made = {}

    def get(seed, n_true, seconds, offsets):
        key = (int(seed), tuple(float(n) for n in n_true), float(seconds), tuple(float(o) for o in offsets))
        if key not in made:
            made[key] = analyse_armed_flight(tmp_path_factory.mktemp("armed"), *key)
        return made[key]

    return get
