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

The fitted filter's shape is tested against the plateau (:func:`read_plateau`): the curve with the roll-off
divided out must be flat over it too. Where it is, the plateau may reach into the roll-off (down to
MIN_FILTER_SHARE of the white AVAR: a 1-pole corner at 3.3 Hz logged at 50 Hz leaves 78-89 % at 0.32-0.64 s,
where a 2014 Erle rover's curve, corrected, is flat from 0.04 s on), its interval widened over the cut-off's
interval where the roll-off was found in the data. Where it is not, the filter bends a curve the data show
flat (a 2-pole at 10.7 Hz would leave 57 % at 0.04 s of a log whose ADEV*sqrt(tau) is flat from 0.04 s): that
roll-off is not the data's there, the level is the raw one and the white-noise term is reported without it.
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
            out.append(_plateau(int(i), int(j), tau, at, edf, shape, level))
    return out


def _plateau(i, j, tau, at, edf, shape, level=0.95) -> Plateau:
    """The plateau over points i..j: the EDF-weighted mean of AVAR*tau / shape, square-rooted, and its
    ``level`` interval (module docstring)."""
    from companion.allan.confidence import adev_ci

    w = edf[i:j + 1]
    lev = math.sqrt(float(np.sum(w * at[i:j + 1] / shape[i:j + 1]) / np.sum(w)))
    e = float(np.max(w))
    (clo,), (chi,) = adev_ci([lev], [e], level)
    return Plateau(i, j, (float(tau[i]), float(tau[j])), lev, (float(clo), float(chi)), e)


def widest(found: list[Plateau]) -> Plateau | None:
    """The plateau spanning the most octaves; of equals the one at the longer cluster times (a low-pass
    roll-off rises slowly at the short end, where a short run can look flat)."""
    if not found:
        return None
    return max(found, key=lambda p: (round(math.log2(p.tau[1] / p.tau[0]), 6), p.tau[1]))


#: the least share of the white AVAR the fitted filter may leave at a plateau's points for its level to be read
#: with the roll-off divided out (deeper in the roll-off the level would be more the filter model's than the data's)
MIN_FILTER_SHARE = 0.5
#: the keys of a white-noise term that carry its low-pass filter
FILTER_KEYS = ("filter_hz", "sample_hz", "filter_order")


def filter_shape(terms: list, bounds: list, tau, filter_hz: float | None = None) -> np.ndarray:
    """The fitted filter's share of the white AVAR at each cluster time (1 without a filter): a filtered white
    curve approaches its level as 1 - c/tau, a few per cent low an octave or two above the corner, which a
    plateau read off the raw curve would take for flat. ``filter_hz``: the cut-off in place of the fitted one."""
    from companion.allan.terms import avar_term

    tau = np.asarray(tau, dtype=float)
    wn = next((t for t in list(terms) + list(bounds) if t["effect"] == "white_noise"), None)
    if wn is None or not wn.get("filter_hz"):
        return np.ones_like(tau)
    plain = {k: v for k, v in wn.items() if k not in ("ci95", "std", "bound", "selected")}
    if filter_hz:
        plain["filter_hz"] = float(filter_hz)
    bare = {k: v for k, v in plain.items() if k not in FILTER_KEYS}
    return np.clip(np.asarray(avar_term(plain, tau)) / np.asarray(avar_term(bare, tau)), 1e-12, None)


@dataclass
class Reading:
    """The white level a plateau gives and how the fitted filter's roll-off was taken."""

    plateau: Plateau  #: its level and interval, the roll-off divided out unless set aside
    aside: bool  #: the filter's shape disagrees with the flat curve: the raw level, the filter set aside
    least: float  #: the least share of the white AVAR the filter leaves at the plateau's points


def _flat_corrected(at, edf, shape, p: Plateau) -> bool:
    """Whether the curve with the filter's roll-off divided out is flat over the plateau too (the test the raw
    curve passed): a filter that bends the curve where the data show it flat is not the data's roll-off."""
    from companion.allan.special import chi2_ppf

    k = slice(p.i, p.j + 1)
    return flat_chi2(at[k] / shape[k], edf[k]) <= chi2_ppf(FLAT_LEVEL, p.j - p.i)


def _with_level(p: Plateau, level: float, lo: float, hi: float) -> Plateau:
    return Plateau(p.i, p.j, p.tau, level, (lo, hi), p.edf)


def read_plateau(tau, avar, edf, shape, filter_ci=None, shape_at=None) -> Reading | None:
    """The widest plateau of the curve (found on ADEV*sqrt(tau) as measured, every point with EDF >= MIN_EDF)
    and its white level. The fitted filter's shape is tested against it (:func:`_flat_corrected`): where the
    curve with the roll-off divided out is flat too, the level is read with it divided out (where it leaves
    at least MIN_FILTER_SHARE at every point; else no level), its interval widened to the levels at the ends
    of the cut-off's interval ``filter_ci`` (``shape_at(f_c)``: the shape at another cut-off); where it is not,
    the roll-off the filter puts there is not in the data: the raw level, the filter set aside."""
    tau, avar, edf = (np.asarray(x, dtype=float) for x in (tau, avar, edf))
    p = widest(plateaus(tau, avar, edf, shape=shape))
    if p is None:
        return None
    at = np.where(np.isfinite(avar) & (avar > 0), avar * tau, 1.0)
    least = float(np.min(shape[p.i:p.j + 1]))
    if not _flat_corrected(at, edf, shape, p):
        return Reading(_plateau(p.i, p.j, tau, at, edf, np.ones_like(tau)), True, least)
    if least < MIN_FILTER_SHARE:
        return None
    if least < 1.0 and filter_ci and shape_at is not None:
        w = edf[p.i:p.j + 1]
        ends = [math.sqrt(float(np.sum(w * at[p.i:p.j + 1] / shape_at(f)[p.i:p.j + 1]) / np.sum(w)))
                for f in filter_ci]
        lo = min(ends + [p.level]) * p.ci95[0] / p.level
        hi = max(ends + [p.level]) * p.ci95[1] / p.level
        p = _with_level(p, p.level, lo, hi)
    return Reading(p, False, least)


def flat_white_level(terms: list, bounds: list, tau, avar, edf, notes: list, record: dict, filter_ci=None):
    """N from the widest plateau of the curve (:func:`read_plateau`: its level with the fitted filter's
    roll-off divided out, or raw with the filter set aside where its shape disagrees with the flat curve)
    where the fit's N misses it (more than KEEP_WITHIN off, or its interval not covering the level) or where
    N was left as a bound: the white-noise term gets the level and its interval (and loses the filter where it
    was set aside), ``record`` (the entry's ``fit.white_refit``) the plateau's cluster times and the N it
    replaces. ``filter_ci``: the fitted cut-off's interval (a roll-off found in the data). Returns (terms,
    bounds)."""
    shape = filter_shape(terms, bounds, tau)
    reading = read_plateau(tau, avar, edf, shape, filter_ci,
                           lambda f: filter_shape(terms, bounds, tau, filter_hz=f))
    if reading is None:
        return terms, bounds
    p = reading.plateau
    wn = next((t for t in terms if t["effect"] == "white_noise"), None)
    if wn is not None:
        lo, hi = wn.get("ci95", {}).get("N", [wn["N"], wn["N"]])
        if abs(wn["N"] / p.level - 1) <= KEEP_WITHIN and lo <= p.level <= hi:
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
    if reading.aside:
        for k in FILTER_KEYS:
            new.pop(k, None)
    terms = [new if t is wn else t for t in terms]
    record.clear()
    record.update(tau=list(p.tau), N_global=before, N=p.level, rule="flat")
    if reading.aside:
        record["filter_set_aside"] = True
    notes[:] = [x for x in notes if not x.startswith("N from a local weighted fit")]
    notes.append(f"N from the flat white region {p.tau[0]:.3g}-{p.tau[1]:.3g} s (ADEV*sqrt(tau) constant within "
                 f"its noise, EDF >= {MIN_EDF:.0f}), {100 * (p.level / before - 1):+.1f} % from the fitted model's N"
                 + (f"; the low-pass roll-off set aside there: it would leave {100 * reading.least:.0f} % of the "
                    "white AVAR where the curve is flat" if reading.aside else ""))
    return terms, bounds
