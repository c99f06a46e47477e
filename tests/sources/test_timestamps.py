"""Timing rules: rate, gaps, duplicates, backward steps, resets, millisecond stamps, through load() too."""

from __future__ import annotations

import numpy as np
import pytest

from companion.mavlink.tlog_writer import write_imu_tlog
from companion.sources import load
from companion.sources.timestamps import analyse


def test_clean_stream():
    t = 5.0 + np.arange(1000) / 200.0
    keep, seg, rep = analyse(t, 1e-6)
    assert keep.all() and seg == [(0, 1000)]
    assert rep.rate_hz == pytest.approx(200.0) and rep.gaps == 0 and rep.resets == 0
    assert rep.duration_s == pytest.approx(999 / 200.0)


def test_gap_duplicate_backwards_reset():
    base = np.arange(400) / 100.0  # 100 Hz
    t = list(base[:100])
    t += list(base[103:200])  # 3 samples missing: one gap, short (counted, not split)
    t += [t[-1]]  # duplicate
    t += [t[-1] - 0.015]  # small step back
    t += list(base[200:300] + 2.0)  # 2 s hole: a gap that splits
    t += list(np.arange(50) / 100.0)  # reboot: time starts again near 0
    t = np.array(t)
    keep, seg, rep = analyse(t, 1e-6)
    assert rep.duplicates == 1 and rep.backwards == 1 and rep.resets == 1
    assert rep.gaps == 2
    assert keep.sum() == len(t) - 2
    assert seg == [(0, 197), (197, 297), (297, 347)]
    assert rep.rate_hz == pytest.approx(100.0)
    tk = t[keep]
    assert all(np.all(np.diff(tk[a:b]) > 0) for a, b in seg)


def test_millisecond_stamps_at_400hz_are_not_gaps():
    rng = np.random.default_rng(2)
    n = 4000
    t_true = 1.0 + np.arange(n) / 400.0 + rng.uniform(-2e-4, 2e-4, n)
    t_ms = np.round(t_true * 1e3) / 1e3  # time_boot_ms: intervals of 2 and 3 ms
    assert set(np.round(np.diff(t_ms) * 1e3).astype(int)) <= {2, 3}
    keep, seg, rep = analyse(t_ms, 1e-3)
    assert rep.gaps == 0 and keep.all() and seg == [(0, n)]
    assert rep.rate_hz == pytest.approx(400.0, rel=2e-3)
    # two dropped samples (7.5 ms) are a gap; one (5 ms, stamped 4-6 ms) is only provably one when
    # its interval exceeds 1.5 P + 1 ms = 4.75 ms
    t2 = np.delete(t_ms, [2000, 2001])
    assert analyse(t2, 1e-3)[2].gaps == 1
    t3 = np.delete(t_ms, [1000])
    assert analyse(t3, 1e-3)[2].gaps == int(round((t_ms[1001] - t_ms[999]) * 1e3) > 4.75)


@pytest.mark.parametrize("message", ["RAW_IMU", "SCALED_IMU2"])
def test_reboot_and_gap_in_a_tlog(tmp_path, message):
    rate = 50.0
    t = np.r_[np.arange(500) / rate + 100.0, np.arange(300) / rate + 0.5]  # reboot after 10 s
    t = np.delete(t, 250)  # one missing sample
    n = t.shape[0]
    path = tmp_path / "r.tlog"
    write_imu_tlog(path, t, np.full((n, 3), 0.004), np.full((n, 3), 0.5), message=message)
    s = load(path).streams[0]
    assert s.timing.resets == 1 and s.timing.gaps == 1
    assert s.segments == [(0, 499), (499, 799)]
    assert s.timing.rate_hz == pytest.approx(rate, rel=1e-6)
    assert s.samples == 799


def test_period_of_ms_stamped_streams_and_lost_samples():
    from companion.sources.timestamps import period_of

    for rate in (400.0, 300.0, 250.0, 150.0, 100.0):
        t = np.floor((5.0 + np.arange(4000) / rate) * 1e3) / 1e3
        assert 1.0 / period_of(np.diff(t), 1e-3) == pytest.approx(rate, rel=2e-3)
        keep = np.random.default_rng(0).random(t.size) > 0.2  # 20 % lost: intervals of 2, 3 periods left out
        assert 1.0 / period_of(np.diff(t[keep]), 1e-3) == pytest.approx(rate, rel=0.01)
    assert np.isnan(period_of([], 1e-3))


def test_period_of_late_messages_split_a_period_without_biasing_it():
    """A telemetry stream at 2 Hz whose late messages split one period into 0.12 + 0.88 s or 0.22 + 0.78 s
    (the shared ArduSub tlog): the short part alone was kept and took the rate 3 % high on 64 intervals."""
    from companion.sources.timestamps import period_of

    rng = np.random.default_rng(3)
    for seed in range(20):
        t = 10.0 + np.arange(400) * 0.5 + rng.normal(0, 2e-4, 400)
        late = rng.choice(np.arange(5, 395), 6, replace=False)
        t[late] += rng.uniform(0.25, 0.4, late.size)  # a message held back by a quarter to 0.4 s
        d = np.diff(t)
        assert 1.0 / period_of(d[:64]) == pytest.approx(2.0, rel=2e-3)
        assert 1.0 / period_of(d) == pytest.approx(2.0, rel=1e-3)


def _messy(rng, n, period, res):
    """Timestamps with duplicates, small steps back, gaps, long gaps and a reboot, stamped at ``res``."""
    t = 5.0 + np.arange(n) * period + rng.normal(0, 0.05 * period, n)
    t[n // 3:] += 0.7  # a gap long enough to split
    for i in rng.choice(np.arange(1, n), 12, replace=False):
        t[i] = t[i - 1]  # duplicates
    for i in rng.choice(np.arange(2, n), 6, replace=False):
        t[i] = t[i - 1] - 0.3 * period  # small steps back
    gaps = rng.choice(np.arange(1, n), 5, replace=False)
    for i in gaps:
        t[i:] += 2.2 * period  # short gaps
    t[2 * n // 3:] -= t[2 * n // 3] - 0.5  # reboot: time starts again near 0
    return np.round(t / res) * res if res else t


@pytest.mark.parametrize("seed", range(8))
def test_classify_steps_counts_equal_analyse(seed):
    """The vectorised step rules (what a live block cutter calls, block by block or one sample at a time)
    count what the offline analysis counts, and keep the same samples."""
    from companion.sources.timestamps import (BACKWARD, DUPLICATE, GAP, RESET, SPLIT, analyse, classify_steps,
                                          step_rules)

    rng = np.random.default_rng(seed)
    res = 1e-3 if seed % 2 else 0.0
    period = 1 / 400.0 if seed % 2 else 0.01
    t = _messy(rng, 3000, period, res)
    keep, segments, rep = analyse(t, res, rate_hz=1 / period)
    rules = step_rules(period, res)
    kind = classify_steps(t, None, rules)
    assert int((kind == DUPLICATE).sum()) == rep.duplicates
    assert int((kind == BACKWARD).sum()) == rep.backwards
    assert int((kind == RESET).sum()) == rep.resets >= 1
    assert int(((kind == GAP) | (kind == SPLIT)).sum()) == rep.gaps >= 5
    assert 1 + int(((kind == RESET) | (kind == SPLIT)).sum()) == len(segments) >= 3
    assert np.array_equal(keep, (kind != DUPLICATE) & (kind != BACKWARD))
    # in pieces, carrying the newest kept timestamp: the same kinds (a one-sample call is a one-row block)
    parts, newest = [], None
    for a, b in ((0, 1), (1, 700), (700, 701), (701, 3000)):
        parts.append(classify_steps(t[a:b], newest, rules))
        k = np.concatenate(parts)
        resets = np.flatnonzero(k == RESET)
        lo = int(resets[-1]) if resets.shape[0] else 0  # the newest kept timestamp since the last reset
        newest = float(t[lo:b][((k != DUPLICATE) & (k != BACKWARD))[lo:b]].max())
    assert np.array_equal(np.concatenate(parts), kind)
