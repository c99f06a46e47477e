"""Whole-log gyro faults (companion.health.log_faults): known faults written into simulated gyro records are
found where they were put, and healthy records over many seeds (float noise, int16 rounding at rest, motion up
to near the range) give none."""

import numpy as np
import pytest

from companion.health.log_faults import gyro_faults, saturated_axis, stuck_axis

RATE = 100.0


def healthy(seed, n=30_000, sigma=2e-3, motion=0.0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    g = rng.normal(0.0, sigma, (n, 3))
    if motion:
        g += motion * np.sin(2 * np.pi * 0.3 * t)[:, None] * rng.uniform(0.5, 1.0, 3)
    return t, g


@pytest.mark.parametrize("motion", [0.0, 5.0])
def test_healthy_float_records_have_no_fault(motion):
    for seed in range(30):
        t, g = healthy(seed, motion=motion)
        assert gyro_faults(g, RATE, t) == [], seed


def test_int16_gyro_quieter_than_its_step_is_not_called_stuck():
    # 0.3 LSB of noise at rest, then a minute of motion: long runs of one code at rest are a quiet gyro
    for seed in range(10):
        t, g = healthy(seed, sigma=0.3e-3)
        g[20_000:26_000] += 0.5 * np.sin(2 * np.pi * 0.5 * t[20_000:26_000])[:, None]
        q = np.round(g * 1000) / 1000
        assert [f.kind for f in gyro_faults(q, RATE, t, lsb=1e-3)] == [], seed


def test_frozen_stretch_is_found_where_it_was_put():
    for seed in range(10):
        t, g = healthy(seed)
        start = 4000 + 500 * seed
        g[start:start + 150, 2] = g[start, 2]  # 1.5 s frozen
        faults = gyro_faults(g, RATE, t)
        assert [(f.axis, f.kind) for f in faults] == [(2, "stuck")], seed
        assert stuck_axis(g[:, 2], RATE) == (start, 150)
        assert f"from {t[start]:.1f} s (1.5 s, 150 samples)" in faults[0].text
    # shorter than a second: no verdict
    t, g = healthy(0)
    g[4000:4080, 0] = g[4000, 0]
    assert gyro_faults(g, RATE, t) == []


def test_clipped_motion_is_saturated_and_unclipped_is_not():
    for seed in range(10):
        t, g = healthy(seed, motion=40.0)  # 20-40 rad/s peaks; clipped at 15 rad/s, below the range limit
        clipped = np.clip(g, -15.0, 15.0)
        faults = gyro_faults(clipped, RATE, t)
        assert [(f.axis, f.kind) for f in faults] == [(a, "saturated") for a in range(3)], seed
        assert all("in 180 flat runs" in f.text for f in faults), faults  # 300 s at 0.3 Hz: 90 cycles, 2 peaks each
        assert saturated_axis(g[:, 0] * 0.5) is None  # the same motion unclipped, within the range


def test_dead_axis_named_with_both_causes_on_an_integer_message():
    t, g = healthy(1)
    g[:, 1] = 0.0
    f = gyro_faults(g, RATE, t, lsb=1e-3, label="RAW_IMU[0]")
    assert [(x.axis, x.kind) for x in f] == [(1, "dead")]
    assert f[0].text.startswith("RAW_IMU[0]: gyro dead or below resolution: Y exactly 0 in all 30000 samples")


def test_a_sample_at_the_range_limit_is_saturated_as_run_says():
    """A crash's one sample beyond the range (a public log: 35.3 rad/s on gyro Y at 50 Hz) is what `run` calls
    saturated (its gyro_limit); the offline test takes the same limit."""
    from companion.health.log_faults import RANGE_LIMIT
    from companion.service.pipeline_config import PipelineConfig

    assert RANGE_LIMIT == PipelineConfig().gyro_limit
    t, g = healthy(2, motion=5.0)
    g[12_000, 1] = 35.3
    f = gyro_faults(g, RATE, t)
    assert [(x.axis, x.kind) for x in f] == [(1, "saturated")]
    assert "beyond the range limit 32.77 rad/s in 1 sample(s)" in f[0].text
    g[12_000, 1] = 30.0  # a fast turn within the range
    assert gyro_faults(g, RATE, t) == []
