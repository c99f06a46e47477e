"""The autopilot's low-pass filter on the white noise as an explanation of a gap: its cut-off read from the
log or fitted by profile likelihood (:mod:`companion.allan.filtered_white` for the filtered white AVAR)."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar

from companion.allan.filtered_white import aliasing_gain
from companion.gap.candidates import MAGNITUDE, Fit, fit_terms, lr_inflation, refine_shapes, unit_column
from companion.gap.likelihood import MODEL_FLOOR, Measured
from companion.gap.scoring import FILTER_LIKE_SAMPLES, LOWPASS, RECAL_PENALTY, Explanation, add_penalty

#: cut-offs tried when the log does not give one, as fractions of the log's rate (8 per decade), at most
#: 0.4 and only where the implied aliasing stays within the model floor (see lowpass_explanations)
LOWPASS_GRID = 10.0 ** np.arange(math.log10(0.02), math.log10(0.4) + 1e-9, 1.0 / 8.0)


def lowpass_explanations(meas: Measured, state: Fit, held, recalibratable, lowpass, shaped=(), sigma=None) -> list:
    """The low-pass filter on the state's white-noise term (:mod:`companion.allan.filtered_white`): alone (N held
    as it stands) and with N recalibrated. ``lowpass`` = (cut-off Hz or None, order[, integrate]): a cut-off from the
    log's parameters is used as it is (a known property of the data: the level of a recalibration,
    chi^2_1(1 - ALPHA_RECAL) = 10.8), else it is fitted by profile likelihood over LOWPASS_GRID x rate (the
    level of a one-parameter added effect, 15.1). Its overdispersion is taken
    in the direction the filter changes the curve (filtered minus unfiltered white column)."""
    if lowpass is None:
        return []
    fc0, order = lowpass[0], lowpass[1]
    integrate = bool(lowpass[2]) if len(lowpass) > 2 else False
    whites = [j for j, t in enumerate(state.terms) if t["effect"] == "white_noise" and not t.get("cutoff_hz")
              and t["N"] > 0]
    if not whites:
        return []
    j = whites[0]
    if any(t["effect"] == "gauss_markov" and t["tau_c"] * meas.rate_hz < FILTER_LIKE_SAMPLES and t["sigma"] > 0
           for t in state.terms):
        return []  # a filter-like Gauss-Markov term is already there: one filter, not two
    # a cut-off from the log: the autopilot's two-pole filter; a fitted one: order 1 or 2, whichever fits
    # (the sensor's own digital low-pass and averaging need not be two-pole)
    # (a free cut-off is kept where the aliasing it implies stays within the 5 % model floor in AVAR: beyond,
    # a fitted filter would raise the long-tau white level and pass for "N is right" when N is not)
    grid = [(fc0, order)] if fc0 else _cutoff_grid(meas, integrate)
    out = []
    for recal in ((), (j,)):
        if recal and j not in recalibratable:
            continue
        fixed = [i for i in held if i not in recal]
        base = [dict(t) for t in state.terms]
        if integrate:
            base[j]["integrate"] = True
        best = _profile_cutoff(meas, base, j, fixed, grid, refine=not fc0)
        if shaped:
            best = refine_shapes(meas, best.terms, fixed, shaped)
        t0 = state.terms[j]
        col = unit_column(best.terms[j], meas.tau, meas.rate_hz) - unit_column(t0, meas.tau, meas.rate_hz)
        dirs = [col * t0["N"] ** 2] + [unit_column(t0, meas.tau, meas.rate_hz) for _ in recal]
        phi = lr_inflation(meas, state, None, direction=dirs, sigma=sigma)
        # a cut-off read from the log is a known property of the data, not a searched shape: it is tested at
        # the level of a recalibration (chi^2_1(1 - ALPHA_RECAL)); a fitted cut-off at that of an added effect
        pen = (RECAL_PENALTY if fc0 else add_penalty(1)) + RECAL_PENALTY * len(recal)
        out.append(Explanation(LOWPASS, tuple(recal), best, state.dev - best.dev, phi, pen, modifies=j))
    return out


def _cutoff_grid(meas: Measured, integrate: bool) -> list:
    """(cut-off, order) pairs a fitted filter is profiled over: LOWPASS_GRID x rate, order 1 and 2, where the
    aliasing it implies stays within the model floor."""
    return [(fc, o) for o in (1, 2) for fc in LOWPASS_GRID * meas.rate_hz
            if aliasing_gain(fc, None if integrate else meas.rate_hz, o) <= 1.0 + MODEL_FLOOR]


def with_cutoff(meas: Measured, f: Fit, fixed, effect, lowpass) -> Fit:
    """A candidate fitted beside a low-pass filter whose cut-off was fitted before it: the cut-off is a shape
    the new term may compete with, re-profiled in every candidate's fit (as earlier Gauss-Markov and
    sinusoid shapes are), so that no candidate gains or loses from it against another. Held at the value
    fitted without it, the filter keeps the short-tau power it took in the new term's absence, and a line
    near the logger's Nyquist frequency scores far below its evidence."""
    if (lowpass is None or lowpass[0] or f.terms[-1][MAGNITUDE[effect]] <= 0
            or not any(t["effect"] == "white_noise" and t.get("cutoff_hz") for t in f.terms)):
        return f
    return refine_cutoff(meas, f.terms, fixed, lowpass)


def refine_cutoff(meas: Measured, terms, fixed, lowpass) -> Fit:
    """Refit with the fitted cut-off (and order) of the filtered white-noise term re-profiled over the grid
    in the current state (magnitudes free except ``fixed``): like a Gauss-Markov tau_c, a cut-off fitted
    before a later addition is no longer the maximum of the likelihood."""
    integrate = bool(lowpass[2]) if len(lowpass) > 2 else False
    js = [j for j, t in enumerate(terms) if t["effect"] == "white_noise" and t.get("cutoff_hz")]
    best = fit_terms(meas, terms, fixed, intervals=False)
    for j in js:
        f = _profile_cutoff(meas, best.terms, j, fixed, _cutoff_grid(meas, integrate))
        if f.dev < best.dev:
            best = f
    return best


def _profile_cutoff(meas: Measured, terms, j, fixed, grid, refine: bool = True) -> Fit:
    """The fit with the cut-off (and order) of the white-noise term ``j`` at its profile-likelihood maximum:
    over ``grid`` ((cut-off, order) pairs), then, like every other shape parameter, by a bounded scalar
    refinement between the best grid point's neighbours of the same order (the grid's 8 steps a decade are
    33 % apart, too coarse for the shortest cluster times' ADEV). The neighbours bound it, so the aliasing
    limit the grid keeps holds. ``refine`` False: the grid as it is (a cut-off from the log)."""
    def fit_at(fc, o):
        trial = [dict(t) for t in terms]
        trial[j].update(cutoff_hz=float(fc), order=int(o))
        return fit_terms(meas, trial, fixed, intervals=False)

    fits = [fit_at(fc, o) for fc, o in grid]
    k = int(np.argmin([f.dev for f in fits]))
    best = fits[k]
    if not refine or len(grid) < 2:
        return best
    fc, o = grid[k]
    same = sorted(g for g, oo in grid if oo == o)
    i = same.index(fc)
    lo, hi = math.log(same[max(i - 1, 0)]), math.log(same[min(i + 1, len(same) - 1)])
    if hi > lo:
        res = minimize_scalar(lambda u: fit_at(math.exp(u), o).dev, bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-3})
        f = fit_at(math.exp(float(res.x)), o)
        if f.dev < best.dev:
            best = f
    return best
