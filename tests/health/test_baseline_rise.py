"""The Allan check compares a coefficient's rise only where the measured Allan curve rose with it
(health.baseline.risen_params): independent truth from known models with chi-square distributed levels,
scipy's F distribution for the rise test, and the baseline's persistence."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from companion.allan.terms import avar_model
from companion.health.baseline import Baseline, rise_z, risen_params

TAU = 0.02 * 2.0 ** np.arange(15)  # a 50 Hz octave bank up to 328 s
N, B, K = 7.5e-5, 1.1e-4, 2.0e-5  # the copter preset's gyro (rad/s/sqrt(Hz), rad/s, rad/s^1.5)


def _edf(record_s):
    # overlapping Allan variance of a random-walk-like term: EDF ~ 3 T / (2 tau) at long tau, at least 1
    return np.maximum(1.5 * record_s / TAU - 1.0, 1.0)


def _levels(rng, k, record_s):
    terms = [{"effect": "white_noise", "N": N}, {"effect": "bias_instability", "B": B},
             {"effect": "random_walk", "K": k}]
    a = avar_model(terms, TAU)
    edf = _edf(record_s)
    use = 2.0 * TAU <= record_s
    return TAU[use], (a * rng.chisquare(edf) / edf)[use], edf[use]


@pytest.mark.parametrize("nu1,nu2", [(10, 10), (10, 100), (100, 1000), (30, 5)])
def test_rise_z_at_the_f_quantile_is_three_or_less(nu1, nu2):
    f3 = stats.f.ppf(stats.norm.cdf(3.0), nu1, nu2)
    z = float(rise_z(f3, nu1, nu2))
    assert 2.7 < z <= 3.02
    # and a ratio of 1 is no rise at all
    assert float(rise_z(1.0, nu1, nu2)) < 0.5


def test_a_projected_k_rise_on_an_unchanged_curve_is_not_compared_a_real_one_is():
    """The same gyro (K 2e-5) at the baseline (600 s) and now (1000 s): a selection that projects the curve
    as K 3x (the copter hour's 5.7e-5 against 1.9e-5) claims a rise the levels do not show and is left out:
    each of the ~6 levels where the claim matters passes by chance with p = 0.13 % (z = 3, one-sided), so
    about 1 % of draws keep it (1-4 of 200 over seeds 1-7); at most 8 (binomial 99.9 % point at p = 1.5 %).
    When the gyro's K really is 6x, the levels show it (200 of 200 over those seeds; at least 190)."""
    rng = np.random.default_rng(7)
    base = {"K": (K, 0.3 * K), "N": (N, 0.01 * N), "B": (B, 0.1 * B)}
    claim = {"K": (3.0 * K, 0.1 * K)}
    kept_null = kept_real = 0
    for _ in range(200):
        lb = _levels(rng, K, 600.0)
        kept_null += "K" in risen_params(claim, base, _levels(rng, K, 1000.0), lb)
        kept_real += "K" in risen_params({"K": (6.0 * K, K)}, base, _levels(rng, 6.0 * K, 1000.0), lb)
    assert kept_null <= 8
    assert kept_real >= 190


def test_without_the_baseline_levels_nothing_is_left_out_and_a_fall_is_always_kept():
    rng = np.random.default_rng(1)
    lv = _levels(rng, K, 600.0)
    claim = {"K": (3.0 * K, 0.1 * K), "N": (0.5 * N, 0.01 * N)}
    assert risen_params(claim, {"K": (K, 0.3 * K), "N": (N, 0.01 * N)}, lv, None) == claim
    assert "N" in risen_params(claim, {"K": (K, 0.3 * K), "N": (N, 0.01 * N)}, lv, lv)


def test_the_baseline_levels_survive_its_file():
    b = Baseline("learned")
    b.set_axis(0, "gy", {"K": (K, 0.3 * K)})
    b.set_levels(0, "gy", TAU[:4], np.arange(1.0, 5.0), np.full(4, 9.0))
    c = Baseline.from_dict(b.to_dict())
    tau, avar, edf = c.get_levels(0, "gy")
    assert np.array_equal(tau, TAU[:4]) and np.array_equal(avar, np.arange(1.0, 5.0)) and np.all(edf == 9.0)
    d = b.to_dict()
    d["levels"]["IMU0"]["gy"]["avar"] = "damaged"
    assert Baseline.from_dict(d).get_levels(0, "gy") is None
