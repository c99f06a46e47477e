"""Backward steps of the gap workflow: an effect or a recalibration that later steps made unnecessary is
taken back (the level it passed when it was taken, corrected for overdispersion), and a fitted low-pass
filter is weighed again against a short Gauss-Markov term in the final state."""

from __future__ import annotations

from typing import NamedTuple

from companion.gap import selection
from companion.gap.candidates import (MAGNITUDE, SHAPE, Fit, _intervals, fit_terms, lr_inflation, refine_shapes,
                                      unit_column)
from companion.gap.likelihood import Measured
from companion.gap.spectral import line_evidence


class HoldTest(NamedTuple):
    """Holding a freed model term back at its model value, all else refitted."""

    lr: float  #: the corrected likelihood ratio, lr_raw / inflation
    lr_raw: float  #: deviance the freed term removes
    inflation: float  #: sandwich overdispersion under the null
    fit: Fit  #: the fit with the term held


class BackwardState(NamedTuple):
    """The workflow's state after a backward step."""

    terms: list
    held: set
    alternatives: dict  #: index of a term -> the Gauss-Markov fit it won over
    notes: list  #: what was dropped and why


class FilterSwap(NamedTuple):
    """The final state with a short Gauss-Markov term in place of a fitted low-pass filter."""

    terms: list
    held: set
    alternatives: dict  #: index of a term -> the Gauss-Markov fit it won over
    note: str  #: why the swap, and what it made unnecessary


def refit(meas: Measured, terms, held, n_model: int) -> Fit:
    """Refit the free magnitudes; intervals for them and for the shapes of added Gauss-Markov/sinusoid terms."""
    fit = fit_terms(meas, terms, fixed=sorted(held))
    free = [i for i in range(len(terms)) if i not in held]
    _intervals(meas, fit, free, shape_free=[i for i in range(n_model, len(terms))
                                            if terms[i]["effect"] in SHAPE and i not in held])
    return fit


def hold_test(meas: Measured, base: Fit, held, i: int, t0) -> HoldTest:
    """Likelihood ratio of holding the freed model term ``i`` back at its model value (all else refitted),
    divided by the sandwich overdispersion evaluated under that null (score form: a model B larger than
    the data's gets the wider spread of its own flicker)."""
    p = MAGNITUDE[t0["effect"]]
    terms = [dict(t) for t in base.terms]
    terms[i][p] = t0[p]
    shaped = [j for j in range(len(terms)) if terms[j]["effect"] in SHAPE and j not in held and j != i]
    hf = refine_shapes(meas, terms, sorted(set(held) | {i}), shaped)
    lr_raw = hf.dev - base.dev
    phi = lr_inflation(meas, hf, None, direction=[unit_column(terms[i], meas.tau, meas.rate_hz)])
    return HoldTest(lr_raw / phi, lr_raw, phi, hf)


def added_level(term, y, rate_hz: float) -> float:
    """The level an added effect passed: chi^2_k(1 - ALPHA) for k free parameters (a Gauss-Markov term's
    tau_c and a sinusoid's searched frequency count), a sinusoid whose line the periodogram confirms at
    that of a known frequency (chi^2_1(1 - ALPHA_RECAL), as when it was taken)."""
    if term["effect"] == "sinusoid" and y is not None:
        ev = line_evidence(y, rate_hz, term["freq_hz"], term["amplitude"])
        if ev is not None and ev.get("confirmed"):
            return selection.RECAL_PENALTY
    return selection.add_penalty(2 if term["effect"] in SHAPE else 1)


def drop_unneeded(meas: Measured, base: Fit, held, n_model: int, alternatives: dict, y,
                  rate_hz: float) -> BackwardState:
    """Backward step for added effects, the counterpart of undoing a recalibration: each effect added at
    one step is taken out with the rest refitted (magnitudes; shapes as they stand); when putting it back
    no longer passes the level it passed when it was added (corrected LR, overdispersion under that null), the
    weakest such effect is removed, and the test is repeated. A later addition can make an earlier one
    unnecessary: a second sinusoid at the periodogram's line takes the power of a first fitted a little off
    its frequency."""
    terms, held, notes = [dict(t) for t in base.terms], set(held), []
    while True:
        weakest, dev_all = None, fit_terms(meas, terms, sorted(held), intervals=False).dev
        for i in range(n_model, len(terms)):
            t = terms[i]
            if i in held or t["effect"] not in MAGNITUDE or t[MAGNITUDE[t["effect"]]] <= 0:
                continue
            trial = [dict(x) for x in terms]
            trial[i][MAGNITUDE[t["effect"]]] = 0.0
            # the others' shapes as they stand (magnitudes free): re-optimised, a second sinusoid would move
            # onto the first's frequency and either of two would look unneeded in turn
            without = fit_terms(meas, trial, sorted(held | {i}), intervals=False)
            phi = lr_inflation(meas, without, None, direction=[unit_column(t, meas.tau, meas.rate_hz)])
            lr = (without.dev - dev_all) / phi
            level = added_level(t, y, rate_hz)
            if lr <= level and (weakest is None or lr / level < weakest[0]):
                weakest = (lr / level, i, lr, level, without)
        if weakest is None:
            return BackwardState(terms, held, alternatives, notes)
        _, i, lr, level, without = weakest
        t = terms[i]
        notes.append(f"{t['effect']} ({', '.join(f'{k} {v:.3g}' for k, v in term_params(t).items())}), added at one "
                     f"step, is no longer needed after a later one (putting it back: LR {lr:.1f} <= {level:.1f}): "
                     "dropped")
        keep = [j for j in range(len(terms)) if j != i]
        index = {j: k for k, j in enumerate(keep)}
        held = {index[j] for j in held if j != i}
        alternatives = {index[j]: v for j, v in alternatives.items() if j != i}
        terms = [dict(without.terms[j]) for j in keep]
        shaped = [j for j in range(n_model, len(terms)) if terms[j]["effect"] in SHAPE and j not in held]
        terms = refine_shapes(meas, terms, sorted(held), shaped).terms  # the state changed: shapes again


def penalised_dev(meas: Measured, terms, held, terms0, y, rate_hz: float) -> float:
    """Deviance plus the level each added effect passed (a fitted filter on a model's white term 15.1):
    the criterion two final states are compared by."""
    dev = fit_terms(meas, terms, sorted(held), intervals=False).dev
    for i, t in enumerate(terms):
        if i in held:
            continue
        if i >= len(terms0):
            dev += added_level(t, y, rate_hz)
        elif t.get("cutoff_hz") and not terms0[i].get("cutoff_hz"):
            dev += selection.add_penalty(1)
    return dev


def filter_or_gauss_markov(meas: Measured, base: Fit, held, terms0, lp, y, rate_hz: float, alternatives: dict,
                           veto) -> FilterSwap | None:
    """The filter rule decides between a fitted low-pass filter and a short Gauss-Markov term at the step
    where they compete, in the state of that step: with another effect not yet named (a vibration line at
    the Gauss-Markov term's cluster times) the Gauss-Markov fit is pulled to a few samples' tau_c, the filter
    wins, and later steps patch what it leaves with further terms. In the final state the filter is taken
    out and the step weighed again (the same choice and rules); when a Gauss-Markov term wins there, the
    effects it makes unnecessary are dropped (backward step) and the two final states are compared by
    deviance plus the levels their added effects passed. Returns the Gauss-Markov state (its one note) when
    it is the better one, else None."""
    n_model = len(terms0)
    js = [j for j, t in enumerate(base.terms) if t["effect"] == "white_noise" and t.get("cutoff_hz")
          and not (j < n_model and terms0[j].get("cutoff_hz"))]
    if not js:
        return None
    trial = [dict(t) for t in base.terms]
    for j in js:
        for k in ("cutoff_hz", "order", "integrate"):
            trial[j].pop(k, None)
    shaped = [i for i in range(n_model, len(trial)) if trial[i]["effect"] in SHAPE and i not in held]
    tb = fit_terms(meas, trial, sorted(held), intervals=False)
    step = selection.choose(meas, tb, sorted(held), [], shaped=shaped, lowpass=lp, veto=veto)
    x = step.chosen
    if x is None or x.effect != "gauss_markov":
        return None
    alt = dict(alternatives)
    if step.alternative is not None:
        alt[len(x.fit.terms) - 1] = step.alternative
    kept = drop_unneeded(meas, x.fit, held, n_model, alt, y, rate_hz)
    terms, held2, alt, dropped = kept.terms, kept.held, kept.alternatives, kept.notes
    before = penalised_dev(meas, base.terms, held, terms0, y, rate_hz)
    after = penalised_dev(meas, terms, held2, terms0, y, rate_hz)
    if after >= before:
        return None
    fc = ", ".join(f"{base.terms[j]['cutoff_hz']:.3g} Hz" for j in js)
    gm = [t for t in terms[n_model:] if t["effect"] == "gauss_markov"][-1]
    note = (f"the low-pass filter fitted at one step ({fc}) was weighed again in the final state: a "
            f"Gauss-Markov term (tau_c {gm['tau_c']:.3g} s) explains the short cluster times better there "
            f"(deviance + levels {after:.1f} against {before:.1f}) and is taken instead"
            + ("; " + "; ".join(dropped) if dropped else ""))
    return FilterSwap(terms, held2, alt, note)


def term_params(term) -> dict:
    return {k: v for k, v in term.items() if k != "effect"}
