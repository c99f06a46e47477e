"""The white level where the Allan curve is flat: ADEV*sqrt(tau) constant within its noise over an octave or
more of well-resolved cluster times.

For white rate noise AVAR = N^2/tau, so ADEV*sqrt(tau) is N itself wherever white noise alone sets the curve.
A fitted model can miss that level: a low-pass roll-off whose shape the model does not follow, or a bias
instability and a ramp that lift the curve where a local refit looks, pull N below (or above) every point of
a plateau that thousands of EDF pin down. Where such a plateau exists, its level is the data's own answer
for N, and the analysis takes it (:func:`flat_white_level`).

A plateau: a maximal run of consecutive cluster times, each with EDF >= MIN_EDF, on which ADEV*sqrt(tau) is
flat within its noise, spanning at least MIN_SPAN in tau. Flat within its noise: a constant fits ln(AVAR*tau)
over the run within the FLAT_LEVEL point of chi^2 (:func:`flat_chi2`), each point of variance 2 / EDF and
neighbouring octaves correlated as the overlapping estimator makes them (0.53, 0.19, ...): taken point by point
(their 95 % intervals sharing a value) a rise of 17 % per octave passes as flat at EDF 126-225, where the ratio
of two neighbours is known to +-11 %. The run is found on the curve as measured (ADEV*sqrt(tau) itself
flat); its level is the EDF-weighted mean of AVAR*tau with the fitted filter's roll-off divided out (a filtered
white curve approaches N as 1 - c/tau: white noise of known N through ArduPilot's and PX4's real filter chains
puts the raw level of such a run 2.6-4 % below N on average, the corrected one within 0.4 %,
``python -m benchmarks.bench_white_chain``), square-rooted; its interval the chi-square one of the run's
best-resolved point (the points of an overlapping estimator at neighbouring cluster times are correlated, so
their EDF do not add). Of several, the widest is the white level (:func:`widest`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: the least EDF of every point of a plateau, and the least span of its cluster times
MIN_EDF = 100.0
MIN_SPAN = 2.0
#: the fitted N is kept when it lies within this fraction of the plateau's level and its interval covers it
KEEP_WITHIN = 0.03


@dataclass
class Plateau:
    """A flat white stretch of the Allan curve."""

    i: int  #: first point
    j: int  #: last point (inclusive)
    tau: tuple  #: (first, last) cluster time (s)
    level: float  #: N (SI) the plateau reads
    ci95: tuple  #: its 95 % interval
    edf: float  #: the EDF its interval is taken with


#: the flatness test's level: a run ends where a constant is rejected at this level (each extension of a run
#: is one more test, so the family of tests is held to a stricter level than 95 %)
FLAT_LEVEL = 0.99


def flat_chi2(avar_tau, edf) -> float:
    """chi^2 of a constant fitted to ln(AVAR*tau) over consecutive octave points (module docstring)."""
    from companion.allan.white import OCTAVE_CORRELATION

    x = np.log(np.asarray(avar_tau, dtype=float))
    sd = np.sqrt(2.0 / np.asarray(edf, dtype=float))
    k = np.abs(np.subtract.outer(np.arange(x.size), np.arange(x.size)))
    rho = np.asarray(OCTAVE_CORRELATION + (0.0,))[np.minimum(k, len(OCTAVE_CORRELATION))]
    vi = np.linalg.inv(rho * np.outer(sd, sd))
    one = np.ones_like(x)
    r = x - float(one @ vi @ x / (one @ vi @ one))
    return float(r @ vi @ r)


def plateaus(tau, avar, edf, level: float = 0.95, shape=None) -> list[Plateau]:
    """The plateau starting at each point of the curve (module docstring), left to right: runs from
    neighbouring starts overlap (a rising roll-off holds several short ones). ``shape``: the filter's share of
    the white AVAR at each cluster time, divided out of the level (not of the flatness test)."""
    from companion.allan.confidence import adev_ci
    from companion.allan.special import chi2_ppf

    tau, avar, edf = (np.asarray(x, dtype=float) for x in (tau, avar, edf))
    shape = np.ones_like(tau) if shape is None else np.asarray(shape, dtype=float)
    ok = np.isfinite(avar) & (avar > 0) & np.isfinite(edf) & (edf >= MIN_EDF)
    if ok.sum() < 2:
        return []
    at = np.where(ok, avar * tau, 1.0)
    out, n = [], tau.shape[0]
    for i in np.flatnonzero(ok):
        j = i
        while j + 1 < n and ok[j + 1] and flat_chi2(at[i:j + 2], edf[i:j + 2]) <= chi2_ppf(FLAT_LEVEL, j + 1 - i):
            j += 1
        if tau[j] >= MIN_SPAN * tau[i] * (1 - 1e-9):
            w = edf[i:j + 1]
            lev = math.sqrt(float(np.sum(w * at[i:j + 1] / shape[i:j + 1]) / np.sum(w)))
            e = float(np.max(w))
            (clo,), (chi,) = adev_ci([lev], [e], level)
            out.append(Plateau(int(i), int(j), (float(tau[i]), float(tau[j])), lev, (float(clo), float(chi)), e))
    return out


def widest(found: list[Plateau]) -> Plateau | None:
    """The plateau spanning the most octaves; of equals the one at the longer cluster times (a low-pass
    roll-off rises slowly at the short end, where a short run can look flat)."""
    if not found:
        return None
    return max(found, key=lambda p: (round(math.log2(p.tau[1] / p.tau[0]), 6), p.tau[1]))


#: the least share of the white AVAR the fitted filter leaves at a plateau's points
MIN_FILTER_SHARE = 0.9
#: the keys of a white-noise term that carry its low-pass filter
FILTER_KEYS = ("filter_hz", "sample_hz", "filter_order")


def filter_shape(terms: list, bounds: list, tau) -> np.ndarray:
    """The fitted filter's share of the white AVAR at each cluster time (1 without a filter): a filtered white
    curve approaches its level as 1 - c/tau, a few per cent low an octave or two above the corner, which a
    plateau read off the raw curve would take for flat."""
    from companion.allan.terms import avar_term

    tau = np.asarray(tau, dtype=float)
    wn = next((t for t in list(terms) + list(bounds) if t["effect"] == "white_noise"), None)
    if wn is None or not wn.get("filter_hz"):
        return np.ones_like(tau)
    plain = {k: v for k, v in wn.items() if k not in ("ci95", "std", "bound", "selected")}
    bare = {k: v for k, v in plain.items() if k not in FILTER_KEYS}
    return np.clip(np.asarray(avar_term(plain, tau)) / np.asarray(avar_term(bare, tau)), 1e-12, None)


def flat_white_level(terms: list, bounds: list, tau, avar, edf, notes: list, record: dict):
    """N from the widest plateau of the curve (at cluster times where the fitted filter leaves at least
    MIN_FILTER_SHARE of the white AVAR; its level with the roll-off divided out, :func:`filter_shape`) where
    the fit's N misses it (more than KEEP_WITHIN off, or its interval not covering the level) or where N was
    left as a bound: the white-noise term gets the level and its interval, ``record`` (the entry's
    ``fit.white_refit``) the plateau's cluster times and the N it replaces. Returns (terms, bounds)."""
    shape = filter_shape(terms, bounds, tau)
    # only where the filter's share is small: deep in the roll-off the level would be the filter model's
    edf = np.where(shape >= MIN_FILTER_SHARE, np.asarray(edf, dtype=float), 0.0)
    p = widest(plateaus(tau, avar, edf, shape=shape))
    if p is None:
        return terms, bounds
    wn = next((t for t in terms if t["effect"] == "white_noise"), None)
    if wn is not None:
        lo, hi = wn.get("ci95", {}).get("N", [wn["N"], wn["N"]])
        if abs(wn["N"] / p.level - 1.0) <= KEEP_WITHIN and lo <= p.level <= hi:
            return terms, bounds
        before = float(wn["N"])
    else:
        old = next((b for b in bounds if b["effect"] == "white_noise"), None)
        if old is None:
            return terms, bounds
        before = float(old["N"])
        bounds = [b for b in bounds if b["effect"] != "white_noise"]
        wn = {k: v for k, v in old.items() if k not in ("bound", "selected", "ci95", "std")}
        terms = [wn] + list(terms)
    new = dict(wn, N=p.level, ci95=dict(wn.get("ci95", {}), N=list(p.ci95)),
               std=dict(wn.get("std", {}), N=(p.ci95[1] - p.ci95[0]) / 3.92))
    new.pop("bound", None)
    terms = [new if t is wn else t for t in terms]
    record.clear()
    record.update(tau=list(p.tau), N_global=before, N=p.level, rule="flat")
    notes[:] = [x for x in notes if not x.startswith("N from a local weighted fit")]
    notes.append(f"N from the flat white region {p.tau[0]:.3g}-{p.tau[1]:.3g} s (ADEV*sqrt(tau) constant within "
                 f"its noise, EDF >= {MIN_EDF:.0f}), {100 * (p.level / before - 1):+.1f} % from the fitted model's N")
    return terms, bounds
