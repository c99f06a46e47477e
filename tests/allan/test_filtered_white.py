"""The one filtered-white-noise AVAR (companion.allan.filtered_white) against independent forms: the PSD's
Fourier transform, the autocovariance sum of block means, the digital filter's own impulse response, the
Poisson sum of the aliased power, and the Gauss-Markov AVAR of IEEE 952 C.6 for the first-order filter."""

import math

import numpy as np
import pytest
from scipy import signal
from scipy.integrate import quad

from companion.allan.filtered_white import aliasing_gain, autocovariance, avar_filtered_white
from companion.allan.terms import avar_gauss_markov, avar_white_noise


def _avar_from_r(r, m):
    """Var(mean of m) - Cov(adjacent means) of a stationary sequence of autocovariance r(l), l >= 0."""
    k = np.arange(-(m - 1), m)
    w = m - np.abs(k)
    return (np.sum(w * r[np.abs(k)]) - np.sum(w * r[np.abs(k + m)])) / m**2


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_autocovariance_is_the_transform_of_the_psd(order):
    fc = 20.0
    psd = lambda f: 2.0 / (1 + (f / fc) ** (2 * order))  # noqa: E731  (two-sided, both halves)
    for t in (0.0, 0.004, 0.02):
        num = quad(psd, 0, np.inf)[0] if t == 0 else quad(psd, 0, np.inf, weight="cos", wvar=2 * math.pi * t)[0]
        assert autocovariance(t, 1.0, fc, order) == pytest.approx(num, rel=2e-3, abs=1e-3)


@pytest.mark.parametrize("order,fc,fs", [(1, 8.0, 50.0), (2, 20.0, 50.0), (3, 30.0, 100.0), (4, 5.0, 20.0)])
def test_point_samples_equal_the_block_mean_sum(order, fc, fs):
    r = autocovariance(np.arange(0, 200) / fs, 1.0, fc, order)
    for m in (1, 2, 3, 7, 30):
        assert avar_filtered_white(m / fs, 1.0, fc, fs, order) == pytest.approx(_avar_from_r(r, m), rel=1e-9)
    # the long-tau level: the Poisson sum of the power folded into the log band, sum_j |H(j fs)|^2
    # (order 1's terms fall as 1/j^2: the tail beyond 10^5 is ~2 (fc/fs)^2 1e-5)
    j = np.arange(1, 100_000)
    assert aliasing_gain(fc, fs, order) == pytest.approx(1 + 2 * np.sum(1 / (1 + (j * fs / fc) ** (2 * order))),
                                                        rel=1e-5)


def test_first_order_averaged_is_the_gauss_markov_avar():
    """Order 1: R(t) = N^2 pi fc exp(-2 pi fc |t|), a Gauss-Markov process of sigma^2 = N^2 pi fc and tau_c =
    1/(2 pi fc); averaged samples have its continuous-time AVAR (IEEE 952 C.6)."""
    fc, N = 3.0, 2e-3
    tau = np.array([0.01, 0.05, 0.2, 1.0, 10.0])
    ref = avar_gauss_markov(tau, N * math.sqrt(math.pi * fc), 1.0 / (2 * math.pi * fc))
    assert avar_filtered_white(tau, N, fc, None, 1) == pytest.approx(ref, rel=1e-9)


@pytest.mark.parametrize("order,fc,fs,fl", [(2, 20.0, 1000.0, 50.0), (4, 5.0, 8000.0, 400.0),
                                            (1, 80.0, 1000.0, 100.0), (3, 30.0, 2000.0, 250.0)])
def test_digital_filter_matches_its_impulse_response(order, fc, fs, fl):
    """The digital Butterworth at the sensor rate, point-sampled every k: AVAR from the autocovariance of its
    own impulse response (sum_n h[n] h[n + k l]), no partial fractions."""
    b, a = signal.butter(order, fc, fs=fs)
    k = int(fs / fl)
    n_imp = 400_000 if fc / fs < 0.002 else 60_000
    h = signal.lfilter(b, a, np.r_[1.0, np.zeros(n_imp - 1)])
    lags = k * np.arange(0, 80)
    r = np.array([np.dot(h[: n_imp - L], h[L:]) for L in lags]) * fs  # sigma^2 = N^2 fs, N = 1
    for m in (1, 2, 5, 20):
        got = avar_filtered_white(m / fl, 1.0, fc, fl, order, sensor_hz=fs)
        assert got == pytest.approx(_avar_from_r(r, m), rel=1e-6)


def test_no_filter_at_the_sensor_rate_aliases_the_whole_band():
    """White noise drawn at 1 kHz and picked at 50 Hz: per-sample variance N^2 fs, white level x 20."""
    assert aliasing_gain(None, 50.0, sensor_hz=1000.0) == pytest.approx(20.0, rel=1e-12)
    assert avar_filtered_white(np.array([0.02, 10.0]), 1.0, None, 50.0, sensor_hz=1000.0) \
        == pytest.approx([1000.0, 2.0], rel=1e-12)
    with pytest.raises(ValueError):
        avar_filtered_white(0.1, 1.0, 20.0, 30.0, sensor_hz=1000.0)  # not an integer decimation


def test_fitter_term_keeps_n_as_the_logged_white_level():
    """avar_white_noise(N, filter): N is the logged level (long-tau N^2 / tau) whatever the aliasing."""
    for fs in (None, 50.0):
        assert avar_white_noise(1000.0, 2e-3, 20.0, fs) == pytest.approx(4e-6 / 1000.0, rel=1e-4)
    g = aliasing_gain(20.0, 50.0)
    assert g > 1.01
    assert avar_white_noise(0.02, 1.0, 20.0, 50.0) == pytest.approx(avar_filtered_white(0.02, 1 / math.sqrt(g),
                                                                                          20.0, 50.0))
