"""companion.health.evidence_rules: the floors and evidence rules, against simulated truth."""

import math

import numpy as np
import pytest

from companion.health.evidence_rules import (DEG, FaultLimits, allan_wander_var, capped, equal_codes_llr, floored_mean_llr,
                                     p_equal_codes, wander_var)


@pytest.mark.parametrize("sigma", [0.3, 0.7, 1.0, 2.0, 4.0])
def test_p_equal_codes_matches_simulated_rounding(sigma):
    rng = np.random.default_rng(int(sigma * 10))
    # a slowly moving true value spreads the offset within the LSB uniformly
    x = np.round(rng.normal(0.0, sigma, 400_000) + np.linspace(0.0, 37.3, 400_000))
    measured = float(np.mean(np.diff(x) == 0))
    assert p_equal_codes(sigma) == pytest.approx(measured, abs=0.01)


def test_healthy_quantised_gyro_gives_no_stuck_evidence_but_a_frozen_one_does():
    rng = np.random.default_rng(3)
    sigma = 0.7  # LSB: a healthy int16 mrad/s gyro with 0.7 mrad/s noise
    p0 = p_equal_codes(sigma)
    worst = -math.inf
    for _ in range(2000):  # 2000 blocks of 100 samples
        x = np.round(rng.normal(0.0, sigma, 100) + rng.uniform())
        eq = int(np.sum(np.diff(x) == 0))
        worst = max(worst, equal_codes_llr(eq, 99, p0))
    assert worst < 20.0  # a CUSUM with h = 20 is not crossed by one healthy block
    assert equal_codes_llr(99, 99, p0) > 90.0  # frozen: about 98 nats in one block
    # every code distinct (a filtered float log): evidence against a frozen gyro
    assert equal_codes_llr(0, 99, p_equal_codes(50.0)) < 0.0


def test_floored_mean_llr_below_floor_never_accumulates():
    floor = 0.5 * DEG
    for sigma in (1e-5, 1e-4, 1e-3):
        assert floored_mean_llr(0.7 * floor, sigma, floor) < 0
        assert floored_mean_llr(1.0 * floor, sigma, floor) > 0
    assert floored_mean_llr(0.3 * DEG, 1e-4, 0.0, 0.2 * DEG) > 0  # no floor: the textbook allowance


def test_capped_needs_hold_blocks():
    assert capped(1000.0, 20.0, 5) == 4.0
    assert capped(-3.0, 20.0, 5) == -3.0
    assert capped(7.0, 20.0, 1) == 7.0


def test_allan_wander_var_rate_random_walk_matches_simulation():
    rng = np.random.default_rng(7)
    K, T = 2e-4, 120
    w = np.cumsum(rng.normal(0.0, K, (T + 1, 4000)), axis=0)  # 1 s steps: b(t) = K W(t)
    d = w[T] - w[:T].mean(axis=0)
    assert allan_wander_var(None, K, T) == pytest.approx(float(d.var()), rel=0.08)
    assert allan_wander_var(1e-4, None, T) == pytest.approx(2 * math.log(2) / math.pi * 1e-8)


def test_wander_var_measures_the_spread_of_the_means():
    rng = np.random.default_rng(11)
    x = rng.normal(0.0, 0.2 * DEG, 60)
    assert math.sqrt(wander_var(x)) == pytest.approx(0.2 * DEG, rel=0.35)
    assert wander_var(x[:5]) == 0.0


def test_limits_from_mapping():
    lim = FaultLimits.from_mapping({"bias_jump_dps": 1.0, "disagree_hold_blocks": 5})
    assert lim.bias_jump == pytest.approx(DEG) and lim.disagree_hold_blocks == 5
    with pytest.raises(ValueError):
        FaultLimits.from_mapping({"bias_jump": 1})
    with pytest.raises(ValueError):
        FaultLimits.from_mapping({"disagree_dps": -1})
