"""Ramp or random walk: the record's own time series decides what the Allan curve cannot.

A rate ramp R t and a rate random walk K W(t) both make the long-tau Allan variance rise (R^2 tau^2 / 2,
slope +1 in ADEV; K^2 tau / 3, slope +1/2), and over the last octaves of a finite record the two curves
can be fitted about equally well (a ramp over one record is one realisation of a random walk). The Allan
variance keeps only the mean square of the differences of cluster means; the time series keeps their
sign. A ramp is a deterministic straight line in the rate: take the least-squares line out of the record
and its Allan variance falls to that of the noise under it. A random walk's increments are independent:
the fitted line takes only a share of about 1.2 tau / T of its Allan variance (the slope of a least-squares
line through a Brownian path has variance 6 K^2 / (5 T)), and the rest stays in the residuals.

So the test, asked whenever a ramp and a random walk both pass their level on the Allan curve (whichever of
the two leads the ranking): each explanation predicts the Allan variance of the detrended record (one
slope, an intercept per segment). The ramp says nothing of the rise is left; the random walk of the Allan
fit (its K) says its detrended share is left, K^2 tau / 3 - tau cov(Dx, slope) + tau^2 var(slope) / 2
(:func:`detrended_walk_avar`, exact in continuous time; K^2 tau / 3 (1 - 1.2 tau / T) at short tau).
Each prediction's deviance on the detrended record (the terms under the rise with their magnitudes free:
the question is the form of the rise, not the model's sizes; a held mis-sized flicker term could otherwise
hide a random walk or fake one)
is added to the explanation's own on the raw record (deviance + penalty), and the smaller total wins: the
larger likelihood, the rule between look-alikes of the same size. Both explanations make a definite
prediction, so the rule is symmetric: no default, no threshold (a threshold on "a random walk is left"
alone cannot name a ramp where the random walk won the Allan ranking, since a weak, straight-running walk
also leaves little; the prediction says how much a walk of that K should leave). The free random walk of
the detrended record (its corrected LR and K) is reported beside it.
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


def detrended_walk_avar(K: float, tau, lengths_s) -> np.ndarray:
    """Expected overlapping AVAR of a rate random walk K after :func:`detrend` (one common slope, an intercept
    per segment of ``lengths_s`` seconds), in continuous time. With Dx the difference of adjacent cluster
    means and b the fitted slope, the residual's difference is Dx - b tau, so
    AVAR = (E[Dx^2] - 2 tau E[Dx b] + tau^2 E[b^2]) / 2, averaged over the cluster positions. For Brownian
    W on a segment of length T: b = sum_s n_s / den, n_s = int (t - T/2) W dt (only the segment's own
    increments enter), den = sum_s T_s^3 / 12, var(n_s) = K^2 T_s^5 / 120, cov(W(s), n) = K^2 g(s) with
    g(s) = T s^2 / 4 - s^3 / 6, whose double integral H(s) = T s^4 / 48 - s^5 / 120 gives cov(Dx, n) averaged
    over the positions u in [0, T - 2 tau] in closed form. Short tau: K^2 tau / 3 (1 - 1.2 tau / T)."""
    tau = np.asarray(tau, dtype=float)[:, None]
    T = np.asarray([float(x) for x in lengths_s if x > 0], dtype=float)[None, :]
    den = float(np.sum(T ** 3)) / 12.0
    var_b = float(np.sum(T ** 5)) / 120.0 / den ** 2

    def H(s):
        return T * s ** 4 / 48.0 - s ** 5 / 120.0

    L = np.maximum(T - 2.0 * tau, 0.0)  # cluster positions per segment (the pooling weights)
    with np.errstate(invalid="ignore", divide="ignore"):
        cov_n = (H(T) - H(2 * tau) - 2.0 * (H(L + tau) - H(tau)) + H(L)) / (tau * L)
    cov_n = np.where(L > 0, cov_n, 0.0)
    cross = (L * cov_n).sum(axis=1) / np.maximum(L.sum(axis=1), 1e-300) / den
    t1 = tau[:, 0]
    out = t1 / 3.0 - t1 * cross + 0.5 * t1 ** 2 * var_b
    return K ** 2 * np.maximum(out, 0.0)


def detrended_deviance(meas_d: Measured, terms, fixed, extra=None) -> float:
    """Deviance of the detrended record under ``terms`` (magnitudes free except ``fixed``) plus the fixed
    AVAR ``extra`` (a prediction with no free parameter)."""
    from companion.gap.candidates import _assemble, fit_magnitudes

    A, s_fixed, _ = _assemble(meas_d, [dict(t) for t in terms], sorted(set(fixed)))
    if extra is not None:
        s_fixed = s_fixed + np.asarray(extra, dtype=float)
    return float(fit_magnitudes(meas_d, A, s_fixed)[2])


def ramp_or_random_walk(meas_d: Measured, best, ranked, fixed, level: float, lengths_s):
    """The rule between a ramp and a random walk that both pass their level (the Explanation objects of
    :mod:`companion.gap.selection`), whichever leads: the one whose prediction of the detrended record,
    added to its own evidence on the raw record, has the larger likelihood. ``fixed``: indices of terms
    that are no model term (a rate-LSB white term): they stay fixed, every other magnitude is free;
    ``lengths_s``: the segments' lengths. ``level``: the level the free random walk of the detrended record
    is reported against. Returns (explanation to take, record or None)."""
    if best.effect not in ("ramp", "random_walk") or best.score <= 0:
        return best, None
    other = "random_walk" if best.effect == "ramp" else "ramp"
    comp = next((x for x in ranked if x.effect == other and x.score > 0), None)
    if comp is None:
        return best, None
    ramp, rw = (best, comp) if best.effect == "ramp" else (comp, best)
    base = ramp.fit.terms[:-1]
    K = rw.fit.terms[-1]["K"]
    d_line = detrended_deviance(meas_d, base, fixed)
    d_walk = detrended_deviance(meas_d, base, fixed, detrended_walk_avar(K, meas_d.tau, lengths_s))
    raw_ramp = ramp.fit.dev + ramp.penalty
    raw_rw = rw.fit.dev + rw.penalty
    evidence = (raw_ramp + d_line) - (raw_rw + d_walk)  # > 0: the random walk is the likelier
    ev = residual_random_walk(meas_d, base, fixed)
    named = "random_walk" if evidence > 0 else "ramp"
    rec = {"ramp_score": ramp.score, "random_walk_score": rw.score, "led": best.effect,
           "raw": raw_rw - raw_ramp, "dev_line": d_line, "dev_walk": d_walk, "K_walk": K,
           "evidence": evidence, "lr": ev["lr"], "lr_raw": ev["lr_raw"], "inflation": ev["inflation"],
           "K_detrended": ev["K"], "threshold": level, "named": named}
    return (rw if named == "random_walk" else ramp), rec
