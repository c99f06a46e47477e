"""Choose one explanation of a gap per step: the best by the one criterion of :mod:`companion.gap.scoring`,
then the rules between look-alikes the score alone cannot separate, applied in order (:data:`RULES`).

A gap between a model and a measurement can have several explanations that compete for the same points:
an effect the model lacks, a model term that is mis-sized, an effect plus a recalibrated term; and within
these, look-alikes (a ramp or a larger random walk for a rising long-tau end; a Gauss-Markov term or a
random walk; a sinusoid or a Gauss-Markov bump). Each is fitted from the same state and ranked by one
score (:mod:`companion.gap.ranking`). Between two explanations the difference of scores is the difference
of their deviances net of their scaled penalties: the gain is not divided by phi for the ranking, because
with a gap of thousands of deviance units a 10 % difference of phi between two directions would outweigh
any difference of fit.

The best-scoring explanation is taken when its score is positive; the runner-up that is not merely the
winner plus a further change is reported with its evidence. The rules, in the order they apply:

1. nested: a Gauss-Markov term against its one-parameter limit (tau_c -> infinity is a random walk,
   tau_c -> 0 white noise); the limit is named unless the Gauss-Markov term is significantly better than
   it (:func:`nested_test`), because the score's small cost of a shape parameter (18.4 - 15.1) is not a
   test of lambda = 1/tau_c = 0;
2. filter: a short Gauss-Markov term against the low-pass filter (:func:`filter_rule`);
3. flicker: a Gauss-Markov term against bias instability (:func:`flicker_rule`);
4. equal size: between look-alikes with the same number of parameters, the larger likelihood
   (:func:`equal_size_rule`);
5. trend: a ramp against a random walk, decided by the record with its least-squares line taken out
   (:mod:`companion.gap.ramp_or_walk`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from companion.gap import ramp_or_walk
from companion.gap.candidates import MAGNITUDE, Fit, estimate_covariance, fit_terms, gm_rw_direction, lr_inflation
from companion.gap.likelihood import Measured
from companion.gap.ranking import explanations
from companion.gap.scoring import (ALPHA, ALPHA_RECAL, FILTER_LIKE_SAMPLES, LOWPASS, NESTED, RECAL_PENALTY,
                                   SHORT_TAU_EFFECTS, Explanation, add_penalty, make_explanation)

__all__ = ["ALPHA", "ALPHA_RECAL", "FILTER_LIKE_SAMPLES", "LOWPASS", "NESTED", "RECAL_PENALTY", "SHORT_TAU_EFFECTS",
           "DetrendedRecord", "Explanation", "LimitPair", "StepChoice", "add_penalty", "choose", "equal_size_rule",
           "filter_rule", "flicker_rule", "margin", "nested_test", "runner_up"]


def nearer_limit(meas: Measured, x: Explanation) -> str | None:
    """The one-parameter limit a two-parameter effect is near: for Gauss-Markov, random walk when its
    tau_c lies in the upper half of the measured tau range (log scale), white noise in the lower half."""
    limits = NESTED.get(x.effect)
    if not limits:
        return None
    tau_c = x.fit.terms[-1]["tau_c"]
    return limits[0] if tau_c >= math.sqrt(meas.tau[0] * meas.tau[-1]) else limits[1]


@dataclass
class LimitPair:
    """A Gauss-Markov explanation and the one that replaces it by its nearer one-parameter limit."""

    gauss_markov: Explanation
    limit: Explanation
    #: index of the limit's term in ``limit.fit.terms``
    index: int


def limit_explanation(meas: Measured, state: Fit, held, x: Explanation, ranked) -> LimitPair | None:
    """The explanation that replaces Gauss-Markov ``x`` by its nearer limit, with the index of the limit's
    term in its fit: the limit added (when the model lacks it) or the model's own term of that effect
    recalibrated (when it is held), other parts of ``x`` unchanged. None when there is none."""
    limit = nearer_limit(meas, x)
    if limit is None:
        return None
    own = [j for j, t in enumerate(state.terms) if t["effect"] == limit]
    if not own:
        for y in ranked:
            if y.effect == limit and y.recal == x.recal:
                return LimitPair(x, y, len(y.fit.terms) - 1)
        return None
    j = own[0]
    if j not in held:
        return None
    recal = tuple(sorted(set(x.recal) | {j}))
    for y in ranked:
        if y.effect is None and y.recal == recal:
            return LimitPair(x, y, j)
    f = fit_terms(meas, state.terms, [i for i in held if i not in recal], intervals=False)
    return LimitPair(x, make_explanation(meas, state, held, None, recal, f, estimate_covariance(meas, state)), j)


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
    deterministic ramp over a stochastic random walk that fits better; the model's K recalibrated many
    times over a ramp that fits better). The filter and the temperature term keep their own rules."""
    if best.score <= 0 or best.effect in (LOWPASS, "temperature"):
        return best
    for y in ranked:
        if (y is not best and y.effect not in (LOWPASS, "temperature") and y.changes() != best.changes()
                and y.k == best.k and y.score > 0 and y.fit.dev < best.fit.dev):
            best = y
    return best


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
    hump between the white and random-walk lines clears by chance."""
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


@dataclass
class DetrendedRecord:
    """The record with its least-squares line taken out, for the trend rule (:mod:`companion.gap.ramp_or_walk`)."""

    meas: Measured
    #: indices of terms that are no model term and stay fixed (a rate-LSB white term)
    keep: list
    #: the segments' lengths, s
    lengths: list


@dataclass
class StepChoice:
    """What one selection step found."""

    #: every explanation left after the veto, best score first
    ranked: list
    #: the explanation the rules settled on (chosen or not)
    best: Explanation | None = None
    #: ``best`` when its score is positive, else None
    chosen: Explanation | None = None
    #: the nested test's record (Gauss-Markov against its one-parameter limit), when it decided
    nested: dict | None = None
    #: the Gauss-Markov fit a one-parameter look-alike won over
    alternative: dict | None = None
    runner_up: Explanation | None = None
    #: the trend rule's record, when a ramp and a random walk competed
    trend: dict | None = None
    #: (explanation, reason) of every explanation the record's own time series ruled out
    vetoed: list = field(default_factory=list)


@dataclass
class _Context:
    """The state one step's rules are applied in."""

    meas: Measured
    state: Fit
    held: list
    detrended: Callable[[], DetrendedRecord] | None


def _resolve(ctx: _Context, c: StepChoice, best: Explanation) -> None:
    """The nested rule for ``best``: sets the explanation to take, the nested record and the Gauss-Markov
    alternative. ``best`` is a Gauss-Markov term, or may itself be the limit of one close behind."""
    pair = None
    if best.effect in NESTED:
        pair = limit_explanation(ctx.meas, ctx.state, ctx.held, best, c.ranked)
    else:
        for y in c.ranked:
            if y.effect in NESTED and y.score > 0:
                cand = limit_explanation(ctx.meas, ctx.state, ctx.held, y, c.ranked)
                if cand is not None and cand.limit is best:
                    pair = cand
                    break
    term = pair.limit.fit.terms[pair.index] if pair is not None else None
    if term is None or term[MAGNITUDE[term["effect"]]] <= 0:
        c.best, c.nested, c.alternative = best, None, None
        return
    nt = nested_test(ctx.meas, pair.gauss_markov, pair.limit, pair.index)
    if nt["lr"] >= nt["threshold"]:
        c.best, c.nested, c.alternative = pair.gauss_markov, nt, None
        return
    if pair.limit not in c.ranked:
        c.ranked.append(pair.limit)
        c.ranked.sort(key=lambda x: -x.score)
    gm = pair.gauss_markov
    c.best, c.nested = pair.limit, nt
    c.alternative = {**{p: v for p, v in gm.fit.terms[-1].items() if p != "effect"}, "effect": gm.effect,
                     "lr": nt["lr"], "instead_of": nt["limit"]}


def _nested_step(ctx: _Context, c: StepChoice) -> None:
    _resolve(ctx, c, c.ranked[0])


def _filter_step(ctx: _Context, c: StepChoice) -> None:
    c.best = filter_rule(ctx.meas, c.best, c.ranked)


def _flicker_step(ctx: _Context, c: StepChoice) -> None:
    gm = c.best
    c.best = flicker_rule(gm, c.ranked)
    if c.best is not gm:  # the Gauss-Markov fit is reported as the alternative the flicker won over
        c.nested = None
        c.alternative = {**{p: v for p, v in gm.added_term().items() if p != "effect"},
                         "effect": gm.effect, "lr": c.best.fit.dev - gm.fit.dev, "instead_of": FLICKER}


def _equal_size_step(ctx: _Context, c: StepChoice) -> None:
    if c.nested is not None:  # the nested test decided between the look-alikes already
        return
    same = equal_size_rule(c.best, c.ranked)
    if same is not c.best and same.effect in NESTED:
        # a Gauss-Markov term that won on the larger likelihood still has to beat its one-parameter limit
        _resolve(ctx, c, same)
    else:
        c.best = same


def _trend_step(ctx: _Context, c: StepChoice) -> None:
    """Ramp or random walk: the record's own time series decides (a ramp is a line, a random walk is not),
    whichever of the two led on the Allan curve."""
    best = c.best
    other = {"ramp": "random_walk", "random_walk": "ramp"}.get(best.effect)
    if ctx.detrended is None or not other or best.score <= 0 or \
            not any(x.effect == other and x.score > 0 for x in c.ranked):
        return
    rec = ctx.detrended()
    taken, c.trend = ramp_or_walk.ramp_or_random_walk(rec.meas, best, c.ranked, rec.keep, RECAL_PENALTY, rec.lengths)
    if taken is best:
        return
    c.best = taken
    if taken.effect == "ramp":  # a Gauss-Markov fit the random walk stood for is no alternative now
        c.nested, c.alternative = None, None
    elif c.nested is None:  # the random walk may be the limit of a Gauss-Markov term close behind
        _resolve(ctx, c, taken)


#: the rules between look-alikes, in the order they apply to the best-scoring explanation
RULES = (_nested_step, _filter_step, _flicker_step, _equal_size_step, _trend_step)


def choose(meas: Measured, state: Fit, held, recalibratable, combine_top: int | None = None, shaped=(),
           lowpass=None, thermal=None, detrended=None, veto=None) -> StepChoice:
    """One step: rank all explanations (:func:`companion.gap.ranking.explanations`), apply :data:`RULES` to
    the best. ``detrended``: a callable giving the :class:`DetrendedRecord` (measured once, when a ramp and
    a random walk both pass their level). ``veto``: a callable that returns a reason (str) for an
    explanation the record's own time series rules out (a sinusoid whose line the periodogram would show
    and does not), or None; vetoed ones leave the ranking."""
    ranked = explanations(meas, state, held, recalibratable, combine_top, shaped, lowpass, thermal)
    c = StepChoice(ranked=ranked)
    if veto is not None:
        reasons = [veto(x) for x in ranked]
        c.vetoed = [(x, r) for x, r in zip(ranked, reasons) if r]
        c.ranked = [x for x, r in zip(ranked, reasons) if not r]
    if not c.ranked:
        return c
    ctx = _Context(meas, state, held, detrended)
    for rule in RULES:
        rule(ctx, c)
    if c.best.score > 0:
        c.chosen = c.best
    c.runner_up = runner_up(c.ranked, c.best)
    return c


def margin(a: Explanation, b: Explanation | None) -> float:
    """How far ``a`` scores above ``b`` (infinite when there is no ``b``)."""
    return math.inf if b is None else a.score - b.score
