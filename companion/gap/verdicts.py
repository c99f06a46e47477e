"""The final state of the gap workflow in words and numbers: per model term its verdict (consistent,
too small, too large, not seen) with the test behind it, and per added effect its entry with the
independent evidence (periodogram, temperature regression) and the alternative it won over."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from companion.gap import explain, selection
from companion.gap.backward import hold_test
from companion.gap.candidates import MAGNITUDE, SHAPE, Fit, fit_terms, lr_inflation, refine_shapes, unit_column
from companion.gap.likelihood import Measured
from companion.gap.spectral import line_evidence
from companion.gap.temperature_candidate import regression_check


@dataclass
class EffectEvidence:
    """The record's own series an added effect is checked against beside the Allan curve."""

    y: object  #: the longest segment (the periodogram's)
    y_segs: list  #: every segment (the temperature regression's)
    t_smooth: list | None  #: the smoothed temperature per segment, when the log has it


def lowpass_entry(t, cutoff_param, rate_hz, axis, index, terms0) -> dict:
    """The JSON/report entry of a low-pass filter put on the white-noise term ``t``."""
    from companion.allan.filtered_white import aliasing_gain

    fc, order = float(t["cutoff_hz"]), int(t.get("order", 2))
    gain = aliasing_gain(fc, None if t.get("integrate") else rate_hz, order)
    src = "the log's parameter" if cutoff_param else "fitted"
    entry = {"effect": selection.LOWPASS, "cutoff_hz": fc, "order": order, "source": src, "N": t["N"],
             "on_model_term": index < len(terms0), "aliasing_gain": gain,
             "integrated": bool(t.get("integrate", False)),
             "explanation": explain.explain_lowpass(fc, order, rate_hz, gain, src, axis)}
    if cutoff_param:
        entry["cutoff_param_hz"] = float(cutoff_param)
    return entry


@dataclass
class TermEvidence:
    """A model term's value at the final state and the test behind its verdict."""

    fitted: float
    ci95: list
    lr: float
    lr_raw: float
    inflation: float


def term_evidence(meas: Measured, base: Fit, held, i: int, t0, n_model: int) -> TermEvidence:
    """Model term ``i`` at the final state: held, the evidence for freeing it (its value freed, the
    likelihood ratio of freeing it, overdispersion at the state); freed, the evidence for holding it back at
    its model value (:func:`companion.gap.backward.hold_test`)."""
    p = MAGNITUDE[t0["effect"]]
    if i not in held:
        fitted = base.terms[i][p]
        lo, hi = base.ci95[i].get(p, [fitted, fitted])
        ht = hold_test(meas, base, held, i, t0)
        return TermEvidence(fitted, [lo, hi], ht.lr, ht.lr_raw, ht.inflation)
    shaped = [j for j in range(n_model, len(base.terms)) if base.terms[j]["effect"] in SHAPE and j not in held]
    free_fit = fit_terms(meas, refine_shapes(meas, base.terms, sorted(held - {i}), shaped).terms,
                         fixed=sorted(held - {i}))
    fitted = free_fit.terms[i][p]
    lo, hi = free_fit.ci95[i].get(p, [fitted, fitted])
    phi = lr_inflation(meas, base, None, direction=[unit_column(base.terms[i], meas.tau, meas.rate_hz)])
    lr_raw = base.dev - free_fit.dev
    return TermEvidence(fitted, [lo, hi], lr_raw / phi, lr_raw, phi)


def model_term_verdicts(meas: Measured, base: Fit, held, terms0, alternatives: dict) -> list[dict]:
    """Per model term: its model and fitted value, the test, and the verdict (consistent: held at the model
    value; not seen: freed and refitted to zero; too small / too large: recalibrated), with the
    Gauss-Markov alternative a recalibrated term won over."""
    out = []
    rate_hz = meas.rate_hz
    for i, t0 in enumerate(terms0):
        p = MAGNITUDE[t0["effect"]]
        entry = {"effect": t0["effect"], "param": p, "model": t0[p]}
        ev = term_evidence(meas, base, held, i, t0, len(terms0))
        fitted, (lo, hi) = ev.fitted, ev.ci95
        ratio = fitted / t0[p] if t0[p] > 0 else math.inf
        entry.update(fitted=fitted, ratio=ratio, ci95=[lo, hi], lr=ev.lr, lr_raw=ev.lr_raw, inflation=ev.inflation)
        if i in held:
            entry["verdict"] = "consistent"
        elif fitted == 0:
            entry["verdict"] = "not seen"
            entry["text"] = (f"{t0['effect']} {p}: not seen in the data (95 % upper bound {hi:.3g}, model "
                             f"{t0[p]:.3g})")
        else:
            entry["verdict"] = "too small" if ratio > 1 else "too large"
            entry["text"] = explain.explain_missized(t0["effect"], p, ratio)
            if i in alternatives:
                entry["alternative"] = alternatives[i]
                entry["text"] += ". " + explain.explain_alternative(alternatives[i], meas.n / rate_hz, rate_hz)
        out.append(entry)
    return out


@dataclass
class AddedEffects:
    """The entries of the effects added (``GapResult.added``) and the notes on those dropped."""

    entries: list = field(default_factory=list)
    notes: list = field(default_factory=list)


def _added_entry(meas: Measured, base: Fit, i: int, t, evidence: EffectEvidence, axis: str, alternatives: dict):
    """The entry of the added term ``t`` (index ``i`` in the final state)."""
    rate_hz = meas.rate_hz
    ci = base.ci95[i] if i < len(base.ci95) else {}
    if t["effect"] == "temperature":
        chk = regression_check(evidence.y_segs, evidence.t_smooth, t["coef"], rate_hz)
        return {"effect": "temperature", "coef": t["coef"], "ci95": ci, "check": chk,
                "explanation": explain.explain_temperature(t["coef"], chk, axis)}
    ev = None
    if t["effect"] == "sinusoid" and t["amplitude"] > 0:
        ev = line_evidence(evidence.y, rate_hz, t["freq_hz"], t["amplitude"])
    entry = {**t, "ci95": ci, "explanation": explain.explain_added(t, axis, rate_hz, spectral=ev)}
    if ev is not None:
        entry["spectral"] = ev
    if i in alternatives:
        alt = alternatives[i]
        entry["alternative"] = alt
        entry["explanation"] += " " + explain.explain_alternative(alt, meas.n / rate_hz, rate_hz)
    return entry


def added_effects(meas: Measured, base: Fit, held, terms0, evidence: EffectEvidence, axis: str,
                  alternatives: dict, cutoff_hz) -> AddedEffects:
    """Per effect added in the final state ``base``: its entry; then a low-pass filter put on a white term.
    An addition a later one refitted to zero is dropped with a note."""
    out = AddedEffects()
    final = base.terms
    for i in range(len(terms0), len(final)):
        t = final[i]
        if i in held:
            continue
        if t[MAGNITUDE[t["effect"]]] <= 0:
            out.notes.append(f"{t['effect']} added at one step was refitted to zero after a later step and is "
                             "dropped")
            continue
        out.entries.append(_added_entry(meas, base, i, t, evidence, axis, alternatives))
    for i, t in enumerate(final):
        if t["effect"] == "white_noise" and t.get("cutoff_hz") and not (i < len(terms0) and terms0[i].get("cutoff_hz")):
            out.entries.append(lowpass_entry(t, cutoff_hz, meas.rate_hz, axis, i, terms0))
    return out
