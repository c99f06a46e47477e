"""The threshold of the in-flight noise test (:mod:`companion.service.inflight_live`) from the distribution of
its statistic, and that statistic's false-alarm rate per hour (numpy only).

The statistic of one pair and axis at a check is the log-ratio of the difference's white level now to its
baseline, in units of its standard deviation:

    Z = ln(x / b) / sigma_L,   sigma_L^2 = sigma_x^2 + sigma_b^2,   sigma = sqrt(1 / (2 EDF))            (1)

(relative 1-sigma of N from the chi-square of the Allan estimate; the EDF with the overlap of the estimator's
staggered phases, :func:`overlap_edf_gain`). With no change, ``ln x`` is Gaussian with an autocorrelation
exp(-lag / memory_s) between checks (an exponentially forgotten mean of squared Allan differences: a
Gaussian AR(1) at the checks, rho = exp(-check_s / memory_s)) and ``ln b`` an offset fixed per baseline. A
test fires when Z stays above ``z`` for ``hold`` checks in a row; its false alarms per hour are the rate
of such runs starting (:func:`run_rate`), averaged over the baseline's offset (Gauss-Hermite nodes). One
test per pair, axis and direction (up and down); :func:`z_for_rate` solves for the ``z`` whose tests
together give ``per_imu_hour`` false alarms per IMU and hour.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

GRID = 0.025  # grid step of the run recursion (standard deviations; the kernel is >= 0.3 wide at rho <= 0.95)
SPAN = 7.0  # the grid reaches this far above the level
NODES = 16  # Gauss-Hermite nodes over the baseline's offset


def overlap_edf_gain(phases: int) -> float:
    """EDF of the Allan estimate from ``phases`` staggered phases over that of one phase alone, for white
    noise: the differences of clusters m apart at steps m / phases are correlated as the Haar kernel's
    autocorrelation, rho(l) = 1 - 1.5 l / m (l <= m), (l - 2m) / 2m (m < l <= 2m); the variance of the mean
    of their squares is 2 sigma^4 / n sum rho^2, so the EDF is n / sum rho^2 against n / phases."""
    p = int(phases)
    if p <= 1:
        return 1.0
    f = np.arange(-2 * p + 1, 2 * p) / p
    a = np.abs(f)
    rho = np.where(a <= 1.0, 1.0 - 1.5 * a, (a - 2.0) / 2.0)
    return p / float(np.sum(rho * rho))


def run_rate(u: float, rho: float, hold: int) -> float:
    """Per check: the probability that a stationary standard Gaussian AR(1) (lag-one correlation ``rho``)
    crosses above ``u`` and stays above it for ``hold`` checks (a run of a debounced test starting)."""
    if not math.isfinite(u):
        return 0.0 if u > 0 else 1.0
    s = math.sqrt(max(1.0 - rho * rho, 1e-12))
    x = u + np.arange(0.0, SPAN + GRID / 2, GRID)
    w = np.full(x.size, GRID)
    w[0] = w[-1] = GRID / 2
    phi = np.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)
    below = 0.5 * np.vectorize(math.erfc)(-(u - rho * x) / (s * math.sqrt(2.0)))  # P(previous <= u | x)
    f = phi * below
    kern = np.exp(-0.5 * ((x[None, :] - rho * x[:, None]) / s) ** 2) / (s * math.sqrt(2.0 * math.pi))
    for _ in range(int(hold) - 1):
        f = (f * w) @ kern
    return float(np.sum(f * w))


@lru_cache(maxsize=64)
def false_alarms_per_hour(z: float, hold: int, check_s: float, memory_s: float, base_share: float) -> float:
    """False alarms per hour of one test (one pair, axis and direction): ``base_share`` = sigma_b^2 /
    sigma_L^2, the baseline's part of the variance (an offset fixed over the flight)."""
    rho = math.exp(-check_s / memory_s)
    sx, sb = math.sqrt(1.0 - base_share), math.sqrt(base_share)
    nodes, weights = np.polynomial.hermite_e.hermegauss(NODES)
    weights = weights / weights.sum()
    per_check = sum(w * run_rate((z - sb * o) / sx, rho, hold) for o, w in zip(nodes, weights))
    return 3600.0 / check_s * float(per_check)


@lru_cache(maxsize=64)
def z_for_rate(per_imu_hour: float, imus: int, hold: int, check_s: float, memory_s: float,
               base_share: float) -> float:
    """The ``z`` of (1) at which all tests of ``imus`` IMUs (every pair, 3 axes, up and down) give
    ``per_imu_hour`` false alarms per IMU-hour together (bisection on :func:`false_alarms_per_hour`)."""
    tests = 6 * (imus * (imus - 1) // 2)
    target = per_imu_hour * imus / max(tests, 1)
    lo, hi = 1.0, 9.0
    while hi - lo > 1e-3:
        mid = 0.5 * (lo + hi)
        if false_alarms_per_hour(mid, hold, check_s, memory_s, base_share) > target:
            lo = mid
        else:
            hi = mid
    return hi


def z_threshold(per_imu_hour: float, imus: int, hold: int, check_s: float, memory_s: float,
                baseline_s: float) -> float:
    """:func:`z_for_rate` of a test whose statistic is a running mean over ``memory_s`` against a baseline
    learned over ``baseline_s`` (the baseline's share of the variance from the two EDFs), rounded up to two
    decimals."""
    base_share = 1.0 / (1.0 + baseline_s / (2.0 * memory_s))  # sigma_b^2 / sigma_L^2 from the two EDFs
    z = z_for_rate(per_imu_hour, imus, hold, check_s, memory_s, round(base_share, 4))
    return math.ceil(z * 100.0) / 100.0


SHAPE_GRID = 1 << 12  # frequency points of the Allan shape's integral


def allan_shape(filters, rate_hz: float, m) -> np.ndarray:
    """Allan variance of white noise through the cascade of 2-pole Butterworth low-passes ``filters`` (Hz,
    bilinear and pre-warped as ArduPilot's LowPassFilter2p) over that of plain white noise, at cluster sizes
    ``m``: as :func:`companion.redundancy.shape.avar_shape`, numpy only (the live pipeline loads no scipy),
    from the filters' exact gain |H|^2 = 1 / (1 + (tan(pi f) / tan(pi f_c / f_s))^4).

    Remembered per (filters, rate, m): the flight figures ask for the same shapes at every check, and one call
    over 256 cluster sizes costs about 0.1 s of CPU (most of a replayed 3-IMU flight's time without it)."""
    key = (tuple(float(f) for f in filters), float(rate_hz), tuple(np.asarray(m, dtype=float).ravel().tolist()))
    return _allan_shape(*key).copy()


@lru_cache(maxsize=256)
def _allan_shape(filters: tuple, rate_hz: float, m: tuple) -> np.ndarray:
    m = np.asarray(m, dtype=float)
    f = (np.arange(SHAPE_GRID) + 0.5) / SHAPE_GRID * 0.5  # cycles per sample
    h2 = np.ones_like(f)
    for fc in filters:
        h2 /= 1.0 + (np.tan(np.pi * f) / math.tan(math.pi * fc / rate_hz)) ** 4
    s2 = np.sin(np.pi * f) ** 2
    kern = np.sin(np.pi * f[None, :] * m[:, None]) ** 4 / s2[None, :]
    return np.sum(kern * h2[None, :], axis=1) / np.sum(kern, axis=1)
