"""Trend test across flights: is an IMU's N, B or K rising beyond what the per-flight intervals explain?

Pure numpy/scipy. For one IMU, one axis and one parameter p (N, B or K) with estimates p_i and 95 %
intervals [lo_i, hi_i] from flights i = 0..F-1 in time order:

    y_i = ln p_i,   s_i = (ln hi_i - ln lo_i) / (2 z_0.975)   (one-sided half width when lo_i = 0),
    x_i = i / (F - 1)                                          (flight index scaled to [0, 1]),

weighted least squares y_i = a + b x_i with weights w_i = 1 / s_i^2:

    b = sum w (x - xbar)(y - ybar) / S_xx,   S_xx = sum w (x - xbar)^2,   var_0(b) = 1 / S_xx,
    phi = chi^2 / (F - 2) = sum w (y - a - b x)^2 / (F - 2)          (dispersion, Birge ratio),
    se(b) = sqrt(var_0(b) max(1, phi)),   T = b / se(b) ~ Student t with F - 2 degrees of freedom.

The per-flight intervals say how much scatter to expect; when the flights scatter more than that (a
vehicle flown in other conditions, an interval too narrow), ``phi > 1`` widens the slope's error
accordingly (quasi-likelihood; McCullagh & Nelder 1989, sec. 4.5) and the t reference accounts for
phi being estimated. phi < 1 is not used to narrow it. The one-sided p-value P(T >= t) tests for a
*rise*; ``ratio = exp(b)`` is the fitted last/first flight ratio.

An IMU has up to 3 axes x 3 parameters = m tests (a parameter is tested on an axis when the fit
selected it in at least ``MIN_FLIGHTS`` flights and in at least half of the IMU's flights). Its
**evidence** is ``-log10(min(1, m p_min))`` (Bonferroni over its own tests), and it is **flagged** when
``evidence >= EVIDENCE_THRESHOLD`` and the worst test's fitted rise ``ratio >= MIN_RISE``.

EVIDENCE_THRESHOLD = 4 was chosen from simulated healthy fleets run through the whole analysis
(benchmarks/bench_fleet.py calibrate; figure docs/img/fleet_threshold.png, table in docs/fleet.md):
the per-IMU exceedance of healthy IMUs follows 10^-evidence (the p-values are calibrated), so 4 means
a false alarm for one healthy IMU in 10,000 (one in ten 1,000-IMU fleets), while a 1.5x rise of N
over 10 or more flights reaches evidence > 6 even on 1-minute logs. MIN_RISE = 1.2: a rise
smaller than 20 % over the whole history is not called degradation even when statistically certain
(long logs make N precise to 0.2 %; seasons and mounting move it by a few per cent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from companion.allan.special import Z95

#: flag when evidence = -log10(Bonferroni p) reaches this (per-IMU false-alarm probability 1e-4)
EVIDENCE_THRESHOLD = 4.0
#: ... and the fitted last/first ratio of the worst test reaches this
MIN_RISE = 1.2
#: flights with an estimate needed before a parameter of an axis is tested
MIN_FLIGHTS = 5
#: the parameters tested for a rise
TREND_PARAMS = ("N", "B", "K")
#: smallest relative standard error of one flight's ln p (an interval reported as a point)
MIN_REL_SD = 1e-3


@dataclass
class SlopeTest:
    """Weighted regression of ln p on the scaled flight index (see the module docstring)."""

    slope: float  # b: change of ln p from the first to the last flight
    se: float  # its standard error, dispersion-corrected
    t: float  # b / se
    dof: int  # F - 2
    phi: float  # chi^2 / dof of the straight-line fit
    log10_p: float  # log10 of the one-sided p-value P(T >= t)
    intercept: float
    flights: int

    @property
    def ratio(self) -> float:
        """Fitted value at the last flight over the fitted value at the first flight."""
        return math.exp(self.slope)


def log_sd(value, lo, hi) -> np.ndarray:
    """Standard deviation of ln p from a 95 % interval [lo, hi] (upper half width when lo <= 0)."""
    value, lo, hi = (np.asarray(a, dtype=float) for a in (value, lo, hi))
    with np.errstate(divide="ignore", invalid="ignore"):
        both = (np.log(hi) - np.log(lo)) / (2.0 * Z95)
        upper = (np.log(hi) - np.log(value)) / Z95
    sd = np.where(lo > 0, both, upper)
    sd = np.where(np.isfinite(sd), sd, np.nan)
    return np.maximum(sd, MIN_REL_SD)


def slope_test(x, y, s) -> SlopeTest | None:
    """One-sided test for a positive slope of ``y`` (ln p) on ``x`` in [0, 1] with standard errors ``s``.

    Returns None with fewer than 3 points or no spread in ``x``.
    """
    x, y, s = (np.asarray(a, dtype=float) for a in (x, y, s))
    ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(s) & (s > 0)
    x, y, s = x[ok], y[ok], s[ok]
    n = x.size
    if n < 3:
        return None
    w = 1.0 / s**2
    xb = float(np.sum(w * x) / np.sum(w))
    yb = float(np.sum(w * y) / np.sum(w))
    sxx = float(np.sum(w * (x - xb) ** 2))
    if not sxx > 0:
        return None
    b = float(np.sum(w * (x - xb) * (y - yb)) / sxx)
    a = yb - b * xb
    dof = n - 2
    chi2 = float(np.sum(w * (y - a - b * x) ** 2))
    phi = chi2 / dof
    se = math.sqrt(max(1.0, phi) / sxx)
    t = b / se
    from scipy.stats import t as t_dist

    log10_p = float(t_dist.logsf(t, dof)) / math.log(10.0)
    return SlopeTest(b, se, t, dof, phi, log10_p, a, n)


@dataclass
class ImuTrend:
    """Trend verdict of one IMU: its tests, the worst one, evidence and flag."""

    flights: int
    tests: dict = field(default_factory=dict)  # (axis, param) -> SlopeTest
    axis: str | None = None
    param: str | None = None
    evidence: float = 0.0
    flagged: bool = False
    note: str = ""

    @property
    def worst(self) -> SlopeTest | None:
        return self.tests.get((self.axis, self.param))

    @property
    def trend(self) -> float | None:
        return self.worst.ratio if self.worst else None


def imu_trend(series: dict, flights: int, threshold: float = EVIDENCE_THRESHOLD,
              min_rise: float = MIN_RISE, params=TREND_PARAMS) -> ImuTrend:
    """Trend verdict from ``series[(axis, param)] = (flight_index, value, lo, hi)`` arrays.

    ``flight_index``: 0..flights-1 in time order (the IMU's flights; an axis may miss some).
    """
    out = ImuTrend(flights=flights)
    if flights < MIN_FLIGHTS:
        out.note = f"{flights} flight(s): at least {MIN_FLIGHTS} needed for a trend"
        return out
    span = max(flights - 1, 1)
    for (axis, param), (idx, v, lo, hi) in sorted(series.items()):
        if param not in params:
            continue
        idx, v, lo, hi = (np.asarray(a, dtype=float) for a in (idx, v, lo, hi))
        ok = np.isfinite(v) & (v > 0) & np.isfinite(hi) & (hi > 0)
        if ok.sum() < max(MIN_FLIGHTS, math.ceil(0.5 * flights)):
            continue
        lo = np.where(np.isfinite(lo), lo, 0.0)
        test = slope_test(idx[ok] / span, np.log(v[ok]), log_sd(v[ok], lo[ok], hi[ok]))
        if test is not None:
            out.tests[(axis, param)] = test
    if not out.tests:
        out.note = "no parameter estimated in enough flights"
        return out
    (axis, param), worst = min(out.tests.items(), key=lambda kv: (kv[1].log10_p, -kv[1].t))
    m = len(out.tests)
    out.axis, out.param = axis, param
    out.evidence = max(0.0, -(worst.log10_p + math.log10(m)))
    out.flagged = bool(out.evidence >= threshold and worst.ratio >= min_rise)
    return out
