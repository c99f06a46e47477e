"""The pure parts of an alarm's evidence: decimation that keeps a spike, the two-sided PSD level of white
noise, a sentence and a statistic name for every fault kind."""

from __future__ import annotations

import math

import numpy as np

from companion.health.evidence_data import ALARM_BAR, STAT_NAMES, minmax_buckets, psd_two_sided, sentence
from companion.health.faults import KIND_CODE


def test_minmax_buckets_keep_a_single_sample_spike_and_bound_the_points():
    rng = np.random.default_rng(1)
    t = np.arange(0, 120, 0.01)
    y = rng.normal(0, 1e-3, (t.size, 3))
    y[5432, 1] = 0.3  # one sample of a 0.3 rad/s spike among 12000
    k, lo, hi = minmax_buckets(t, y, 0.5)
    assert k.size == 240 and np.all(np.diff(k) == 1)
    assert hi[:, 1].max() == 0.3 and int(k[np.argmax(hi[:, 1])]) == int(t[5432] // 0.5)
    assert np.all(lo <= hi)
    # an already bucketed series merged where two blocks share a bucket: the same result as in one go
    k1, lo1, hi1 = minmax_buckets(t[:4321], y[:4321], 0.5)
    k2, lo2, hi2 = minmax_buckets(t[4321:], y[4321:], 0.5)
    km, lom, him = minmax_buckets((np.r_[k1, k2] + 0.5) * 0.5, np.r_[lo1, lo2], 0.5, np.r_[hi1, hi2])
    assert np.array_equal(km, k) and np.array_equal(lom, lo) and np.array_equal(him, hi)


def test_two_sided_psd_of_white_noise_is_its_variance_over_the_rate():
    """IEEE 952's two-sided PSD of white noise of variance s^2 sampled at fs: s^2 / fs at every frequency
    (N^2 = s^2 / fs). Over 20 seeds the mean level is within 3 % of it."""
    fs, s = 200.0, 2e-3
    levels = []
    for seed in range(20):
        y = np.random.default_rng(seed).normal(0, s, (1600, 3))
        f, p = psd_two_sided(y, fs)
        assert f[0] == 0 and math.isclose(f[-1], fs / 2)
        levels.append(np.mean(p[1:-1]))
    assert abs(np.mean(levels) / (s * s / fs) - 1) < 0.03


def test_every_fault_kind_has_words_and_a_statistic():
    for kind in KIND_CODE:
        if kind == "none":
            continue
        assert kind in STAT_NAMES
        text = sentence(kind, 1, "gy", 2.5, "IMU0", ALARM_BAR.get(kind, 1.3))
        assert text.startswith("IMU1 gyro axis Y:") and len(text) > 40 and "nan" not in text, (kind, text)
