"""The spread of the gap metric under a right model on a record's own layout (companion.gap.null): what a
remaining gap is compared with."""

import numpy as np
import pytest

from companion.gap.compare import gap_metric, measure, model_avar
from companion.gap.likelihood import expected_deviance
from companion.gap.null import null_gap, synthesize_model

WHITE = [{"effect": "white_noise", "N": 1e-3}]


def test_right_model_g_has_its_analytic_mean_and_the_shares_are_tail_probabilities():
    """Under a right model an estimate is s chi^2_nu_raw / nu_raw, and the Gamma deviance taken with the
    floored nu (5 % model floor) has mean (nu / nu_raw) E0(nu_raw) per point, so G's mean is
    mean_i (nu_i / nu_raw_i) E0(nu_raw_i) / E0(nu_i) (0.76 for white noise, 2000 samples at 50 Hz; 1 without
    the floor): the simulated G matches it within 12 % (100 records; the mean's spread is about 0.04). The
    share with G >= g is a tail probability: 1 at g = 0, 0 above every draw, about a half at the median."""
    r = null_gap(WHITE, [2000], 50.0, 0.0, None, None, seed=3, draws=100)
    assert r["draws"] == 100 and r["share_ge"] == 1.0
    m = measure(synthesize_model(WHITE, 50.0, 2000, np.random.default_rng(0)), 50.0)
    expected = float(np.mean(m.nu / m.nu_raw * expected_deviance(m.nu_raw) / expected_deviance(m.nu)))
    assert r["mean"] == pytest.approx(expected, rel=0.12)
    assert r["median"] < r["mean"] < r["p95"]
    assert null_gap(WHITE, [2000], 50.0, r["median"], None, None, seed=3, draws=100)["share_ge"] == \
        pytest.approx(0.5, abs=0.02)
    assert null_gap(WHITE, [2000], 50.0, 1e6, None, None, seed=3, draws=100)["share_ge"] == 0.0


def test_a_short_record_spreads_g_more_than_a_long_one_and_a_wrong_model_is_far_out():
    """The noise floor (2) is one number; G's spread is not: on a record of 600 samples (octaves up to a
    third of it, EDF down to 2) the 95th percentile lies above that of a record 16x longer. A record whose
    noise is 1.3x the model's in ADEV gives a G no simulated record of the model reaches."""
    short = null_gap(WHITE, [600], 50.0, 0.0, None, None, seed=5, draws=80)
    long_ = null_gap(WHITE, [9600], 50.0, 0.0, None, None, seed=5, draws=80)
    assert short["p95"] > long_["p95"]
    y = synthesize_model([{"effect": "white_noise", "N": 1.3e-3}], 50.0, 2000, np.random.default_rng(11))
    m = measure(y, 50.0)
    g = gap_metric(m, model_avar(WHITE, m.tau, 50.0))
    assert null_gap(WHITE, [2000], 50.0, g, None, None, seed=3, draws=100)["share_ge"] == 0.0


def test_resolved_share_and_the_sample_budget():
    """Over tau <= tau_max the resolved G is drawn too; a layout beyond the sample budget gets no null."""
    r = null_gap(WHITE, [1000, 700], 50.0, 0.0, 0.0, 2.0, seed=1, draws=50)
    assert r["share_ge_resolved"] == 1.0 and r["p95_resolved"] > r["median_resolved"] > 0
    assert null_gap(WHITE, [3_000_000], 50.0, 1.0, None, None) is None
