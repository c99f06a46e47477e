"""Tolerances of statistical checks from their distributions, so that a check's false-failure rate is a
stated number and no seed is picked to pass."""

from __future__ import annotations

from scipy.stats import binom

#: false-failure rate of one coverage check: a correct 95 % interval fails it once in 1000 runs
ALPHA = 1e-3


def coverage_floor(n: int, level: float = 0.95, alpha: float = ALPHA) -> int:
    """The fewest of ``n`` independent ``level`` intervals that must hold the truth: the largest k with
    P(X < k) <= alpha for X ~ Binomial(n, level). A calibrated interval fails the check ``count >= k`` with
    probability at most ``alpha``."""
    k = int(binom.ppf(alpha, n, level))
    return k if binom.cdf(k - 1, n, level) <= alpha else k - 1


def covers(lo_hi, truth) -> bool:
    lo, hi = lo_hi
    return lo <= truth <= hi
