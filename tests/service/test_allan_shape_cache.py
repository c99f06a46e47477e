"""The filters' Allan shape of the flight figures: computed once per (filters, rate, cluster sizes)."""

from __future__ import annotations

import numpy as np

from companion.service import inflight_alarm
from companion.service.inflight_alarm import allan_shape


def test_the_shape_is_remembered_and_unchanged_by_a_caller():
    grid = np.arange(1, 257)
    first = allan_shape([20.0, 20.0, 20.0], 50.0, grid)
    # the white-noise limit: no filter, shape 1; a 20 Hz cut-off at 50 Hz lowers the shortest cluster sizes
    assert np.allclose(allan_shape([], 50.0, grid[:4]), 1.0)
    assert first[0] < 0.9 and abs(first[-1] - 1.0) < 0.02
    first[:] = -1.0  # a caller's change must not reach the remembered array
    hits = inflight_alarm._allan_shape.cache_info().hits
    again = allan_shape((20.0, 20.0, 20.0), 50, list(grid))
    assert inflight_alarm._allan_shape.cache_info().hits == hits + 1
    assert again[0] > 0 and np.all(np.isfinite(again))
