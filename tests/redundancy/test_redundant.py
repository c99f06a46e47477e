"""The in-flight noise per IMU from redundant IMUs (companion.redundancy) against known truth: simulated
flights with per-IMU white noise, mounting errors and time offsets, over seeds; tolerances from the EDF."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.redundancy import ImuTrack, fit_pair, hat_share, redundant_noise
from companion.redundancy.calibration import fractional_delay
from companion.redundancy.shape import avar_shape
from tests.redundancy.synthetic import RATE, flight

DEG = math.radians(1.0) / 60.0  # 1 deg/sqrt(h) in rad/s/sqrt(Hz)


def _n(entry):
    """(N, lo, hi, bound?) of an axes entry's white-noise term or bound."""
    for t in entry["terms"]:
        if t["effect"] == "white_noise":
            return t["N"], t["ci95"]["N"][0], t["ci95"]["N"][1], False
    for t in entry["bounds"]:
        if t["effect"] == "white_noise":
            return t["N"], 0.0, t["N"], True
    return None


def test_hat_share_is_exact_on_exact_curves():
    s = np.array([1.0, 4.0, 9.0])
    a01, a02, a12 = s[0] + s[1], s[0] + s[2], s[1] + s[2]
    share, edf, sd = hat_share(a01, a02, a12, 1000.0)
    assert share == pytest.approx(1.0)
    # EDF of the quietest of three: EDF s^2 / (s^2 + (s0 s1 + s0 s2 + s1 s2) / 2)
    assert edf == pytest.approx(1000.0 / (1.0 + (4 + 9 + 36) / 2.0))
    assert sd == pytest.approx(math.sqrt(2.0 / 1000.0 * (1.0 + 24.5)))


def test_fractional_delay_moves_a_line_by_the_delay():
    t = np.arange(4000) / RATE
    x = np.sin(2 * np.pi * 37.0 * t)[:, None]
    y = fractional_delay(x, 0.3)[20:-20, 0]
    assert np.max(np.abs(y - np.sin(2 * np.pi * 37.0 * (t[20:-20] + 0.3 / RATE)))) < 1e-3


def test_shape_is_one_without_filter_effect_at_long_cluster_times():
    shp = avar_shape([20.0, 25.0], 400.0, np.array([1, 4, 64, 1024]))
    assert shp[0] < 0.1 and shp[-1] == pytest.approx(1.0, abs=0.01)
    assert np.all(np.diff(shp) > 0)


def test_pair_calibration_recovers_mounting_and_time_offset():
    t, g, c = flight(3, [1.0 * DEG, 1.0 * DEG], offsets=[0.0, 0.0015])
    cal, res = fit_pair([g[0]], [g[1]], RATE)
    assert cal.fitted_matrix
    assert np.median(cal.dt_s) == pytest.approx(0.0015, abs=1e-4)
    assert np.max(np.abs(cal.matrix - c[1] @ np.linalg.inv(c[0]))) < 2e-3


@pytest.mark.parametrize("seed", range(4))
def test_three_imus_each_n_within_its_interval(seed):
    """Per-IMU N 0.5-3 deg/sqrt(h) drawn per seed: the estimate's 95 % interval holds the truth (a miss is
    allowed on 1 of the 9 axes: 95 % intervals), and every estimate lies within 5 of its standard deviations."""
    rng = np.random.default_rng(100 + seed)
    n_true = rng.uniform(0.5, 3.0, 3) * DEG
    t, g, _ = flight(seed, n_true, offsets=[0.0, 0.001, 0.002])
    res = redundant_noise([ImuTrack(t, g[i], RATE) for i in range(3)], [(t[0], t[-1])])
    misses = 0
    for i, p in enumerate(res.per_imu):
        assert p["method"].startswith("three-cornered hat")
        for e in p["axes"].values():
            v = _n(e)
            assert v is not None and not v[3]
            sd = (v[2] - v[1]) / 3.92
            assert abs(v[0] - n_true[i]) < 5 * sd
            misses += not (v[1] <= n_true[i] <= v[2])
    assert misses <= 1


@pytest.mark.parametrize("seed", range(3))
def test_two_imus_pair_figure_bounds_and_split(seed):
    """Two IMUs: the pair figure estimates sqrt(N_a^2 + N_b^2) within its interval, each IMU's bound holds,
    and with the still ratio given each IMU's split N is within 5 sd of its truth."""
    rng = np.random.default_rng(200 + seed)
    n_true = rng.uniform(0.5, 3.0, 2) * DEG
    t, g, _ = flight(seed, n_true, offsets=[0.0, 0.002])
    tracks = [ImuTrack(t, g[i], RATE) for i in range(2)]
    res = redundant_noise(tracks, [(t[0], t[-1])])
    truth = math.hypot(*n_true)
    for e in res.pairs[0]["axes"].values():
        v = _n(e)
        assert v[1] <= truth * 1.02 and v[2] >= truth * 0.98
    for i, p in enumerate(res.per_imu):
        assert "at most the pair" in p["method"]
        for e in p["axes"].values():
            assert _n(e)[3] and _n(e)[0] >= n_true[i]
    still = [{ax: float(n_true[i]) for ax in ("gx", "gy", "gz")} for i in range(2)]
    split = redundant_noise(tracks, [(t[0], t[-1])], still_n=still)
    for i, p in enumerate(split.per_imu):
        assert "still ratio" in p["method"]
        for e in p["axes"].values():
            v = _n(e)
            assert not v[3] and abs(v[0] - n_true[i]) < 5 * (v[2] - v[1]) / 3.92


def test_one_imu_says_what_would_help():
    t, g, _ = flight(0, [1.0 * DEG])
    res = redundant_noise([ImuTrack(t, g[0], RATE)], [(t[0], t[-1])])
    p = res.per_imu[0]
    assert p["method"] == "none" and not p["axes"]
    assert "LOG_DISARMED" in p["notes"][0] and "second IMU" in p["notes"][0]
    assert "SDLOG_MODE" in p["notes"][0]  # the PX4 user's setting too (a one-IMU ULog gets this note)


def test_too_short_a_condition_gives_no_figure():
    t, g, _ = flight(0, [1.0 * DEG, 1.0 * DEG], seconds=20.0)
    res = redundant_noise([ImuTrack(t, g[i], RATE) for i in range(2)], [(t[0], t[-1])])
    assert all(p["method"] == "none" and "no figure" in p["notes"][0] for p in res.per_imu)


def test_two_copies_of_one_imu_give_no_figure():
    """The same IMU logged twice (a combined and a per-IMU topic) would claim a noise of 0: refused, said so."""
    t, g, _ = flight(0, [1.0 * DEG])
    res = redundant_noise([ImuTrack(t, g[0], RATE, label="a"), ImuTrack(t, g[0] * 1.0001, RATE, label="b")],
                          [(t[0], t[-1])])
    assert all(p["method"] == "none" and "copies of one IMU" in p["notes"][0] for p in res.per_imu)
