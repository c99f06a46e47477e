"""Every explanation of a gap fitted from the same state and ranked by the score of
:mod:`companion.gap.scoring`: each effect the model lacks added, each held model term recalibrated, each
effect with one term recalibrated, the low-pass filter, a line the periodogram shows, a temperature-driven
rate. Testing them one after another would let whichever is tested first take the points they compete for."""

from __future__ import annotations

from companion.gap.candidates import (MAGNITUDE, SHAPE, Fit, estimate_covariance, fit_terms, fit_with_candidate,
                                      refine_shapes)
from companion.gap.cutoff_fit import lowpass_explanations, with_cutoff
from companion.gap.likelihood import Measured
from companion.gap.scoring import FILTER_LIKE_SAMPLES, LOWPASS, RECAL_PENALTY, make_explanation


def candidate_effects(terms) -> list[str]:
    """Effects that can be added: those the model lacks, and Gauss-Markov / sinusoid also a second time."""
    present = {t["effect"] for t in terms}
    return [e for e in MAGNITUDE if (e not in present or e in SHAPE) and e != "temperature"]


def line_explanations(meas: Measured, state: Fit, held, shaped=(), lowpass=None, sigma=None) -> list:
    """A sinusoid at each line the periodogram shows (``meas.lines``), at the periodogram's frequency, its
    amplitude fitted on the Allan curve like every candidate's. The frequency searched on the Allan curve
    alone can miss such a line: near the Nyquist frequency its profile is flat (the line is seen at tau0
    only) and the search's grid stops at 0.45 x rate. A line whose periodogram amplitude holds at least half
    the fitted one (:data:`companion.gap.spectral.MIN_AMPLITUDE_SHARE`) has a known frequency and is
    weighed at that level, chi^2_1(1 - ALPHA_RECAL) = 10.8, as a confirmed line is
    (:func:`companion.gap.arbitration.spectral_line`); otherwise at a searched one's, chi^2_2(1 - ALPHA)."""
    from companion.gap.spectral import MIN_AMPLITUDE_SHARE

    out = []
    for f_line, amp_psd in meas.lines:
        if any(t["effect"] == "sinusoid" and abs(t["freq_hz"] - f_line) <= 1e-9 * f_line for t in state.terms):
            continue
        f = fit_terms(meas, list(state.terms) + [{"effect": "sinusoid", "amplitude": 1.0, "freq_hz": f_line}], held,
                      intervals=False)
        if shaped and f.terms[-1]["amplitude"] > 0:
            f = refine_shapes(meas, f.terms, held, shaped)
        f = with_cutoff(meas, f, held, "sinusoid", lowpass)
        a = f.terms[-1]["amplitude"]
        if a <= 0:
            continue
        x = make_explanation(meas, state, held, "sinusoid", (), f, sigma)
        if amp_psd >= MIN_AMPLITUDE_SHARE * a:
            x.penalty = RECAL_PENALTY
        out.append(x)
    return out


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
        f = with_cutoff(meas, f, held, e, lowpass)
        fits[e] = f
        if f.terms[-1][MAGNITUDE[e]] > 0:
            out.append(make_explanation(meas, state, held, e, (), f, sigma))
    out += line_explanations(meas, state, held, shaped, lowpass, sigma)
    for j in recalibratable:
        f = refine_shapes(meas, terms, [i for i in held if i != j], shaped)
        out.append(make_explanation(meas, state, held, None, (j,), f, sigma))
    out += lowpass_explanations(meas, state, held, recalibratable, lowpass, shaped, sigma)
    if thermal is not None and not any(t["effect"] == "temperature" for t in terms):
        f = fit_terms(meas, list(terms) + [dict(thermal)], held, intervals=False)
        if shaped:
            f = refine_shapes(meas, f.terms, held, shaped)
        if f.terms[-1]["coef"] > 0:
            out.append(make_explanation(meas, state, held, "temperature", (), f, sigma))
    effects = [x.effect for x in sorted((x for x in out if x.effect and x.effect not in (LOWPASS, "temperature")),
                                        key=lambda x: -x.score)]
    if combine_top is not None:
        effects = effects[:combine_top]
    for e in effects:
        q = SHAPE.get(e)
        for j in recalibratable:
            fixed = [i for i in held if i != j]
            f = fit_with_candidate(meas, terms, fixed, e, near=fits[e].terms[-1][q] if q else None)
            f = with_cutoff(meas, f, fixed, e, lowpass)
            if f.terms[-1][MAGNITUDE[e]] > 0:
                out.append(make_explanation(meas, state, held, e, (j,), f, sigma))
    if any(t["effect"] == "white_noise" and t.get("cutoff_hz") for t in terms) or (lowpass and lowpass[0]):
        # the low-pass filter is already in the model, or the log names one (its cut-off is known): a
        # Gauss-Markov term at the filter's time scale would describe the same roll-off twice, or describe a
        # named filter as a bias process
        out = [x for x in out if not (x.effect == "gauss_markov" and
                                      x.added_term()["tau_c"] * meas.rate_hz < FILTER_LIKE_SAMPLES)]
    out.sort(key=lambda x: -x.score)
    return out
