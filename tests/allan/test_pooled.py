"""Pooled overlapping AVAR over still segments: equals the plain estimator for one segment, never mixes
segments, and its model EDF matches a Monte Carlo of the estimator."""

from __future__ import annotations

import numpy as np
import pytest

from companion.allan.adev import oavar
from companion.allan.pooled import pooled_edf, pooled_oavar


def test_one_segment_is_the_overlapping_avar():
    y = np.random.default_rng(0).normal(0, 1e-2, 50_000)
    tau, a, m, _ = oavar(y, 100.0)
    tp, ap, mp, counts = pooled_oavar([y], 100.0)
    np.testing.assert_array_equal(m, mp)
    np.testing.assert_allclose(ap, a, rtol=1e-12)
    assert counts[0] == y.shape[0] - 1


def test_segments_are_never_joined():
    rng = np.random.default_rng(1)
    a_, b_ = rng.normal(0, 1e-3, 20_000), rng.normal(0, 1e-3, 5_000) + 0.5  # a bias jump between segments
    tau, av, m, counts = pooled_oavar([a_, b_], 100.0)
    # by hand: sums of squared second differences of each segment's phase, divided by the pooled count
    for j, mj in enumerate(m):
        tot, cnt = 0.0, 0
        for y in (a_, b_):
            x = np.r_[0, np.cumsum(y - y.mean())] / 100.0
            if x.shape[0] - 2 * mj < 1:
                continue
            d = x[2 * mj:] - 2 * x[mj:-mj] + x[:-2 * mj]
            tot += float(d @ d)
            cnt += d.shape[0]
        assert counts[j] == cnt
        assert av[j] == pytest.approx(tot / (2 * tau[j] ** 2 * cnt), rel=1e-10)
    assert m.max() == 8192  # octaves up to half the longest segment (10,000)
    assert np.all(av * tau < 2e-6 * 1.5)  # the 0.5 rad/s jump between segments does not appear


def test_pooled_edf_matches_monte_carlo():
    N, fs, lengths = 1e-3, 100.0, [3000, 1200, 500]
    terms = [{"effect": "white_noise", "N": N}]
    m = np.array([1, 8, 64, 256])
    edf = pooled_edf(terms, m, lengths, fs)
    rng = np.random.default_rng(2)
    est = []
    for _ in range(400):
        segs = [rng.normal(0, N * np.sqrt(fs), n) for n in lengths]
        est.append(pooled_oavar(segs, fs, m=m)[1])
    est = np.array(est)
    mc = 2 * est.mean(axis=0) ** 2 / est.var(axis=0, ddof=1)
    np.testing.assert_allclose(edf, mc, rtol=0.25)


def test_blocked_differences_equal_the_plain_expression(monkeypatch):
    """The second differences are formed a block at a time (cache-sized) and summed by one dot product: bit for
    bit the plain sum of (x[2m:] - 2 x[m:-m] + x[:-2m])^2, with blocks that do not divide the count."""
    from companion.allan import pooled
    from companion.allan.adev import phase_from_rate

    monkeypatch.setattr(pooled, "DIFF_BLOCK", 1000)
    y = np.random.default_rng(3).normal(0, 1e-2, 12_345)
    m = np.array([1, 3, 64, 1000, 3000])
    tau, a, m_out, counts = pooled_oavar([y], 100.0, m=m)
    x = phase_from_rate(y, 100.0)
    for k, mk in enumerate(m_out):
        d = x[2 * mk:] - 2.0 * x[mk:x.shape[0] - mk] + x[:x.shape[0] - 2 * mk]
        assert a[k] == float(np.dot(d, d)) / (2.0 * tau[k] ** 2 * counts[k])
