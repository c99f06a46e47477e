"""The Allan N check on a rounded gyro quieter than one LSB (ArduPilot SITL over RAW_IMU: 0.2 LSB): a bias
drifting across the code grid changes the rounded output's N by up to the rounding's ceiling with no change
of the gyro; that is not a degradation. A noise rise beyond what rounding can give is still named."""

from __future__ import annotations

import numpy as np
import pytest

from companion.health.baseline import rounding_ceiling
from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline, PipelineConfig
from tests.support.sinks import RecordingSink

LSB = 1e-3
RATE = 100.0


def replay(seed, noise_lsb, drift_lsb_per_s, factor_at=None, factor=1.0, duration=200.0):
    rng = np.random.default_rng(seed)
    n = int(duration * RATE)
    t = 1.0 + np.arange(n) / RATE
    sigma = np.full(n, noise_lsb * LSB)
    if factor_at is not None:
        sigma[t >= factor_at] *= factor
    bias = (0.1 + drift_lsb_per_s * (t - t[0])) * LSB  # from a code's centre towards and across a boundary
    g = np.round((bias[:, None] + rng.normal(0.0, 1.0, (n, 3)) * sigma[:, None]) / LSB) * LSB
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (n, 3))
    sink = RecordingSink()
    p = Pipeline(PipelineConfig(baseline_s=60.0), Reporter(sink, 1.0))
    p.on_samples(StreamKey(1, 1, "RAW_IMU", 0), t, g, a)
    return [text for _, text in p.transitions]


def test_ceiling_raises_only_a_sub_lsb_baseline():
    base = {"N": (2.14e-5, 1e-6), "B": (1e-5, 1e-6)}
    up = rounding_ceiling(base, 100.0, LSB)  # 0.21 LSB per sample
    assert 2.2 < up["N"][0] / base["N"][0] < 2.5 and up["B"] == base["B"]
    assert rounding_ceiling(base, 100.0, None) is base  # float data
    loud = {"N": (1e-4, 1e-6)}  # 1 LSB per sample: the offset no longer matters
    assert rounding_ceiling(loud, 100.0, LSB) is loud


@pytest.mark.soak
def test_drift_across_the_code_grid_is_not_n_degradation_but_a_noise_rise_is_named():
    for seed in range(2):  # 0.1 LSB, the bias crossing the code boundary at 0.5 LSB at 80 s (before: N 1.4-1.9x)
        texts = replay(seed, 0.1, 0.005)
        assert not [x for x in texts if "degrading" in x or "noise" in x], texts
    texts = replay(7, 0.3, 0.0, factor_at=120.0, factor=4.0)  # 0.3 -> 1.2 LSB: beyond what rounding can do
    assert [x for x in texts if "degrading: N" in x], texts
    assert [x for x in texts if " noise " in x], texts
