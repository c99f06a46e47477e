"""Periodogram check of a sinusoid named from the Allan curve (companion.gap.spectral), against simulated
truth: a real line is confirmed with its amplitude, noise without a line and a filtered (sloping) noise
floor are not."""

import numpy as np
import pytest
from scipy.signal import lfilter

from companion.gap.spectral import line_evidence
from companion.sim.synth import synthesize_axis

RATE = 20.0
WB = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 1e-4}]


@pytest.mark.parametrize("amplitude,freq_hz", [(2e-3, 0.05), (1e-3, 0.005), (3e-3, 0.5)])
@pytest.mark.parametrize("seed", [1, 2])
def test_a_line_is_confirmed_with_its_amplitude(amplitude, freq_hz, seed):
    y = synthesize_axis(WB + [{"effect": "sinusoid", "amplitude": amplitude, "freq_hz": freq_hz}], RATE,
                        int(7200 * RATE), np.random.default_rng(seed))
    ev = line_evidence(y, RATE, freq_hz * 1.03, amplitude)  # the Allan fit's frequency is a few % off
    assert ev["confirmed"]
    assert abs(ev["f_peak"] / freq_hz - 1) < 0.05
    # the band holds the line plus ~(band width x noise level): a few % of A at these sizes
    assert ev["amplitude_psd"] == pytest.approx(amplitude, rel=0.1)


@pytest.mark.parametrize("freq_hz", [0.005, 0.05, 0.5, 5.0])
def test_no_line_in_noise(freq_hz):
    false = 0
    for seed in range(10):
        y = synthesize_axis(WB, RATE, int(7200 * RATE), np.random.default_rng(100 + seed))
        false += line_evidence(y, RATE, freq_hz, 1e-3)["confirmed"]
    assert false == 0


def test_a_filter_roll_off_is_not_a_line():
    """White noise through a 2-pole low-pass at 10 Hz (100 Hz data): a sloping PSD near 8 Hz, no line."""
    rng = np.random.default_rng(7)
    rate = 100.0
    a = np.exp(-2 * np.pi * 10.0 / rate)
    y = lfilter([(1 - a) ** 2], [1, -2 * a, a * a], rng.normal(0, 0.01, 1_000_000))
    ev = line_evidence(y, rate, 8.2, 2.5e-3)
    assert not ev["confirmed"]
    assert ev["peak_ratio"] < ev["threshold"]


def test_too_short_a_record_gives_no_verdict():
    assert line_evidence(np.zeros(100), RATE, 0.05, 1e-3) is None
    assert line_evidence(np.ones(10_000), RATE, 15.0, 1e-3) is None  # above Nyquist


def test_a_line_the_periodogram_would_show_is_ruled_out_when_absent():
    """Noise alone, a line of the hypothesised amplitude (its half would stand ~10x above the level in one
    bin): ruled out at every frequency, up to near the Nyquist frequency (where angle quantisation's rise
    sits); the same line really there is confirmed and never ruled out."""
    rate, n = 50.0, 50_000
    t = np.arange(n) / rate
    for freq_hz in (0.5, 8.8, 22.3):
        out, kept = 0, 0
        for seed in range(8):
            rng = np.random.default_rng(300 + seed)
            y = rng.normal(0.0, 1.0, n)
            out += line_evidence(y, rate, freq_hz, 0.5)["ruled_out"]
            f = freq_hz * rng.uniform(0.95, 1.05)
            ev = line_evidence(y + 0.5 * np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3)), rate, freq_hz, 0.5)
            kept += ev["confirmed"] and not ev["ruled_out"]
        assert out == 8 and kept == 8, freq_hz


def test_no_verdict_against_a_line_without_the_resolution():
    """A slow line in a short record (one Welch segment at 0.1 Hz): the periodogram has little power
    against it, so its absence rules nothing out (the Allan curve alone decides there)."""
    rng = np.random.default_rng(5)
    ev = line_evidence(rng.normal(0.0, 1.0, 5_000), RATE, 0.1, 0.15)
    assert ev["power"] < 0.5 and not ev["ruled_out"]
    ev = line_evidence(rng.normal(0.0, 1.0, 50_000), RATE, 0.1, 0.15)  # ten times as long: 23 segments
    assert ev["power"] > 0.999 and ev["ruled_out"]


def test_no_false_line_near_the_nyquist_frequency():
    """Near the Nyquist frequency the background fit must not take the (halved) Nyquist bin: noise alone
    gave a 'significant' peak at 22.3 Hz of 50 Hz data in most records."""
    rate = 50.0
    sig = 0
    for seed in range(20):
        y = np.random.default_rng(400 + seed).normal(0.0, 1.0, 20_000)
        ev = line_evidence(y, rate, 22.3, 0.05)
        sig += ev["peak_ratio"] > ev["threshold"]
    assert sig <= 2


def test_lines_searched_over_the_spectrum_none_in_noise_and_the_true_one_found():
    """significant_lines: no line in filtered, interval-averaged noise (a band fit from below the Nyquist
    frequency named one in a third of such records), and a line at 0.47 x the rate found within a Welch
    bin with its amplitude (as the averaged samples carry it) within 25 %."""
    from companion.gap.lowpass_check import synthesize_filtered_white
    from companion.gap.spectral import significant_lines

    rate, n = 250.0, 15000
    false = 0
    for seed in range(20):
        rng = np.random.default_rng(500 + seed)
        false += len(significant_lines(synthesize_filtered_white(1e-3, 42.0, rate, n, rng, integrate=True), rate))
    assert false <= 1
    f0, A = 0.47 * rate, 2e-3
    for seed in range(5):
        rng = np.random.default_rng(600 + seed)
        y = synthesize_filtered_white(1e-3, 42.0, rate, n, rng, integrate=True)
        y = y + A * np.sin(2 * np.pi * f0 * np.arange(n) / rate + rng.uniform(0, 2 * np.pi))
        lines = significant_lines(y, rate)
        assert lines and abs(lines[0][0] - f0) <= rate / 256
        assert abs(lines[0][1] / A - 1) < 0.25
