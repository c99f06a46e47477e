"""Allan variance of white rate noise seen through an autopilot's low-pass filter and then sampled.

An autopilot samples its gyro at 1-8 kHz, low-pass filters it (ArduPilot INS_GYRO_FILTER, PX4
IMU_GYRO_CUTOFF: a two-pole Butterworth-like filter) and logs one filtered value every tau0. The logged
sequence is the continuous filtered process sampled at tau0, so

* below the cut-off time the Allan curve falls under the white-noise line N^2/tau (the filter removes
  power at short tau: a datasheet N then looks "too large" at the first points), and
* noise above the logger's Nyquist frequency is folded in (aliasing from decimation): the long-tau white
  level of the log is N_eff^2 = tau0 sum_k R(k tau0) = N^2 sum_j |H(j fs)|^2 (Poisson summation), above N^2
  when the cut-off is near or above fs/2, and equal to N^2 when it is well below.

Both are exact here: the AVAR of a stationary sampled sequence with autocovariance r(k) = R(k tau0) at
cluster size m is Var(block mean) - Cov(adjacent block means),

    AVAR(m) = [m r(0) + 2 sum_{L=1}^{m-1} (m - L) r(L) - sum_{L=1}^{2m-1} (m - |L - m|) r(L)] / m^2,

with R the autocovariance of white noise of two-sided density N^2 through |H(f)|^2:

* order 1, |H|^2 = 1 / (1 + (f/fc)^2):  R(t) = N^2 pi fc exp(-2 pi fc |t|)   (a Gauss-Markov process with
  tau_c = 1 / (2 pi fc), IEEE 952 C.6, here sampled rather than averaged);
* order 2 (Butterworth), |H|^2 = 1 / (1 + (f/fc)^4), w0 = 2 pi fc, a = w0/sqrt(2):
  R(t) = N^2 (w0 / (2 sqrt 2)) exp(-a|t|) (cos(a t) + sin(a |t|)).

This shape lives in companion.gap (the workflow needs it as a candidate); a filtered-white-noise AVAR
shape for the fitter in companion.allan may exist separately.
"""

from __future__ import annotations

import math

import numpy as np

#: lags beyond this many correlation times contribute < 1e-12 of r(0)
_DECAY_TIMES = 30.0
_MAX_LAGS = 400_000


def autocovariance(t, N: float, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """R(t) of white noise (two-sided density N^2) through an ``order`` 1 or 2 low-pass at ``cutoff_hz``."""
    t = np.abs(np.asarray(t, dtype=float))
    w0 = 2.0 * math.pi * cutoff_hz
    if order == 1:
        return N**2 * math.pi * cutoff_hz * np.exp(-w0 * t)
    if order == 2:
        a = w0 / math.sqrt(2.0)
        return N**2 * (w0 / (2.0 * math.sqrt(2.0))) * np.exp(-a * t) * (np.cos(a * t) + np.sin(a * t))
    raise ValueError(f"filter order must be 1 or 2, got {order}")


def _lag_autocovariance(L, tau0, N, cutoff_hz, order, integrate):
    """r(L) = R(L tau0) of the logged sequence; with ``integrate`` each logged value is the mean of the
    filtered rate over its own interval tau0 (PX4 sensor_combined: the gyro integral over integral_dt
    divided by dt), whose autocovariance is R convolved with the triangle (1 - |s|/tau0)/tau0 on
    [-tau0, tau0] (Simpson's rule, 41 nodes, one of them at s = 0 where R has its kink)."""
    L = np.asarray(L, dtype=float)
    if not integrate:
        return autocovariance(L * tau0, N, cutoff_hz, order)
    s_nodes = np.linspace(-tau0, tau0, 41)
    w = np.ones(41)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    w *= (s_nodes[1] - s_nodes[0]) / 3.0 * (1.0 - np.abs(s_nodes) / tau0) / tau0
    return autocovariance(L[:, None] * tau0 + s_nodes[None, :], N, cutoff_hz, order) @ w


def correlation_time(cutoff_hz: float, order: int = 2) -> float:
    """Decay time of R: 1/(2 pi fc) (order 1), sqrt(2)/(2 pi fc) (order 2)."""
    return (1.0 if order == 1 else math.sqrt(2.0)) / (2.0 * math.pi * cutoff_hz)


def aliasing_gain(cutoff_hz: float, rate_hz: float, order: int = 2, integrate: bool = False) -> float:
    """N_eff^2 / N^2 = tau0 sum_k r(k) / N^2: the long-tau white level of the log over the sensor's."""
    tau0 = 1.0 / rate_hz
    kmax = int(min(_MAX_LAGS, math.ceil(_DECAY_TIMES * correlation_time(cutoff_hz, order) / tau0) + 2))
    r = _lag_autocovariance(np.arange(kmax + 1), tau0, 1.0, cutoff_hz, order, integrate)
    return float(tau0 * (r[0] + 2.0 * np.sum(r[1:])))


def avar_filtered_white(tau, N: float, cutoff_hz: float, rate_hz: float, order: int = 2,
                        integrate: bool = False) -> np.ndarray:
    """AVAR at ``tau`` (multiples of 1/rate_hz) of white noise N low-pass filtered at ``cutoff_hz`` and
    sampled at ``rate_hz`` (exact for the sampled sequence; see the module docstring); ``integrate``: each
    sample is the mean over its interval instead of a point value (:func:`_lag_autocovariance`)."""
    tau = np.asarray(tau, dtype=float)
    mf = np.maximum(tau * rate_hz, 1.0)
    lo, hi = np.floor(mf + 1e-9).astype(np.int64), np.ceil(mf - 1e-9).astype(np.int64)
    a_lo = _avar_at(lo, N, cutoff_hz, rate_hz, order, integrate)
    if np.array_equal(lo, hi):
        return a_lo
    # between cluster sizes (a plot's dense tau grid): log-log interpolation of the integer-m values
    a_hi = _avar_at(hi, N, cutoff_hz, rate_hz, order, integrate)
    w = np.where(hi > lo, np.log(mf / lo) / np.log(np.maximum(hi, lo + 1) / lo), 0.0)
    return np.exp((1 - w) * np.log(np.maximum(a_lo, 1e-300)) + w * np.log(np.maximum(a_hi, 1e-300)))


def _avar_at(m_all, N, cutoff_hz, rate_hz, order, integrate):
    tau0 = 1.0 / rate_hz
    kmax = int(min(_MAX_LAGS, math.ceil(_DECAY_TIMES * correlation_time(cutoff_hz, order) / tau0) + 2))
    L = np.arange(kmax + 1)
    r = _lag_autocovariance(L, tau0, N, cutoff_hz, order, integrate)
    # m > kmax: every lag with r != 0 is below m, the weights are m (L = 0) and 2m - 3L (L >= 1)
    s1 = r[0] + 2.0 * np.sum(r[1:])
    s2 = 3.0 * np.sum(L[1:] * r[1:])
    out = (m_all * s1 - s2) / m_all.astype(float) ** 2
    for i, m in enumerate(m_all):
        if m > kmax:
            continue
        Lm = L[: min(2 * m, kmax + 1)]
        w = np.where(Lm == 0, m, 0) + np.where((Lm >= 1) & (Lm <= m - 1), 2 * (m - Lm), 0) \
            - np.where((Lm >= 1) & (Lm <= 2 * m - 1), m - np.abs(Lm - m), 0)
        out[i] = float(np.dot(w, r[: Lm.shape[0]])) / float(m) ** 2
    return np.maximum(out, 0.0)


def synthesize_filtered_white(N: float, cutoff_hz: float, rate_hz: float, n: int, rng, order: int = 2,
                              oversample: int = 8, integrate: bool = False) -> np.ndarray:
    """``n`` samples at ``rate_hz`` of white noise N through the low-pass, simulated at ``oversample`` x the
    rate (the autopilot's sensor rate) and picked every ``oversample``-th sample (no averaging: decimation).
    Noise above oversample x rate / 2 is left out (a small share for cut-offs below the log's rate)."""
    from scipy.signal import butter, sosfilt

    fs = rate_hz * oversample
    w = rng.standard_normal(n * oversample) * (N * math.sqrt(fs))
    sos = butter(order, min(cutoff_hz, 0.45 * fs), fs=fs, output="sos")
    y = sosfilt(sos, w)
    if integrate:  # the mean over each logged interval
        return y[: n * oversample].reshape(n, oversample).mean(axis=1)
    return y[oversample - 1:: oversample][:n]
