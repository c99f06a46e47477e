"""The low-pass + decimation AVAR (companion.allan.filtered_white) against the gap workflow's simulation of
it (companion.gap.lowpass_check), and the filter named on simulated filtered data, not on unfiltered data."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from companion.allan.adev import oavar
from companion.gap import run_gap
from companion.allan.filtered_white import aliasing_gain, autocovariance, avar_filtered_white
from companion.gap.lowpass_check import synthesize_filtered_white
from companion.gap.workflow import NOISE_FLOOR_G


@pytest.mark.parametrize("order", [1, 2])
def test_autocovariance_is_the_transform_of_the_psd(order):
    fc = 20.0
    for t in (0.0, 0.004, 0.02):
        psd = lambda f: 2.0 / (1 + (f / fc) ** (2 * order))  # noqa: E731  (two-sided, both halves)
        num = quad(psd, 0, np.inf)[0] if t == 0 else quad(psd, 0, np.inf, weight="cos", wvar=2 * math.pi * t)[0]
        assert autocovariance(t, 1.0, fc, order) == pytest.approx(num, rel=2e-3, abs=1e-3)


def test_far_below_nyquist_is_white_at_long_tau_and_no_aliasing():
    tau = np.array([10.0, 100.0])
    a = avar_filtered_white(tau, 1e-3, 5.0, 100.0)
    assert a * tau / 1e-6 == pytest.approx([1.0, 1.0], rel=5e-3)  # the correlation leaves a 1/tau^2 term
    assert aliasing_gain(5.0, 100.0) == pytest.approx(1.0, abs=1e-4)
    assert aliasing_gain(40.0, 100.0) > 1.03  # near Nyquist the folded noise shows


@pytest.mark.parametrize("fc,rate", [(20.0, 50.0), (5.0, 100.0)])
def test_matches_simulation(fc, rate):
    rng = np.random.default_rng(3)
    ratios = []
    for _ in range(3):
        y = synthesize_filtered_white(1e-3, fc, rate, 100_000, rng, oversample=16)
        tau, av, _, _ = oavar(y, rate)
        ratios.append(av[:8] / avar_filtered_white(tau[:8], 1e-3, fc, rate))
    assert np.mean(ratios, axis=0) == pytest.approx(np.ones(8), rel=0.04)


def test_filter_named_on_filtered_data_from_the_log_cutoff():
    rate, n = 100.0, 200_000
    rng = np.random.default_rng(11)
    y = synthesize_filtered_white(1e-3, 8.0, rate, n, rng)
    model = [{"effect": "white_noise", "N": 1e-3}]
    r = run_gap(y, rate, model, cutoff_hz=8.0, simulate=False)
    assert [a["effect"] for a in r.added] == ["lowpass"]
    assert r.added[0]["cutoff_hz"] == 8.0 and r.added[0]["source"] == "the log's parameter"
    assert r.gap_after <= NOISE_FLOOR_G < r.gap_before
    r2 = run_gap(y, rate, model, simulate=False)  # cut-off fitted
    assert [a["effect"] for a in r2.added] == ["lowpass"]
    assert abs(r2.added[0]["cutoff_hz"] / 8.0 - 1) < 0.2


def test_no_filter_named_on_white_data():
    rate = 100.0
    y = np.random.default_rng(5).standard_normal(200_000) * 1e-3 * math.sqrt(rate)
    r = run_gap(y, rate, [{"effect": "white_noise", "N": 1e-3}], cutoff_hz=45.0, simulate=False)
    assert r.added == [] and r.fits_within_noise


def test_temperature_drift_named_and_checked_against_the_channel():
    """A rate of 3e-4 rad/s per K following a warm-up curve (+4 K, time constant 15 min) plus slow
    wiggles of the temperature is named "temperature" (not a ramp or random walk) and the direct
    regression on the channel confirms the coefficient."""
    rate, T = 20.0, 7200.0
    n = int(rate * T)
    t = np.arange(n) / rate
    rng = np.random.default_rng(21)
    temp = 30 + 4 * (1 - np.exp(-t / 900.0)) + 0.4 * np.sin(2 * np.pi * t / 1300.0)
    temp_meas = np.round(temp + 0.02 * rng.standard_normal(n), 2)  # the channel's own noise and LSB
    model = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 5e-5}]
    from companion.sim.synth import synthesize_axis

    y = synthesize_axis(model, rate, n, rng) + 3e-4 * temp
    r = run_gap(y, rate, model, simulate=False, temperature=temp_meas, lowpass=False)
    assert [a["effect"] for a in r.added] == ["temperature"]
    assert r.added[0]["check"]["confirmed"]
    assert abs(r.added[0]["coef"] / 3e-4 - 1) < 0.3
    assert r.gap_after <= NOISE_FLOOR_G
    r0 = run_gap(y - 3e-4 * temp, rate, model, simulate=False, temperature=temp_meas, lowpass=False)
    assert r0.added == []  # no drift: the channel alone adds nothing


def _gap_of_averaged_line(rng, rate, n, fc, N, f0, A):
    """The workflow on averaged samples (PX4 sensor_combined) of white noise of density N behind an fc two-pole
    filter plus a line of frequency f0 and amplitude A averaged over each interval, from the model N alone."""
    y = synthesize_filtered_white(N, fc, rate, n, rng, integrate=True)
    t = np.arange(n) / rate
    ph = rng.uniform(0, 2 * math.pi)
    w = 2 * math.pi * f0
    y = y + A * (np.sin(w * (t + 1 / rate) + ph) - np.sin(w * t + ph)) / (w / rate)  # the mean over each interval
    return run_gap(y, rate, [{"effect": "white_noise", "N": N}], simulate=False, integrated=True)


@pytest.mark.parametrize("seed", [0, 1])
def test_fitted_cutoff_is_refitted_after_a_line_near_nyquist(seed):
    """Averaged samples (PX4 sensor_combined) of white noise behind a 42 Hz two-pole filter, plus a 116.5 Hz
    line near the 125 Hz Nyquist frequency, averaged the same way: both named, and once the line is in, the
    fitted cut-off is profiled again (it had taken the line's short-tau power: a 50 Hz order-1 filter and the
    line at 60 % of its amplitude, G above 2), so the line's amplitude is within 30 % and the gap closes."""
    rate, n, fc, N, f0, A = 250.0, 15000, 42.0, 5.6e-5, 116.5, 6e-4
    rng = np.random.default_rng(seed)
    r = _gap_of_averaged_line(rng, rate, n, fc, N, f0, A)
    named = {a["effect"]: a for a in r.added}
    assert set(named) == {"sinusoid", "lowpass"}
    assert abs(named["sinusoid"]["freq_hz"] / f0 - 1) < 0.1
    assert abs(named["sinusoid"]["amplitude"] / A - 1) < 0.3
    assert abs(named["lowpass"]["cutoff_hz"] / fc - 1) < 0.2
    assert r.gap_after <= NOISE_FLOOR_G


@pytest.mark.parametrize("seed", [0, 1])
def test_a_line_near_nyquist_is_named_at_its_frequency(seed):
    """Averaged samples of white noise behind a 42 Hz two-pole filter, plus a line at 0.47 x the rate (above
    the 0.45 x rate where the Allan-curve search of a sinusoid's frequency stops, and where that curve, which
    sees such a line at tau0 alone, cannot place it): the periodogram's line is a candidate at its own
    frequency, named within 1 % (a Welch bin is 0.4 % of it), its amplitude within 30 %, and the fitted
    cut-off, refined between its grid points (33 % apart), within 10 % of the filter's."""
    rate, n, fc, N, f0, A = 250.0, 15000, 42.0, 5.6e-5, 0.47 * 250.0, 6e-4
    rng = np.random.default_rng(100 + seed)
    r = _gap_of_averaged_line(rng, rate, n, fc, N, f0, A)
    named = {a["effect"]: a for a in r.added}
    assert set(named) == {"sinusoid", "lowpass"}
    assert abs(named["sinusoid"]["freq_hz"] / f0 - 1) < 0.01
    assert abs(named["sinusoid"]["amplitude"] / A - 1) < 0.3
    assert abs(named["lowpass"]["cutoff_hz"] / fc - 1) < 0.1
    assert r.gap_after <= NOISE_FLOOR_G
