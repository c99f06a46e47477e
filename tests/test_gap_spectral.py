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
