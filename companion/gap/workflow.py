"""The simulation-vs-measurement gap workflow: compare, name the missing effect, add it, refit, re-simulate.

:func:`run_gap` builds a :class:`GapInput` (the measurement and what the log says about it) and a
:class:`GapState` (the terms as they stand), and runs :data:`STEPS` over them in order:

1. ``compare``: measured overlapping AVAR with EDF and 95 % band (:func:`companion.gap.compare.measure`); the
   model's AVAR, analytic from its terms, and confirmed by simulating the model (same rate and length, fixed
   seed: :func:`companion.gap.null.sim_checks`); the cluster times where the measurement leaves the model's
   95 % band.
2. ``rate_rounding``: a known LSB (int16 mrad/s RAW_IMU, say) as a white term N_q = LSB sqrt(tau0/12) with no
   free parameter, added first when it lowers the deviance of the unrecalibrated model by more than
   chi^2_1(1 - ALPHA) (:mod:`companion.gap.rate_rounding`).
3. ``forward``: explanations weighed head to head (:mod:`companion.gap.selection`). From the current state
   (model terms held at their values unless recalibrated, effects added earlier free) every explanation is
   fitted by maximum likelihood on the same data and ranked by one score, Delta D / phi - penalty
   (:mod:`companion.gap.scoring`); the rules between look-alikes apply; a sinusoid the periodogram rules out
   leaves the ranking, one it confirms is taken at a known frequency's level, and the temperature channel
   decides between a drift and a temperature-driven rate (:mod:`companion.gap.arbitration`). Repeated until
   no explanation scores above zero, at most ``max_iter`` times.
4. ``drop_unneeded``: an effect later steps made unnecessary is dropped (:mod:`companion.gap.backward`).
5. ``undo_recalibrations``: a recalibration later additions made unnecessary (holding the term at its model
   value costs LR <= chi^2_1(1 - ALPHA_RECAL)) is undone.
6. ``weigh_riders``: a recalibration taken as the rider of another change is weighed once more against every
   effect from the state with that term held.
7. ``filter_again``: a fitted filter taken over a short Gauss-Markov term is weighed again in the final state.
8. ``verdicts``: per model term its verdict, per added effect its entry (:mod:`companion.gap.verdicts`); the
   model after with every term refitted together (:func:`refit_base`; N held at the analysis' white level
   when the caller gives it), G after (:mod:`companion.gap.gap_result`), its simulation; the noise floor: the model fits within
   the noise when G <= NOISE_FLOOR_G = 2 and nothing is added or recalibrated.
9. ``remaining_gap``: G over the cluster times the record resolves, a long-tau term named from too short a
   record, and how often the model after leaves a gap as large on this record's layout
   (:mod:`companion.gap.null`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from companion.gap import explain, selection, ramp_or_walk
from companion.gap.band_fit import better_in_band
from companion.gap.arbitration import LineVeto, spectral_line, thermal_arbitration
from companion.gap.backward import drop_unneeded, filter_or_gauss_markov, hold_test, refit
from companion.gap.candidates import MAGNITUDE, SHAPE, Fit, refine_shapes
from companion.gap.compare import Measured, disagreements, gap_metric, measure, measure_pooled, model_avar
from companion.gap.cutoff_fit import refine_cutoff
from companion.gap.null import null_gap, null_text, sim_checks
from companion.gap.rate_rounding import delta_crit, detect_lsb, rate_rounding
from companion.gap.gap_result import (NOISE_FLOOR_G, GapResult, record_rule_notes, resolved_gap, resolved_text,
                                  strongest_left)
from companion.gap.spectral import significant_lines
from companion.gap.step_records import IterationRecord, SwapRecord, alternative_entry, swap_alternative_entry
from companion.gap.temperature_candidate import thermal_term
from companion.gap.verdicts import EffectEvidence, added_effects, model_term_verdicts

__all__ = ["ALPHA", "ALPHA_RECAL", "MAX_ITER", "NESTED", "NOISE_FLOOR_G", "GapResult", "delta_crit", "detect_lsb",
           "run_gap"]

#: the selection's levels and nested limits, under the names the workflow's users read
ALPHA = selection.ALPHA
ALPHA_RECAL = selection.ALPHA_RECAL
NESTED = selection.NESTED
#: steps (an effect added, a term recalibrated, or both) before stopping
MAX_ITER = 6


@dataclass
class DetrendedProvider:
    """The record with its least-squares line out, measured once, when a ramp and a random walk first
    compete (:mod:`companion.gap.ramp_or_walk`)."""

    y_segs: list
    rate_hz: float
    #: indices of the terms with no free parameter (the rate-LSB white term), fixed in the detrended fit
    fixed: list
    _meas: Measured | None = None

    def __call__(self) -> selection.DetrendedRecord:
        if self._meas is None:
            self._meas = ramp_or_walk.detrended_measure(self.y_segs, self.rate_hz)
        lengths = [len(s) / self.rate_hz for s in self.y_segs]
        return selection.DetrendedRecord(self._meas, sorted(self.fixed), lengths)


@dataclass
class GapOptions:
    """The choices of one run (:func:`run_gap`'s keyword arguments)."""

    axis: str = "gx"
    lsb: float | None = None  #: output step of the data (None: detected from the values)
    seed: int = 0  #: of the simulations
    simulate: bool = True  #: the checks by simulation (False: the analytic curves only)
    max_iter: int = MAX_ITER
    cutoff_hz: float | None = None  #: low-pass cut-off from the log's parameters (None: fitted)
    filter_order: int = 2
    lowpass: bool = True  #: the filter among the candidates (False: data known to be unfiltered)
    integrated: bool = False  #: each value is the mean of the filtered rate over its interval
    #: the analysis' white level of the same data ({"N", "ci95": [lo, hi]}, SI): the one N the report and the
    #: model after carry (None: the workflow's own fit)
    white: dict | None = None


@dataclass
class GapInput:
    """What the workflow compares: the measurement, the model, and what the log says about the data."""

    meas: Measured
    rate_hz: float
    axis: str
    terms0: list  #: the model's terms as given
    y: np.ndarray | None  #: the longest segment (periodogram)
    y_all: np.ndarray | None  #: every sample (LSB detection)
    y_segs: list  #: the segments (trend, temperature regression, null layout)
    t_smooth: list  #: smoothed temperature per segment (empty: no channel)
    t_series: np.ndarray | None  #: the same, concatenated (simulation of a temperature term)
    thermal: dict | None  #: the temperature-driven rate candidate
    lowpass: tuple | None  #: (cut-off from the log or None, order, integrated); None: no filter candidate
    cutoff_hz: float | None
    lsb: float | None
    seed: int
    simulate: bool
    max_iter: int
    white: dict | None = None


@dataclass
class GapState:
    """The terms as they stand, carried through the steps."""

    current: list  #: the terms (model terms first, then the added ones)
    held: set  #: indices held at their values (model terms not recalibrated, the rate-LSB term)
    fixed: list = field(default_factory=list)  #: indices of terms with no free parameter
    base: Fit | None = None  #: the refit of ``current``
    #: index of a term -> the Gauss-Markov fit it won over (reported as the alternative)
    alternatives: dict = field(default_factory=dict)
    veto: LineVeto | None = None
    detrended: DetrendedProvider | None = None

    def refit(self, inp: GapInput) -> None:
        self.base = refit(inp.meas, self.current, self.held, len(inp.terms0))


def _prepare(y, rate_hz: float, terms, segments, temperature, opts: GapOptions) -> GapInput:
    """The measurement (pooled over ``segments`` when there are several), the lines the periodogram shows
    (candidates at their own frequency) and the temperature channel's candidate."""
    if segments is not None and len(segments) > 1:
        segments = [np.asarray(s_, dtype=float) for s_ in segments]
        meas = measure_pooled(segments, rate_hz)
        y = max(segments, key=len) if y is None else y
        y_all = np.concatenate(segments)
    else:
        if segments is not None:
            y = np.asarray(segments[0], dtype=float)
        meas = measure(y, rate_hz)
        y_all = y
    if y is not None:
        meas.lines = significant_lines(y, rate_hz)
    y_segs = segments if segments is not None else [y]
    t_segs = None
    if temperature is not None:  # aligned with ``segments``, or with ``y``
        t_segs = temperature if segments is not None else [temperature]
    thermal, t_smooth = thermal_term(t_segs, rate_hz, meas.tau)
    lp = (opts.cutoff_hz, int(opts.filter_order), bool(opts.integrated)) if opts.lowpass else None
    return GapInput(meas=meas, rate_hz=rate_hz, axis=opts.axis, terms0=[dict(t) for t in terms], y=y, y_all=y_all,
                    y_segs=y_segs, t_smooth=t_smooth, t_series=np.concatenate(t_smooth) if t_smooth else None,
                    thermal=thermal, lowpass=lp, cutoff_hz=opts.cutoff_hz, lsb=opts.lsb, seed=opts.seed,
                    simulate=opts.simulate, max_iter=opts.max_iter, white=opts.white)


def _compare(inp: GapInput, st: GapState, res: GapResult) -> None:
    """The model before against the measurement: G, the regions outside the band, the simulated check."""
    meas, terms0 = inp.meas, inp.terms0
    s0 = model_avar(terms0, meas.tau, inp.rate_hz) if terms0 else np.full_like(meas.tau, 1e-300)
    res.gap_before = gap_metric(meas, s0)
    res.regions_before = disagreements(meas, s0)
    if inp.simulate and terms0:
        res.sim_avar_before, res.gap_sim_before, res.sim_check_before = sim_checks(terms0, meas, inp.seed)


def _rate_rounding(inp: GapInput, st: GapState, res: GapResult) -> None:
    rr = rate_rounding(inp.meas, inp.terms0, inp.lsb, inp.y_all, inp.rate_hz, inp.axis)
    if rr is None:
        return
    if rr.note:
        res.notes.append(rr.note)
    if rr.term is not None:
        st.current.append(rr.term)
        st.fixed.append(len(st.current) - 1)
        res.added.append(rr.added)
    res.quantization = rr.info


def _weigh_evidence(inp: GapInput, st: GapState, res: GapResult, c: selection.StepChoice) -> IterationRecord:
    """The step's choice after the independent evidence: a sinusoid the periodogram confirms when nothing
    passed, the temperature channel between a drift and a temperature-driven rate."""
    chosen, top, ru = c.chosen, c.best, c.runner_up
    if c.vetoed and c.vetoed[0][0].score > max(0.0, c.ranked[0].score if c.ranked else 0.0):
        res.notes.append(c.vetoed[0][1] + "; the next explanation is weighed instead")
    if chosen is None:  # a vibration line the periodogram shows is a known frequency, not a searched one
        ruling = spectral_line(c.ranked, inp.y, inp.rate_hz)
        chosen = ruling.taken
        if ruling.note:
            res.notes.append(ruling.note)
            top = chosen
            ru = selection.runner_up(c.ranked, chosen)
    if inp.thermal is not None and chosen is not None:
        ruling = thermal_arbitration(c.ranked, chosen, inp.y_segs, inp.t_smooth, inp.rate_hz)
        chosen = ruling.taken
        if ruling.note:
            res.notes.append(ruling.note)
            top = chosen if chosen is not None else top
            ru = selection.runner_up(c.ranked, chosen) if chosen is not None else ru
    if c.trend:
        res.notes.append(explain.explain_trend(c.trend))
    return IterationRecord(len(res.iterations) + 1, st.base.gap, c, top, ru, chosen, inp.terms0)


def _take(inp: GapInput, st: GapState, chosen, c: selection.StepChoice, shaped: list) -> None:
    """The state after ``chosen``: its terms, its recalibrated terms freed, earlier shapes re-optimised."""
    meas, terms0 = inp.meas, inp.terms0
    if c.alternative is not None and chosen.effect not in (selection.LOWPASS, "temperature"):
        if chosen.effect:
            st.alternatives[len(st.current)] = c.alternative
        else:  # the model's own term of the limit, recalibrated
            st.alternatives[[j for j in chosen.recal if st.current[j]["effect"] == c.nested["limit"]][0]] = \
                c.alternative
    st.current = [dict(t) for t in chosen.fit.terms]
    st.held -= set(chosen.recal)
    if shaped and (chosen.effect is not None):  # earlier shapes re-optimised in the new state
        st.current = refine_shapes(meas, st.current, sorted(st.held), shaped).terms
    if inp.lowpass is not None and not inp.lowpass[0] and chosen.effect in selection.SHORT_TAU_EFFECTS:
        # a fitted cut-off is a shape too: an effect with power at the filter's cluster times (a vibration
        # line near the logger's Nyquist frequency), added after the filter, takes back short-tau power
        # the cut-off had absorbed; a long-tau effect (ramp, random walk) does not compete with it
        st.current = refine_cutoff(meas, st.current, sorted(st.held), inp.lowpass).terms
    st.base = refit(meas, st.current, st.held, len(terms0))


def _forward(inp: GapInput, st: GapState, res: GapResult) -> None:
    """Every explanation weighed from the same state by one criterion, the best taken while it passes."""
    n_model = len(inp.terms0)
    st.held = set(range(n_model)) | set(st.fixed)
    st.refit(inp)
    st.detrended = DetrendedProvider(inp.y_segs, inp.rate_hz, st.fixed)
    st.veto = LineVeto(inp.y, inp.rate_hz)
    for _ in range(inp.max_iter):
        recalibratable = [j for j in range(n_model) if j in st.held]
        shaped = [i for i in range(n_model, len(st.current)) if st.current[i]["effect"] in SHAPE and i not in st.held]
        c = selection.choose(inp.meas, st.base, sorted(st.held), recalibratable, shaped=shaped, lowpass=inp.lowpass,
                             thermal=inp.thermal, detrended=st.detrended, veto=st.veto)
        rec = _weigh_evidence(inp, st, res, c)
        res.iterations.append(rec.as_dict())
        if rec.chosen is None:
            break
        res.alternatives.append(alternative_entry(rec.iteration, rec.chosen, rec.runner_up, inp.terms0))
        _take(inp, st, rec.chosen, c, shaped)


def _drop_unneeded(inp: GapInput, st: GapState, res: GapResult) -> None:
    """An effect that later steps made unnecessary is dropped (backward step, the level it passed)."""
    out = drop_unneeded(inp.meas, st.base, st.held, len(inp.terms0), st.alternatives, inp.y, inp.rate_hz)
    st.current, st.held, st.alternatives = out.terms, out.held, out.alternatives
    if out.notes:
        res.notes.extend(out.notes)
        st.refit(inp)


def _undo_recalibrations(inp: GapInput, st: GapState, res: GapResult) -> None:
    """A recalibration that later additions made unnecessary is undone (backward step, the same test), the
    weakest first."""
    terms0 = inp.terms0
    while True:
        weakest, weakest_j = None, None
        for j in range(len(terms0)):
            if j in st.held:
                continue
            ht = hold_test(inp.meas, st.base, st.held, j, terms0[j])
            if ht.lr <= selection.RECAL_PENALTY and (weakest is None or ht.lr < weakest.lr):
                weakest, weakest_j = ht, j
        if weakest is None:
            return
        st.held.add(weakest_j)
        st.current = [dict(t) for t in weakest.fit.terms]
        st.refit(inp)
        st.alternatives.pop(weakest_j, None)


def _weigh_riders(inp: GapInput, st: GapState, res: GapResult) -> None:
    """A recalibration taken as the rider of another change (e.g. "gauss_markov + random_walk K" when a
    ramp also hides in the data) is weighed once more against every effect from the state with that term
    held: the same score, the recalibration's own (dD - phi x 10.8) against the effect's; against a
    one-parameter effect that passes its level, the larger likelihood (selection.equal_size_rule)."""
    meas, terms0 = inp.meas, inp.terms0
    for j in range(len(terms0)):
        if j in st.held or len(st.current) - len(terms0) >= inp.max_iter:
            continue
        ht = hold_test(meas, st.base, st.held, j, terms0[j])
        value = ht.lr_raw - ht.inflation * selection.RECAL_PENALTY
        hf = ht.fit
        shaped = [i for i in range(len(terms0), len(hf.terms)) if hf.terms[i]["effect"] in SHAPE and i not in st.held]
        c = selection.choose(meas, hf, sorted(st.held | {j}), [], shaped=shaped, lowpass=inp.lowpass,
                             thermal=inp.thermal, detrended=st.detrended, veto=st.veto)
        x = c.chosen
        if x is None:
            continue
        same_size = x.k == 1 and x.effect not in (selection.LOWPASS, "temperature")
        if (x.delta_dev <= ht.lr_raw) if same_size else (x.score <= value):
            continue
        mod = terms0[j]["effect"] + " " + MAGNITUDE[terms0[j]["effect"]]
        rec = SwapRecord(len(res.iterations) + 1, mod, hf.gap, c, value, terms0)
        res.iterations.append(rec.as_dict())
        if c.trend:
            res.notes.append(explain.explain_trend(c.trend))
        res.alternatives.append(swap_alternative_entry(len(res.iterations), x, mod, ht, value, terms0))
        if c.alternative is not None and x.effect:
            st.alternatives[len(hf.terms)] = c.alternative
        st.alternatives.pop(j, None)
        st.held.add(j)
        st.current = [dict(t) for t in x.fit.terms]
        st.refit(inp)


def _filter_again(inp: GapInput, st: GapState, res: GapResult) -> None:
    """A fitted filter taken over a short Gauss-Markov term is weighed again in the final state."""
    if inp.lowpass is None or inp.lowpass[0]:
        return
    swap = filter_or_gauss_markov(inp.meas, st.base, st.held, inp.terms0, inp.lowpass, inp.y, inp.rate_hz,
                                  st.alternatives, st.veto)
    if swap is not None:
        st.current, st.held, st.alternatives = swap.terms, swap.held, swap.alternatives
        res.notes.append(swap.note)
        st.refit(inp)


def _verdicts(inp: GapInput, st: GapState, res: GapResult) -> None:
    """Per model term its verdict, per added effect its entry; the model after and its gap."""
    meas, terms0, base = inp.meas, inp.terms0, st.base
    res.recalibrated.extend(model_term_verdicts(meas, base, st.held, terms0, st.alternatives))
    added = added_effects(meas, base, st.held, terms0, EffectEvidence(inp.y, inp.y_segs, inp.t_smooth), inp.axis,
                          st.alternatives, inp.cutoff_hz)
    res.notes.extend(added.notes)
    res.added.extend(added.entries)
    # an addition a later one refitted to zero leaves the model after
    final = [dict(t) for i, t in enumerate(base.terms)
             if i < len(terms0) or i in st.held or t[MAGNITUDE[t["effect"]]] > 0]
    changed = any(e["verdict"] != "consistent" for e in res.recalibrated) or len(final) > len(terms0) or \
        any(a["effect"] == selection.LOWPASS for a in res.added)
    if not changed:
        res.terms_after = terms0
        res.gap_after = res.gap_before
        res.fits_within_noise = res.gap_before <= NOISE_FLOOR_G
        if res.fits_within_noise:
            res.notes.append("the model already fits the measurement within the noise: nothing added, nothing "
                             "recalibrated")
        else:
            res.notes.append("the model does not fit, but no candidate effect and no recalibration explains the "
                             "gap significantly; see the disagreement table")
    else:
        res.terms_after = refit_base(inp, st, final, res.notes)
        res.gap_after = gap_metric(meas, model_avar(res.terms_after, meas.tau, inp.rate_hz))
    res.regions_after = disagreements(meas, model_avar(res.terms_after, meas.tau, inp.rate_hz))
    if not inp.simulate:
        return
    if res.terms_after is terms0:
        res.sim_avar_after, res.gap_sim_after, res.sim_check_after = (res.sim_avar_before, res.gap_sim_before,
                                                                      res.sim_check_before)
    else:
        res.sim_avar_after, res.gap_sim_after, res.sim_check_after = sim_checks(res.terms_after, meas, inp.seed + 1,
                                                                                inp.t_series)


def refit_base(inp: GapInput, st: GapState, final: list, notes: list) -> list:
    """The model after with every term refitted to the data at once (the verdicts above keep the tests that
    named each change): a model term held at a value the steps found consistent, or an added effect fitted
    before a later one, can leave the sum outside the measurement's band where the model handed over was
    mis-sized. The white level of the analysis (``inp.white``), when given, is the model's N: the model's
    white-noise term is held at it (the rate rounding's white share taken out in quadrature), so that the
    report, the model after and ``analyze`` carry one N. Terms with no free parameter stay fixed. The
    magnitudes are the maximum-likelihood ones, or the band's (:mod:`companion.gap.band_fit`) where those put
    the model inside the measurement's 95 % band at more cluster times."""
    from companion.gap.candidates import fit_terms

    terms = [dict(t) for t in final]
    fixed = [i for i in st.fixed if i < len(terms)]
    j = next((i for i, t in enumerate(terms) if t["effect"] == "white_noise" and i not in fixed), None)
    if inp.white and inp.white.get("N") and j is not None:
        nq2 = sum(terms[i]["N"] ** 2 for i in fixed if terms[i]["effect"] == "white_noise")
        terms[j]["N"] = float(np.sqrt(max(inp.white["N"] ** 2 - nq2, 0.0)))
        fixed = sorted(set(fixed) | {j})
    before = st.base.dev if st.base is not None else np.inf
    f = fit_terms(inp.meas, terms, fixed, intervals=False)
    band = better_in_band(inp.meas, terms, fixed, f.s)
    if band is not None:
        f.terms = band[0]
    n0 = len(inp.terms0)
    out = [t for i, t in enumerate(f.terms) if i in fixed or i < n0 or t[MAGNITUDE[t["effect"]]] > 0]
    mags = [(t["effect"], MAGNITUDE[t["effect"]], t[MAGNITUDE[t["effect"]]], u[MAGNITUDE[t["effect"]]])
            for t, u in zip(f.terms, terms)]
    moved = [f"{e} {p}" for e, p, new, old in mags if abs(new - old) > 1e-3 * max(old, 1e-300)]
    if moved or j in fixed:
        notes.append("the model after: every term refitted to the data together"
                     + (f" ({', '.join(moved)} moved" + ("" if band is not None else
                                                            f"; deviance {f.dev:.1f} against {before:.1f} with the "
                                                            "values the steps left") + ")" if moved else "")
                     + ("; magnitudes by the band's weights (EDF/2 per point), which put the model inside the "
                        "measurement's 95 % band at more cluster times than the likelihood with its 5 % model "
                        "floor" if band is not None else "")
                     + ("; white_noise N held at the analysis' white level of the same data (companion analyze)"
                        if inp.white and j in fixed else ""))
    return out


def _remaining_gap(inp: GapInput, st: GapState, res: GapResult) -> None:
    """What the gap left means on this record: over the cluster times it resolves, from a record long
    enough for the term named, and how often the model after leaves one as large (companion.gap.null)."""
    meas, rate_hz = inp.meas, inp.rate_hz
    record_s = max(len(s_) for s_ in inp.y_segs) / rate_hz
    resolved_gap(res, meas, record_s)
    record_rule_notes(res, record_s, rate_hz)
    changed = res.terms_after is not inp.terms0
    resolved_over = res.gap_after_resolved is not None and res.gap_after_resolved > NOISE_FLOOR_G
    if not (changed and (res.gap_after > NOISE_FLOOR_G or resolved_over)):
        return
    res.gap_after_null = null_gap(res.terms_after, [len(s_) for s_ in inp.y_segs], rate_hz, res.gap_after,
                                  res.gap_after_resolved, res.resolved_tau_max, seed=inp.seed + 7,
                                  t_segs=inp.t_smooth or None) if inp.simulate else None
    nl = null_text(res.gap_after_null, res.gap_after, res.gap_after_resolved) if res.gap_after_null else ""
    if res.gap_after > NOISE_FLOOR_G:
        res.notes.append(f"a gap remains above the noise floor (G = {res.gap_after:.2f} > {NOISE_FLOOR_G}): "
                         "the data hold something none of the seven effects describes well"
                         + strongest_left(res) + resolved_text(res, meas) + nl)
    else:
        res.notes.append(f"over the cluster times the record resolves (tau <= {res.resolved_tau_max:.3g} s, a "
                         f"tenth of the record) G = {res.gap_after_resolved:.2f} > {NOISE_FLOOR_G}, although G "
                         f"over all of them is {res.gap_after:.2f}" + nl)


#: the workflow's steps, in the order they run (module docstring)
STEPS = (_compare, _rate_rounding, _forward, _drop_unneeded, _undo_recalibrations, _weigh_riders, _filter_again,
         _verdicts, _remaining_gap)


def run_gap(y, rate_hz: float, terms, axis: str = "gx", lsb: float | None = None, seed: int = 0,
            simulate: bool = True, max_iter: int = MAX_ITER, cutoff_hz: float | None = None, filter_order: int = 2,
            lowpass: bool = True, segments=None, temperature=None, integrated: bool = False,
            white: dict | None = None) -> GapResult:
    """Run the whole workflow on rate samples ``y`` (SI) against the model ``terms`` of one axis.

    ``segments``: several still segments of one record (rate arrays); the Allan variance is then pooled
    over them (:func:`companion.gap.compare.measure_pooled`) and ``y`` may be None. ``temperature``: the
    log's temperature channel, aligned with ``segments`` (or with ``y``). ``lsb``: the output step of the
    data (None: detected from the values). ``cutoff_hz``: the low-pass cut-off of the logged data from the
    log's parameters (the filter candidate then uses it; None: fitted); ``lowpass`` False leaves the filter
    out of the candidates (data known to be unfiltered); ``integrated``: each logged value is the mean of
    the filtered rate over its interval (PX4 sensor_combined), not a point sample. ``simulate`` False skips
    the checks by simulation (the analytic curves only). ``white``: the analysis' white level of the same data
    ({"N", "ci95"}, SI; :func:`companion.analysis.stream.axis_entry`), which the model after and the
    datasheet verdict then carry."""
    opts = GapOptions(axis=axis, lsb=lsb, seed=seed, simulate=simulate, max_iter=max_iter, cutoff_hz=cutoff_hz,
                      filter_order=filter_order, lowpass=lowpass, integrated=integrated, white=white)
    inp = _prepare(y, rate_hz, terms, segments, temperature, opts)
    res = GapResult(axis=axis, measured=inp.meas, terms_before=inp.terms0, terms_after=inp.terms0,
                    gap_before=float("nan"), gap_after=float("nan"))
    st = GapState(current=[dict(t) for t in inp.terms0], held=set())
    for step in STEPS:
        step(inp, st, res)
    return res
