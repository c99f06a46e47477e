"""Where a record carries its white noise, and what it says about N where it does not.

A fitted N is *resolved* only when white noise dominates the fitted model at cluster times above the low-pass
filter's corner (:func:`white_region`): a heavy filter followed by drift (ADEV sqrt(tau) rising from the first
point on) leaves no such region, and N fitted there is a trade between the filter's shape and the drift terms,
with intervals that do not cover. There the honest answer is a bound (:func:`white_bound`): white noise alone
makes AVAR(tau) = N^2 s(tau) / tau (s the filter's shape, :func:`companion.allan.terms.avar_white_noise` with
N = 1, times tau), and every other independent term adds to it, so at every cluster time
N^2 <= AVAR(tau) tau / s(tau); with the estimate's chi-square spread (EDF) the one-sided 95 % upper bound at
each point is AVAR tau / s EDF / chi2_{0.05}(EDF), and the least over the points is the bound.
"""

from __future__ import annotations

import math

import numpy as np

from companion.allan.special import chi2_ppf
from companion.allan.terms import avar_term, avar_white_noise

#: white noise must make at least this share of the fitted AVAR ...
WHITE_SHARE = 0.5
#: ... at cluster times where the filter leaves at least this share of the white level
FILTER_PASS = 0.9
#: ... on at least this many octave points
MIN_POINTS = 2


def _shape(white_term, tau):
    f = {k: white_term.get(k) for k in ("filter_hz", "sample_hz") if white_term.get(k)}
    return avar_white_noise(tau, 1.0, **f) * tau if f.get("filter_hz") else np.ones_like(tau)


def white_region(terms, tau) -> np.ndarray:
    """Boolean mask of the cluster times ``tau`` where the white-noise term of ``terms`` makes at least
    WHITE_SHARE of the model and its filter passes at least FILTER_PASS of the white level."""
    tau = np.asarray(tau, dtype=float)
    plain = [{k: v for k, v in t.items() if k not in ("ci95", "std", "bound")} for t in terms]
    wn = next((t for t in plain if t["effect"] == "white_noise"), None)
    if wn is None:
        return np.zeros(tau.shape, dtype=bool)
    white = avar_term(wn, tau)
    total = sum(avar_term(t, tau) for t in plain)
    return (white >= WHITE_SHARE * np.where(total > 0, total, np.inf)) & (_shape(wn, tau) >= FILTER_PASS)


def white_resolved(terms, tau) -> bool:
    return int(np.count_nonzero(white_region(terms, tau))) >= MIN_POINTS


def white_bound(tau, avar, edf, white_filter=None, level=0.95) -> tuple[float, float]:
    """(one-sided ``level`` upper bound of N, cluster time where it is reached), see the module docstring."""
    tau = np.asarray(tau, dtype=float)
    avar = np.asarray(avar, dtype=float)
    edf = np.maximum(np.asarray(edf, dtype=float), 0.5)
    s = _shape(dict(white_filter or {}), tau)
    q = np.array([chi2_ppf(1.0 - level, float(e)) for e in edf])
    ub = avar * tau / s * edf / q
    ok = np.isfinite(ub) & (ub > 0)
    if not ok.any():
        return float("nan"), float("nan")
    i = int(np.flatnonzero(ok)[np.argmin(ub[ok])])
    return math.sqrt(float(ub[i])), float(tau[i])
