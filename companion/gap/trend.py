"""Ramp or random walk: the record's own time series decides what the Allan curve cannot.

A rate ramp R t and a rate random walk K W(t) both make the long-tau Allan variance rise (R^2 tau^2 / 2,
slope +1 in ADEV; K^2 tau / 3, slope +1/2), and over the last octaves of a finite record the two curves
can be fitted about equally well (a ramp over one record is one realisation of a random walk). The Allan
variance keeps only the mean square of the differences of cluster means; the time series keeps their
sign. A ramp is a deterministic straight line in the rate: take the least-squares line out of the record
and its Allan variance falls to that of the noise under it. A random walk's increments are independent:
the fitted line takes only a share of about 1.2 tau / T of its Allan variance (the slope of a least-squares
line through a Brownian path has variance 6 K^2 / (5 T)), and the rest stays in the residuals.

So the test: measure the Allan variance of the detrended record (one slope, an intercept per segment) and
ask, with the workflow's likelihood and overdispersion, whether it still needs a random walk beside the
terms the ramp explanation keeps, those terms' magnitudes free (the question is the form of the rise, not
the model's sizes: a model term held mis-sized could otherwise hide a random walk, or fake one). It is
asked only when a ramp wins and an explanation that adds a random walk also passes its level, i.e. between
two explanations the Allan curve accepts. The random walk is taken when the detrended record still holds
one at chi^2_1(1 - 1e-3) = 10.8 (the level of the workflow's other choices between look-alikes, e.g. a
Gauss-Markov term against its random-walk limit); otherwise the ramp stays. The asymmetry is the physics:
a MEMS gyro has a rate random walk, a straight ramp over a still record is a special case (a warm-up), so
the ramp is named when the record shows it is a line, and the random walk when it does not.
"""

from __future__ import annotations

import numpy as np

from companion.gap.candidates import fit_terms, fit_with_candidate, lr_inflation, unit_column
from companion.gap.likelihood import Measured


def detrend(segments, rate_hz: float) -> list:
    """The segments with one least-squares slope (common to all) and one intercept per segment removed."""
    segs = [np.asarray(s, dtype=float) for s in segments]
    num = den = 0.0
    parts = []
    for s in segs:
        t = np.arange(s.shape[0]) / rate_hz
        tc = t - t.mean()
        yc = s - s.mean()
        num += float(tc @ yc)
        den += float(tc @ tc)
        parts.append((tc, yc))
    slope = num / den if den > 0 else 0.0
    return [yc - slope * tc for tc, yc in parts]


def detrended_measure(segments, rate_hz: float) -> Measured:
    """The Allan variance (with EDF) of the record with its least-squares line taken out."""
    from companion.gap.compare import measure, measure_pooled

    res = detrend(segments, rate_hz)
    return measure_pooled(res, rate_hz) if len(res) > 1 else measure(res[0], rate_hz)


def residual_random_walk(meas_d: Measured, terms, fixed) -> dict:
    """Evidence for a random walk in the detrended record beyond ``terms`` (magnitudes free except
    ``fixed``): the model's random-walk term freed when it has one (and it is held), else a random walk
    added. Returns {lr (corrected), lr_raw, inflation, K}."""
    terms = [dict(t) for t in terms]
    fixed = sorted(set(fixed))
    base = fit_terms(meas_d, terms, fixed, intervals=False)
    own = [j for j, t in enumerate(terms) if t["effect"] == "random_walk"]
    if own:
        j = own[0]
        if j not in fixed:
            return {"lr": 0.0, "lr_raw": 0.0, "inflation": 1.0, "K": terms[j]["K"]}
        alt = fit_terms(meas_d, terms, [i for i in fixed if i != j], intervals=False)
        col = unit_column(terms[j], meas_d.tau, meas_d.rate_hz)
        K = alt.terms[j]["K"]
    else:
        alt = fit_with_candidate(meas_d, terms, fixed, "random_walk")
        col = unit_column(alt.terms[-1], meas_d.tau, meas_d.rate_hz)
        K = alt.terms[-1]["K"]
    lr_raw = max(base.dev - alt.dev, 0.0)
    phi = lr_inflation(meas_d, base, None, direction=[col])
    return {"lr": lr_raw / phi, "lr_raw": lr_raw, "inflation": phi, "K": K}


def ramp_or_random_walk(meas_d: Measured, best, ranked, fixed, level: float):
    """The rule between a winning ramp and a random walk that also passes its level (the Explanation objects
    of :mod:`companion.gap.selection`). ``fixed``: indices of terms that are no model term (a rate-LSB white
    term): they stay fixed in the test, every other magnitude is free. Returns (explanation to take, record
    or None)."""
    if best.effect != "ramp" or best.score <= 0:
        return best, None
    rw = next((x for x in ranked if x.effect == "random_walk" and x.score > 0), None)
    if rw is None:
        return best, None
    ev = residual_random_walk(meas_d, best.fit.terms[:-1], fixed)
    rec = {"ramp_score": best.score, "random_walk_score": rw.score, "lr": ev["lr"], "lr_raw": ev["lr_raw"],
           "inflation": ev["inflation"], "K_detrended": ev["K"], "threshold": level,
           "named": "random_walk" if ev["lr"] > level else "ramp"}
    return (rw if ev["lr"] > level else best), rec
