"""The in-flight test's threshold (companion/service/inflight_alarm.py) against Monte Carlo truth: the overlap
gain of the Allan estimate's EDF on white noise, the rate of debounced runs of a Gaussian AR(1), the false
alarms per hour with a baseline offset per flight, and the z solved for a rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.estimators.octave_bank import OctaveBankEstimator
from companion.service.inflight_alarm import false_alarms_per_hour, overlap_edf_gain, run_rate, z_for_rate


def _ar1(rng, n, rho, flights=1):
    e = rng.normal(size=(flights, n)) * math.sqrt(1.0 - rho * rho)
    x = np.empty((flights, n))
    x[:, 0] = rng.normal(size=flights)
    for k in range(1, n):
        x[:, k] = rho * x[:, k - 1] + e[:, k]
    return x


def _runs(above, hold):
    """Runs of ``hold`` checks above, each counted where it starts (the check before is below)."""
    start = ~above[:, :-hold]
    for j in range(1, hold + 1):
        start = start & above[:, j:above.shape[1] - hold + j]
    return int(start.sum())


def test_overlap_gain_matches_white_noise_scatter():
    """Var of the 4-phase Allan estimate at m = 16 over 300 white-noise records: 2 / (edf x gain)."""
    rng = np.random.default_rng(4)
    est = []
    for _ in range(300):
        b = OctaveBankEstimator(rate_hz=100.0, effects=("white_noise",), phases=4, max_tau_s=1.0, fit="diag")
        b.update(rng.normal(size=4000))
        tau, avar, edf = b.avar()
        k = int(np.flatnonzero(np.isclose(tau, 0.16))[0])
        est.append((avar[k], edf[k]))
    a = np.array(est)
    rel_var = np.var(a[:, 0]) / np.mean(a[:, 0]) ** 2
    want = 2.0 / (np.mean(a[:, 1]) * overlap_edf_gain(4))
    # 300 records: the relative variance itself scatters by sqrt(2 / 300) ~ 8 %
    assert rel_var == pytest.approx(want, rel=0.25)
    assert overlap_edf_gain(1) == 1.0 and overlap_edf_gain(4) == pytest.approx(4 / 2.875)


@pytest.mark.parametrize("u,rho,hold", [(2.0, 0.85, 3), (2.5, 0.7, 2), (1.5, 0.9, 4)])
def test_run_rate_matches_simulated_ar1(u, rho, hold):
    x = _ar1(np.random.default_rng(7), 200_000, rho)
    got = _runs(x > u, hold) / x.size
    want = run_rate(u, rho, hold)
    assert got == pytest.approx(want, rel=5 * math.sqrt(1.0 / max(got * x.size, 1)) + 0.02)


def test_false_alarms_per_hour_with_baseline_offsets():
    """Flights of 1000 checks, each with its baseline's offset (share 0.2 of the variance): the runs above
    z = 2.2 per hour as the formula gives."""
    rng = np.random.default_rng(11)
    share, z, hold, check_s, memory_s = 0.2, 2.2, 3, 5.0, 30.0
    x = _ar1(rng, 1000, math.exp(-check_s / memory_s), flights=400)
    stat = math.sqrt(1 - share) * x + math.sqrt(share) * rng.normal(size=(400, 1))
    got = _runs(stat > z, hold) / (x.size * check_s / 3600.0)
    want = false_alarms_per_hour(z, hold, check_s, memory_s, share)
    assert got == pytest.approx(want, rel=0.15)


def test_z_for_rate_gives_the_rate():
    z = z_for_rate(1e-3, 3, 4, 5.0, 30.0, 0.2)
    assert 3.5 < z < 5.0
    per_test = false_alarms_per_hour(z, 4, 5.0, 30.0, 0.2)
    assert per_test * 18 / 3 == pytest.approx(1e-3, rel=0.02)  # 18 tests (3 pairs, 3 axes, 2 ways), 3 IMUs
    assert z_for_rate(1e-3, 2, 4, 5.0, 30.0, 0.2) < z  # fewer tests per IMU


@pytest.mark.parametrize("filters,rate", [([20.0], 50.0), ([20.0, 20.0, 20.0], 50.0), ([30.0, 25.0], 400.0),
                                          ([8.0], 50.0)])
def test_allan_shape_is_the_offline_one(filters, rate):
    from companion.redundancy.shape import avar_shape
    from companion.service.inflight_alarm import allan_shape

    m = np.array([1, 2, 3, 4, 8, 16, 64, 256])
    np.testing.assert_allclose(allan_shape(filters, rate, m), avar_shape(filters, rate, m), rtol=1e-3)
