"""Allan variance of white rate noise seen through a low-pass filter and then logged (point-sampled or averaged).

An autopilot reads its gyro at a sensor rate of 1-8 kHz, low-pass filters it (ArduPilot INS_GYRO_FILTER,
PX4 IMU_GYRO_CUTOFF: a Butterworth filter, usually of order 2) and logs it at 10-400 Hz, either the newest
filtered value (point sampling: power above the log's Nyquist frequency folds in, aliasing) or the mean over
each logged interval (PX4 sensor_combined: delta angle / dt). This module is the one place that computes the
AVAR of that process; :func:`companion.allan.terms.avar_white_noise` (the fitter's white-noise term, N the
logged white level), the gap workflow's low-pass candidate and the simulator's analytic truth all use it.

Two forms of the filter:

* analog Butterworth of order n at f_c (|H|^2 = 1 / (1 + (f/f_c)^(2n)); a filter run far above f_c): the
  autocovariance of white noise of two-sided density N^2 through it is a sum over the n left-half-plane poles
  p_k = w0 exp(i pi (2k + n - 1) / (2n)), w0 = 2 pi f_c (residues of H(s) H(-s) e^(s t)):

      R(t) = N^2 Re sum_k (-p_k / (2n)) e^(p_k |t|)

  (order 1: N^2 pi f_c e^(-w0 |t|), a Gauss-Markov process with tau_c = 1 / w0, IEEE 952 C.6; order 2:
  N^2 (w0 / (2 sqrt 2)) e^(-a|t|) (cos a t + sin a|t|), a = w0 / sqrt 2);
* digital Butterworth (``sensor_hz``): :func:`scipy.signal.butter` (bilinear, pre-warped) run at the sensor
  rate on white noise of per-sample variance N^2 f_s, point-sampled every k = f_s / f_log sensor samples
  (``sensor_hz`` without ``filter_hz``: no filter, the whole sensor band aliases, white level x k). With the
  partial fractions H(z) = k0 + sum_j r_j / (1 - p_j z^-1) the sensor-rate autocovariance is
  r(m) = sigma^2 sum_i r_i (k0 + sum_j r_j / (1 - p_i p_j)) p_i^m for m >= 1, and
  r(0) = sigma^2 [k0^2 + 2 k0 sum r_j + sum_ij r_i r_j / (1 - p_i p_j)].

Either way the logged sequence's autocovariance is r(0) at lag 0 and Re sum_j d_j z_j^l at lags l >= 1, and
the AVAR follows from the phase (angle) structure function D(t) = E[(x(t0 + t) - x(t0))^2]:

    sigma^2(tau) = (4 D(tau) - D(2 tau)) / (2 tau^2),

* point samples at tau0 = 1/f_log, h = t / tau0:
  D(h) = tau0^2 [h r(0) + 2 Re sum_j d_j (F_j(h) - h)], F_j(h) = (h (1 - z_j) - z_j (1 - z_j^h)) / (1 - z_j)^2
  (= sum_{l=0}^{h-1} (h - l) z_j^l);
* averaged samples (continuous angle; the AVAR of interval means at tau = m tau0 is the continuous-time one):
  D(t) = 2 int_0^t (t - s) R(s) ds = 2 Re sum_k c_k (t / b_k - (1 - e^(-b_k t)) / b_k^2), b_k = -p_k.

Both tend to N_eff^2 t for t >> 1/f_c; N_eff^2 / N^2 is :func:`aliasing_gain` (1 for averaged samples,
N_eff^2 = N^2 sum_j |H(j f_log)|^2 for point samples by Poisson summation). Non-integer h (a plot's dense tau
grid) uses the same closed form (z^h = e^(h ln z)), a smooth continuation through the integer values.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np


def _analog_poles(filter_hz: float, order: int) -> tuple[np.ndarray, np.ndarray]:
    """(c_k, p_k): R(t) / N^2 = Re sum c_k e^(p_k |t|) for the analog Butterworth of ``order`` at ``filter_hz``."""
    if order not in (1, 2, 3, 4):
        raise ValueError(f"filter order must be 1-4, got {order!r}")
    w0 = 2.0 * math.pi * float(filter_hz)
    k = np.arange(1, order + 1)
    p = w0 * np.exp(1j * math.pi * (2 * k + order - 1) / (2 * order))
    return -p / (2 * order), p


def _fold(c, p):
    """Keep one pole of each conjugate pair with its coefficient doubled (a real filter's terms come in
    conjugate pairs, Re of the pair's sum = 2 Re of one): half the work of every sum over poles."""
    keep = np.imag(p) >= -1e-12 * np.maximum(np.abs(p), 1e-300)
    w = np.where(np.abs(np.imag(p)) > 1e-12 * np.maximum(np.abs(p), 1e-300), 2.0, 1.0)
    return (c * w)[keep], p[keep]


@lru_cache(maxsize=256)
def _analog_folded(filter_hz: float, order: int):
    return _fold(*_analog_poles(filter_hz, order))


def autocovariance(t, N: float, filter_hz: float, order: int = 2) -> np.ndarray:
    """R(t) of white noise of two-sided density N^2 through the analog Butterworth of ``order`` at ``filter_hz``."""
    t = np.abs(np.asarray(t, dtype=float))
    c, p = _analog_poles(filter_hz, order)
    return N**2 * np.real(np.sum(c[:, None] * np.exp(p[:, None] * t.reshape(1, -1)), axis=0)).reshape(t.shape)


def _sampled_series(N, filter_hz, sample_hz, order, sensor_hz):
    """(r0, d, z) of the logged sequence: r(0) = r0, r(l) = Re sum d z^l for l >= 1 (conjugate pairs folded)."""
    r0, d, z = _unit_series(None if filter_hz is None else float(filter_hz), float(sample_hz), int(order),
                            None if sensor_hz is None else float(sensor_hz))
    return N**2 * r0, N**2 * d, z


@lru_cache(maxsize=256)
def _unit_series(filter_hz, sample_hz, order, sensor_hz):
    tau0 = 1.0 / float(sample_hz)
    N = 1.0
    if sensor_hz is None:
        c, p = _analog_folded(filter_hz, order)
        return float(np.real(np.sum(c))), c, np.exp(p * tau0)
    from scipy.signal import butter

    fs = float(sensor_hz)
    k = int(round(fs / float(sample_hz)))
    if k < 1 or abs(k * float(sample_hz) - fs) > 1e-6 * fs:
        raise ValueError("the sensor rate must be an integer multiple of the logged rate")
    var = N**2 * fs  # per-sample variance at the sensor rate: two-sided density N^2
    if not filter_hz:
        return var, np.zeros(1, dtype=complex), np.zeros(1, dtype=complex)
    # partial fractions from the zeros and poles (the polynomial form loses the poles near z = 1 of a
    # high-order filter far below the sensor rate): H = g prod(1 - z_i w) / prod(1 - p_j w), w = 1/z
    zs, p, g = butter(order, float(filter_hz), fs=fs, output="zpk")
    r = np.array([g * np.prod(1.0 - zs / pj) / np.prod(1.0 - np.delete(p, j) / pj) for j, pj in enumerate(p)])
    k0 = float(np.real(g * np.prod(zs) / np.prod(p)))
    cross = r[None, :] / (1.0 - p[:, None] * p[None, :])
    D = r * (k0 + cross.sum(axis=1))
    r0 = k0**2 + 2.0 * k0 * np.sum(r) + np.sum(r[:, None] * cross)
    d, z = _fold(var * D, p**k)
    return var * float(np.real(r0)), d, z


def aliasing_gain(filter_hz: float | None, sample_hz: float | None, order: int = 2,
                  sensor_hz: float | None = None) -> float:
    """N_eff^2 / N^2: the long-tau white level of the logged samples over the density before the filter
    (tau0 sum_l r(l) / N^2; 1 for averaged samples, ``sample_hz`` None)."""
    if sample_hz is None:
        return 1.0
    r0, d, z = _sampled_series(1.0, filter_hz, sample_hz, order, sensor_hz)
    return float((r0 + 2.0 * np.real(np.sum(d * z / (1.0 - z)))) / float(sample_hz))


def phase_structure(t, N: float, filter_hz: float | None, sample_hz: float | None = None, order: int = 2,
                    sensor_hz: float | None = None) -> np.ndarray:
    """D(t) = E[(x(t0 + t) - x(t0))^2] of the angle of white rate noise (two-sided density N^2 before the
    filter) through the low-pass, point-sampled at ``sample_hz`` or averaged (None); see the module docstring."""
    t = np.abs(np.asarray(t, dtype=float))
    shape, t = t.shape, t.ravel()
    # D is affine in t plus terms that decay like e^(-Re(b) t): the affine part in real arithmetic everywhere,
    # the complex exponentials only where they are above 1e-16 of the rest (the EDF sums call this for tens of
    # thousands of lags per fit)
    if sample_hz is None:
        if sensor_hz is not None:
            raise ValueError("a digital filter at the sensor rate needs the logged rate (point samples)")
        c, p = _analog_folded(float(filter_hz), int(order))
        b = -p
        # 2 Re sum c (t / b - 1 / b^2 + e^(-b t) / b^2)
        out = 2.0 * N**2 * (float(np.real(np.sum(c / b))) * t - float(np.real(np.sum(c / b**2))))
        near = float(np.min(np.real(b))) * t < 37.0
        if near.any():
            e = np.exp(-b[:, None] * t[near][None, :])
            out[near] += 2.0 * N**2 * np.real(np.sum((c / b**2)[:, None] * e, axis=0))
        return out.reshape(shape)
    tau0 = 1.0 / float(sample_hz)
    r0, d, z = _sampled_series(N, filter_hz, sample_hz, order, sensor_hz)
    h = t / tau0
    live = np.abs(z) > 0
    d, z = d[live], z[live]
    # F(h) - h = h (1 / (1 - z) - 1) - z / (1 - z)^2 + z z^h / (1 - z)^2
    k1 = float(np.real(np.sum(d * (1.0 / (1.0 - z) - 1.0))))
    k0 = float(np.real(np.sum(d * z / (1.0 - z) ** 2)))
    out = tau0**2 * (h * (r0 + 2.0 * k1) - 2.0 * k0)
    if z.size:
        lz = np.log(z)
        near = float(np.min(-np.real(lz))) * h < 37.0
        if near.any():
            zh = np.exp(lz[:, None] * h[near][None, :])
            out[near] += tau0**2 * 2.0 * np.real(np.sum((d * z / (1.0 - z) ** 2)[:, None] * zh, axis=0))
    return out.reshape(shape)


def avar_filtered_white(tau, N: float, filter_hz: float | None, sample_hz: float | None = None, order: int = 2,
                        sensor_hz: float | None = None) -> np.ndarray:
    """AVAR at ``tau`` of white rate noise of two-sided density N^2 (before the filter) through the low-pass
    at ``filter_hz`` of ``order``, point-sampled at ``sample_hz`` (None: averaged over each interval); with
    ``sensor_hz`` the filter is the digital Butterworth run at that rate (see the module docstring)."""
    tau = np.asarray(tau, dtype=float)
    D = phase_structure(np.concatenate([tau.ravel(), 2.0 * tau.ravel()]), N, filter_hz, sample_hz, order, sensor_hz)
    D1, D2 = D[: tau.size].reshape(tau.shape), D[tau.size:].reshape(tau.shape)
    return np.maximum((4.0 * D1 - D2) / (2.0 * tau**2), 0.0)


def phase_structure_white(t, N: float, filter_hz: float, sample_hz: float | None = None,
                          order: int = 2) -> np.ndarray:
    """D(t) scaled so that its long-t slope is N^2: ``N`` is the white level of the logged samples (the
    plateau of ADEV sqrt(tau), aliasing included), not the density before the filter (the fitter's
    white-noise term, :func:`companion.allan.terms.avar_white_noise`)."""
    g = aliasing_gain(filter_hz, sample_hz, order)
    return phase_structure(t, N / math.sqrt(g), filter_hz, sample_hz, order)
