"""Weigh every explanation of a gap head to head, on the same data, by one criterion.

A gap between a model and a measurement can have several explanations that compete for the same points:
an effect the model lacks, a model term that is mis-sized, an effect plus a recalibrated term; and within
these, look-alikes (a ramp or a larger random walk for a rising long-tau end; a Gauss-Markov term or a
random walk; a sinusoid or a Gauss-Markov bump). Testing them one after another lets whichever is tested
first take the points; here each is fitted from the same state and scored by one criterion:

    score(E) = Delta D_E - phi_E penalty(E)      (= D_state - [D_E + phi_E penalty(E)])

i.e. each explanation's deviance plus its overdispersion-scaled penalty (a quasi-likelihood AIC, QAIC, with
the penalty of the documented test levels); the smallest wins.

* Delta D_E = D_state - D_E: the Gamma deviance (-2 ln L + const, :mod:`companion.gap.likelihood`) the
  explanation removes; the state is the model as it stands (model terms held at their values unless a
  previous step recalibrated them; effects added earlier free).
* phi_E >= 1: the overdispersion of that likelihood ratio (the long-tau octave estimates are correlated and
  few in EDF), :func:`companion.gap.candidates.lr_inflation` at the state fit (score-test form) in the
  directions E opens (the unit column of an added effect, of a freed model term); for two directions the
  largest Rao-Scott eigenvalue (conservative: a combination never gains from its correction).
* penalty(E) = the sum of the levels its parts must pass on their own: chi^2_k(1 - ALPHA) for an added
  effect with k parameters (15.1, 18.4), chi^2_1(1 - ALPHA_RECAL) = 10.8 per recalibrated term.

A positive score is the same statement as "the corrected likelihood ratio LR = Delta D_E / phi_E exceeds
the documented level", so taking the best explanation only when its score is positive keeps every test's
level. Between two explanations the difference of scores is the difference of their deviances net of
their scaled penalties: the gain is not divided by phi for the ranking, because with a gap of thousands of
deviance units a 10 % difference of phi between two directions would outweigh any difference of fit
(measured: a hidden white noise lost to a sinusoid that fits 4 % worse).

The best-scoring explanation is taken when its score is positive; the runner-up that is not merely the
winner plus a further change is reported with its evidence (``alternatives``). A recalibration taken as
the rider of a combination is weighed once more at the end against every effect, from the state with that
term held (the workflow's swap step): a ramp hidden beside a Gauss-Markov term was otherwise absorbed by
"gauss_markov + random_walk K recalibrated".
One refinement keeps the
nested rule of a two-parameter effect against its one-parameter limit (Gauss-Markov with tau_c -> infinity
is a random walk, tau_c -> 0 white noise): the limit is named unless the Gauss-Markov term is
significantly better than it (:func:`nested_test`), because the score's small cost of a shape parameter
(18.4 - 15.1) is not a test of lambda = 1/tau_c = 0. A second keeps a ramp and a random walk apart where
the Allan curve cannot: when both pass their level, whichever leads, the one whose prediction of the
record with its least-squares line taken out is the likelier is taken (:mod:`companion.gap.trend`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.optimize import minimize_scalar

from companion.allan.filtered_white import aliasing_gain
from companion.gap.candidates import (MAGNITUDE, N_PARAMS, SHAPE, Fit, estimate_covariance, fit_terms,
                                      fit_with_candidate, gm_rw_direction, lr_inflation, refine_shapes,
                                      unit_column)
from companion.gap import trend
from companion.gap.likelihood import MODEL_FLOOR, Measured

#: level an added effect must pass (its score's penalty is chi^2_k(1 - ALPHA))
ALPHA = 1e-4
#: level a recalibrated model term must pass (penalty chi^2_1(1 - ALPHA_RECAL) = 10.8)
ALPHA_RECAL = 1e-3
#: one-parameter limits of two-parameter effects (Gauss-Markov: tau_c >> T is a rate random walk,
#: tau_c << tau0 white noise; IEEE 952 C.6)
NESTED = {"gauss_markov": ("random_walk", "white_noise")}


#: the autopilot's low-pass filter (and the aliasing of the logger's decimation) on the white noise
LOWPASS = "lowpass"
#: cut-offs tried when the log does not give one, as fractions of the log's rate (8 per decade), at most
#: 0.4 and only where the implied aliasing stays within the model floor (see lowpass_explanations)
LOWPASS_GRID = 10.0 ** np.arange(math.log10(0.02), math.log10(0.4) + 1e-9, 1.0 / 8.0)


def add_penalty(k: int) -> float:
    return float(stats.chi2.isf(ALPHA, max(k, 1)))


RECAL_PENALTY = float(stats.chi2.isf(ALPHA_RECAL, 1))


@dataclass
class Explanation:
    """One explanation of the gap, fitted from the state: ``effect`` added (or None) and the model terms
    ``recal`` freed (recalibrated)."""

    effect: str | None
    recal: tuple
    fit: Fit
    delta_dev: float
    inflation: float
    penalty: float
    #: for "lowpass": the index of the white_noise term the filter is put on (no term is appended)
    modifies: int | None = None

    @property
    def lr(self) -> float:
        return self.delta_dev / self.inflation

    @property
    def score(self) -> float:
        return self.delta_dev - self.inflation * self.penalty

    @property
    def k(self) -> int:
        return (N_PARAMS.get(self.effect, 1) if self.effect else 0) + len(self.recal)

    def added_term(self) -> dict | None:
        """The term the explanation adds (for "lowpass": the filtered white-noise term)."""
        if not self.effect:
            return None
        return self.fit.terms[self.modifies] if self.modifies is not None else self.fit.terms[-1]

    def changes(self) -> set:
        return ({("add", self.effect)} if self.effect else set()) | {("recal", j) for j in self.recal}

    def label(self, model_terms) -> str:
        parts = [self.effect] if self.effect else []
        for j in self.recal:
            t = model_terms[j]
            parts.append(f"recalibrated {t['effect']} {MAGNITUDE[t['effect']]}")
        return " + ".join(parts)

    def as_dict(self, model_terms) -> dict:
        d = {"explanation": self.label(model_terms), "effect": self.effect,
             "recalibrate": [f"{model_terms[j]['effect']}.{MAGNITUDE[model_terms[j]['effect']]}" for j in self.recal],
             "k": self.k, "delta_dev": self.delta_dev, "inflation": self.inflation, "lr": self.lr,
             "penalty": self.penalty, "score": self.score, "gap": self.fit.gap}
        if self.effect == "temperature":
            t = self.added_term()
            d["params"] = {"coef": t["coef"]}
        elif self.effect == LOWPASS:
            t = self.added_term()
            d["params"] = {"cutoff_hz": t["cutoff_hz"], "order": t.get("order", 2), "N": t["N"]}
        elif self.effect:
            d["params"] = {p: v for p, v in self.fit.terms[-1].items() if p != "effect"}
        if self.recal:
            d["recalibrated"] = {f"{model_terms[j]['effect']}.{MAGNITUDE[model_terms[j]['effect']]}":
                                 {"model": model_terms[j][MAGNITUDE[model_terms[j]['effect']]],
                                  "fitted": self.fit.terms[j][MAGNITUDE[model_terms[j]['effect']]]}
                                 for j in self.recal}
        return d


def candidate_effects(terms) -> list[str]:
    """Effects that can be added: those the model lacks, and Gauss-Markov / sinusoid also a second time."""
    present = {t["effect"] for t in terms}
    return [e for e in MAGNITUDE if (e not in present or e in SHAPE) and e != "temperature"]


def _explanation(meas, state: Fit, held, effect, recal, fit, sigma=None) -> Explanation:
    dirs = []
    if effect:
        dirs.append(unit_column(fit.terms[-1], meas.tau, meas.rate_hz))
    for j in recal:
        dirs.append(unit_column(state.terms[j], meas.tau, meas.rate_hz))
    phi = lr_inflation(meas, state, None, direction=dirs, sigma=sigma)
    pen = (add_penalty(N_PARAMS[effect]) if effect else 0.0) + RECAL_PENALTY * len(recal)
    return Explanation(effect, tuple(recal), fit, state.dev - fit.dev, phi, pen)


def line_explanations(meas: Measured, state: Fit, held, shaped=(), lowpass=None, sigma=None) -> list:
    """A sinusoid at each line the periodogram shows (``meas.lines``), at the periodogram's frequency, its
    amplitude fitted on the Allan curve like every candidate's. The frequency searched on the Allan curve
    alone can miss such a line: near the Nyquist frequency its profile is flat (the line is seen at tau0
    only) and the search's grid stops at 0.45 x rate. A line whose periodogram amplitude holds at least half
    the fitted one (:data:`companion.gap.spectral.MIN_AMPLITUDE_SHARE`) has a known frequency and is
    weighed at that level, chi^2_1(1 - ALPHA_RECAL) = 10.8, as a confirmed line is
    (:func:`companion.gap.workflow._spectral_line`); otherwise at a searched one's, chi^2_2(1 - ALPHA)."""
    from companion.gap.spectral import MIN_AMPLITUDE_SHARE

    out = []
    for f_line, amp_psd in meas.lines:
        if any(t["effect"] == "sinusoid" and abs(t["freq_hz"] - f_line) <= 1e-9 * f_line for t in state.terms):
            continue
        f = fit_terms(meas, list(state.terms) + [{"effect": "sinusoid", "amplitude": 1.0, "freq_hz": f_line}], held,
                      intervals=False)
        if shaped and f.terms[-1]["amplitude"] > 0:
            f = refine_shapes(meas, f.terms, held, shaped)
        f = _with_cutoff(meas, f, held, "sinusoid", lowpass)
        a = f.terms[-1]["amplitude"]
        if a <= 0:
            continue
        x = _explanation(meas, state, held, "sinusoid", (), f, sigma)
        if amp_psd >= MIN_AMPLITUDE_SHARE * a:
            x.penalty = RECAL_PENALTY
        out.append(x)
    return out


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


#: effects with power at the shortest cluster times, where a fitted low-pass cut-off acts
SHORT_TAU_EFFECTS = ("quantization", "gauss_markov", "sinusoid")


def _with_cutoff(meas: Measured, f: Fit, fixed, effect, lowpass) -> Fit:
    """A candidate fitted beside a low-pass filter whose cut-off was fitted before it: the cut-off is a shape
    the new term may compete with, re-profiled in every candidate's fit (as earlier Gauss-Markov and
    sinusoid shapes are), so that no candidate gains or loses from it against another. Held at the value
    fitted without it, the filter keeps the short-tau power it took in the new term's absence (a 116 Hz line
    on a PX4 log scored LR 8 against a first-order 72 Hz cut-off, 33 with the cut-off refitted to 48 Hz
    beside it)."""
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
    33 % apart; held at the 37.3 Hz grid point, a PX4 log's first-order cut-off left its shortest cluster
    time 1.10x the model in ADEV, refined to 44.6 Hz 1.03x). The neighbours bound it, so the aliasing limit
    the grid keeps holds. ``refine`` False: the grid
    as it is (a cut-off from the log)."""
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


def explanations(meas: Measured, state: Fit, held, recalibratable, combine_top: int | None = None,
                 shaped=(), lowpass=None, thermal=None) -> list:
    """Fit every explanation from ``state`` (terms with the indices ``held`` fixed): each candidate effect
    added; each term of ``recalibratable`` (held model terms) freed; each effect added with one term freed.
    ``combine_top`` limits the combinations to the best-scoring effects alone (None: all). A recalibration
    re-optimises the shapes of the added terms ``shaped`` (:func:`companion.gap.candidates.refine_shapes`).
    Sorted by score, best first."""
    terms = state.terms
    held = sorted(set(held))
    sigma = estimate_covariance(meas, state)  # every explanation is corrected at the same state fit
    out = []
    fits = {}
    for e in candidate_effects(terms):
        f = fit_with_candidate(meas, terms, held, e)
        if shaped and f.terms[-1][MAGNITUDE[e]] > 0:  # earlier shapes re-optimised beside the new term
            f = refine_shapes(meas, f.terms, held, shaped)
        f = _with_cutoff(meas, f, held, e, lowpass)
        fits[e] = f
        if f.terms[-1][MAGNITUDE[e]] > 0:
            out.append(_explanation(meas, state, held, e, (), f, sigma))
    out += line_explanations(meas, state, held, shaped, lowpass, sigma)
    for j in recalibratable:
        f = refine_shapes(meas, terms, [i for i in held if i != j], shaped)
        out.append(_explanation(meas, state, held, None, (j,), f, sigma))
    out += lowpass_explanations(meas, state, held, recalibratable, lowpass, shaped, sigma)
    if thermal is not None and not any(t["effect"] == "temperature" for t in terms):
        f = fit_terms(meas, list(terms) + [dict(thermal)], held, intervals=False)
        if shaped:
            f = refine_shapes(meas, f.terms, held, shaped)
        if f.terms[-1]["coef"] > 0:
            out.append(_explanation(meas, state, held, "temperature", (), f, sigma))
    effects = [x.effect for x in sorted((x for x in out if x.effect and x.effect not in (LOWPASS, "temperature")),
                                        key=lambda x: -x.score)]
    if combine_top is not None:
        effects = effects[:combine_top]
    for e in effects:
        q = SHAPE.get(e)
        for j in recalibratable:
            fixed = [i for i in held if i != j]
            f = fit_with_candidate(meas, terms, fixed, e, near=fits[e].terms[-1][q] if q else None)
            f = _with_cutoff(meas, f, fixed, e, lowpass)
            if f.terms[-1][MAGNITUDE[e]] > 0:
                out.append(_explanation(meas, state, held, e, (j,), f, sigma))
    if any(t["effect"] == "white_noise" and t.get("cutoff_hz") for t in terms):
        # the low-pass filter is already in the model: a Gauss-Markov term at the filter's time scale would
        # describe the same roll-off twice
        out = [x for x in out if not (x.effect == "gauss_markov" and
                                      x.added_term()["tau_c"] * meas.rate_hz < FILTER_LIKE_SAMPLES)]
    out.sort(key=lambda x: -x.score)
    return out


def nearer_limit(meas: Measured, x: Explanation) -> str | None:
    """The one-parameter limit a two-parameter effect is near: for Gauss-Markov, random walk when its
    tau_c lies in the upper half of the measured tau range (log scale), white noise in the lower half."""
    limits = NESTED.get(x.effect)
    if not limits:
        return None
    tau_c = x.fit.terms[-1]["tau_c"]
    return limits[0] if tau_c >= math.sqrt(meas.tau[0] * meas.tau[-1]) else limits[1]


def limit_explanation(meas: Measured, state: Fit, held, x: Explanation, ranked) -> tuple:
    """The explanation that replaces Gauss-Markov ``x`` by its nearer limit, with the index of the limit's
    term in its fit: the limit added (when the model lacks it) or the model's own term of that effect
    recalibrated (when it is held), other parts of ``x`` unchanged. (None, None) when there is none."""
    limit = nearer_limit(meas, x)
    if limit is None:
        return None, None
    own = [j for j, t in enumerate(state.terms) if t["effect"] == limit]
    if not own:
        for y in ranked:
            if y.effect == limit and y.recal == x.recal:
                return y, len(y.fit.terms) - 1
        return None, None
    j = own[0]
    if j not in held:
        return None, None
    recal = tuple(sorted(set(x.recal) | {j}))
    for y in ranked:
        if y.effect is None and y.recal == recal:
            return y, j
    f = fit_terms(meas, state.terms, [i for i in held if i not in recal], intervals=False)
    return _explanation(meas, state, held, None, recal, f, estimate_covariance(meas, state)), j


def nested_test(meas: Measured, best: Explanation, limit: Explanation, i: int) -> dict:
    """Is the Gauss-Markov explanation ``best`` significantly better than ``limit`` (its term ``i`` the
    one-parameter limit)?

    Likelihood ratio LR = D_limit - D_best. Against a random walk (lambda = 1/tau_c -> 0) the long-tau
    estimates that carry the difference are correlated and few in EDF, so the LR is divided by the sandwich
    factor in the direction :func:`companion.gap.candidates.gm_rw_direction` and compared with
    chi^2_1(1 - ALPHA_RECAL) = 10.8 (64 random-walk draws, 2 h at 20 Hz: raw up to 20.3, corrected up to
    7.2). Against white noise the raw LR is compared with chi^2_1(1 - ALPHA) = 15.1."""
    lr_raw = limit.fit.dev - best.fit.dev
    effect = limit.fit.terms[i]["effect"]
    if effect == "random_walk" and limit.fit.terms[i]["K"] > 0:
        phi = lr_inflation(meas, limit.fit, i, direction=gm_rw_direction(meas, limit.fit.terms[i]["K"]))
        threshold = RECAL_PENALTY
    else:
        phi, threshold = 1.0, add_penalty(1)
    return {"limit": effect, "lr": lr_raw / phi, "lr_raw": lr_raw, "inflation": phi, "threshold": threshold}


def equal_size_rule(best: Explanation, ranked) -> Explanation:
    """Between look-alikes of the same size (the same number of free parameters: a ramp or a random walk, a
    sinusoid or a Gauss-Markov term, a ramp or the model's random walk K recalibrated) that both pass their
    level, the one with the larger likelihood wins. The overdispersion factor scales each one's evidence
    against the state (its test), and the level of a recalibration (10.8) is below that of an added effect
    (15.1) because a model term is already there; but between two explanations with the same number of
    parameters, once both pass, either difference would only favour the one that fits worse (a
    deterministic ramp over a stochastic random walk that fits better: the hidden random walk named a ramp;
    the model's K recalibrated 7-16x over the ramp that fits better: the hidden ramp absorbed). The filter
    and the temperature term keep their own rules."""
    if best.score <= 0 or best.effect in (LOWPASS, "temperature"):
        return best
    for y in ranked:
        if (y is not best and y.effect not in (LOWPASS, "temperature") and y.changes() != best.changes()
                and y.k == best.k and y.score > 0 and y.fit.dev < best.fit.dev):
            best = y
    return best


#: a Gauss-Markov term with tau_c below this many samples is the look-alike of a low-pass filter
FILTER_LIKE_SAMPLES = 10.0


def filter_rule(meas: Measured, best: Explanation, ranked) -> Explanation:
    """A short-tau Gauss-Markov term and a low-pass filter on the white noise look alike at the shortest
    cluster times (both roll the white line off). When the winner is a Gauss-Markov term with tau_c below
    FILTER_LIKE_SAMPLES samples and the filter explanation with the same recalibrations also passes its
    level, the filter (one parameter, a known property of autopilot logs) is taken unless the Gauss-Markov
    term fits better by more than chi^2_1(1 - ALPHA_RECAL) = 10.8 (its extra parameter's level)."""
    if best.effect != "gauss_markov" or best.added_term()["tau_c"] * meas.rate_hz >= FILTER_LIKE_SAMPLES:
        return best
    lp = next((x for x in ranked if x.effect == LOWPASS and x.recal == best.recal), None)
    if lp is None or lp.score <= 0 or lp.fit.dev - best.fit.dev > RECAL_PENALTY:
        return best
    return lp


#: the one-parameter look-alike of a Gauss-Markov bump where the model lacks it: flicker noise is a sum of
#: first-order Gauss-Markov processes with spread correlation times (IEEE 952 C.4), so one such process
#: fitted to a limited flat stretch of the Allan curve can match it about as well
FLICKER = "bias_instability"


def flicker_rule(best: Explanation, ranked) -> Explanation:
    """A Gauss-Markov winner whose one-parameter look-alike, bias instability added with the same
    recalibrations, also passes its level gives way to it unless the Gauss-Markov term fits better by
    more than chi^2_1(1 - ALPHA_RECAL) = 10.8, its extra parameter's level (as in the filter rule and the
    nested rule): the QAIC ranking charges the shape parameter only 18.4 - 15.1 = 3.3, which a flicker's
    hump between the white and random-walk lines clears by chance (a hidden bias instability named a
    Gauss-Markov term of tau_c 17 s that fitted 5.3 deviance units better)."""
    if best.effect != "gauss_markov":
        return best
    bi = next((x for x in ranked if x.effect == FLICKER and x.recal == best.recal), None)
    if bi is None or bi.score <= 0 or bi.fit.dev - best.fit.dev > RECAL_PENALTY:
        return best
    return bi


def runner_up(ranked, chosen: Explanation):
    """The best explanation other than ``chosen`` that is not ``chosen`` plus further changes."""
    c = chosen.changes()
    for y in ranked:
        if y is chosen or c <= y.changes():
            continue
        return y
    return None


def choose(meas: Measured, state: Fit, held, recalibratable, combine_top: int | None = None, shaped=(),
           lowpass=None, thermal=None, detrended=None, veto=None) -> dict:
    """One step: rank all explanations, apply the nested rule, return
    {ranked, chosen (Explanation or None), best (top of the ranking, chosen or not), nested, alternative
    (Gauss-Markov fit the limit won over), runner_up, trend}. ``detrended``: a callable giving the Allan
    variance of the record with its least-squares line taken out (:mod:`companion.gap.trend`), the
    indices of the terms that are no model term and stay fixed (a rate-LSB white term) and the segments'
    lengths (s): when a ramp and a random walk both pass their level, whichever leads, the detrended record
    decides between them (``trend``: that test's record). ``veto``: a callable that returns a reason (str)
    for an explanation the record's own time series rules out (a sinusoid whose line the periodogram
    would show and does not), or None; vetoed ones leave the ranking (``vetoed``: (explanation, reason))."""
    ranked = explanations(meas, state, held, recalibratable, combine_top, shaped, lowpass, thermal)
    vetoed = []
    if veto is not None:
        reasons = [veto(x) for x in ranked]
        vetoed = [(x, r) for x, r in zip(ranked, reasons) if r]
        ranked = [x for x, r in zip(ranked, reasons) if not r]
    out = {"ranked": ranked, "chosen": None, "best": ranked[0] if ranked else None, "nested": None,
           "alternative": None, "runner_up": None, "trend": None, "vetoed": vetoed}
    if not ranked:
        return out
    def resolve(best):
        """The nested rule for ``best``: (explanation to take, nested record, Gauss-Markov alternative)."""
        gm, lim, i = None, None, None
        if best.effect in NESTED:
            gm = best
            lim, i = limit_explanation(meas, state, held, best, ranked)
        else:  # the winner may itself be the limit of a Gauss-Markov explanation close behind
            for y in ranked:
                if y.effect in NESTED and y.score > 0:
                    cand, ci = limit_explanation(meas, state, held, y, ranked)
                    if cand is best:
                        gm, lim, i = y, cand, ci
                        break
        if lim is None or lim.fit.terms[i][MAGNITUDE[lim.fit.terms[i]["effect"]]] <= 0:
            return best, None, None
        nt = nested_test(meas, gm, lim, i)
        if nt["lr"] >= nt["threshold"]:
            return gm, nt, None
        if lim not in ranked:
            ranked.append(lim)
            ranked.sort(key=lambda x: -x.score)
        alt = {**{p: v for p, v in gm.fit.terms[-1].items() if p != "effect"}, "effect": gm.effect, "lr": nt["lr"],
               "instead_of": nt["limit"]}
        return lim, nt, alt

    best, out["nested"], out["alternative"] = resolve(ranked[0])
    best = filter_rule(meas, best, ranked)
    gm, best = best, flicker_rule(best, ranked)
    if best is not gm:  # the Gauss-Markov fit is reported as the alternative the flicker won over
        out["nested"] = None
        out["alternative"] = {**{p: v for p, v in gm.added_term().items() if p != "effect"},
                              "effect": gm.effect, "lr": best.fit.dev - gm.fit.dev, "instead_of": FLICKER}
    if out["nested"] is None:
        same = equal_size_rule(best, ranked)
        if same is not best and same.effect in NESTED:
            # a Gauss-Markov term that won on the larger likelihood still has to beat its one-parameter limit
            same, out["nested"], out["alternative"] = resolve(same)
        best = same
    other = {"ramp": "random_walk", "random_walk": "ramp"}.get(best.effect)
    if detrended is not None and other and best.score > 0 and \
            any(x.effect == other and x.score > 0 for x in ranked):
        # ramp or random walk: the record's own time series decides (a ramp is a line, a random walk is not),
        # whichever of the two led on the Allan curve
        meas_d, keep, lengths = detrended()
        taken, out["trend"] = trend.ramp_or_random_walk(meas_d, best, ranked, keep, RECAL_PENALTY, lengths)
        if taken is not best:
            best = taken
            if taken.effect == "ramp":  # a Gauss-Markov fit the random walk stood for is no alternative now
                out["nested"], out["alternative"] = None, None
            elif out["nested"] is None:  # the random walk may be the limit of a Gauss-Markov term close behind
                best, out["nested"], out["alternative"] = resolve(best)
    out["best"] = best
    if best.score > 0:
        out["chosen"] = best
    out["runner_up"] = runner_up(ranked, best)
    return out


def evidence(x: Explanation | None, model_terms) -> dict | None:
    return None if x is None else x.as_dict(model_terms)


def margin(a: Explanation, b: Explanation | None) -> float:
    return math.inf if b is None else a.score - b.score


def summary_line(x: Explanation, model_terms) -> str:
    return (f"{x.label(model_terms)}: dD {x.delta_dev:.1f} - overdispersion {x.inflation:.2f} x penalty "
            f"{x.penalty:.1f} = score {x.score:.1f} (LR {x.lr:.1f})")

