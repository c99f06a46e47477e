"""The simulation-vs-measurement gap workflow: compare, name the missing effect, add it, refit, re-simulate.

1. Measured overlapping AVAR with EDF and 95 % band (:func:`companion.gap.compare.measure`).
2. The model's AVAR, analytic from its terms, and confirmed by simulating the model with
   :func:`companion.sim.synth.synthesize_axis` (same rate and length, fixed seed): G_sim compares the
   measurement with the simulated curve, and the simulated curve with the analytic one.
3. Disagreement regions: consecutive cluster times where the measurement leaves the model's 95 % band.
4-5. Explanations weighed head to head (:mod:`companion.gap.selection`). From the current state (model
   terms held at their values unless recalibrated, effects added earlier free) every explanation is fitted
   by maximum likelihood on the same data: each effect the model lacks added (quantization, white_noise,
   bias_instability, random_walk, ramp; gauss_markov and sinusoid also a second time), each held model
   term recalibrated, each effect with one term recalibrated. One criterion ranks them:
   score = Delta D / phi - penalty (deviance removed, divided by its sandwich overdispersion at the state,
   :func:`companion.gap.candidates.lr_inflation`; penalty chi^2_k(1 - ALPHA) per added effect with k
   parameters, chi^2_1(1 - ALPHA_RECAL) per recalibrated term). The best is taken when its score is
   positive; its runner-up and the margin are reported (``alternatives``). A Gauss-Markov winner gives way
   to the one-parameter limit it is near (random walk, added or the model's own recalibrated; white noise)
   unless significantly better (:func:`companion.gap.selection.nested_test`), and is then reported as the
   alternative the record cannot rule out. Repeat until no explanation scores above zero; then a
   recalibration that later additions made unnecessary (holding the term at its model value costs
   LR <= chi^2_1(1 - ALPHA_RECAL)) is undone. A freed term refitted to zero is reported as not seen.
6. Noise floor: the model fits within the noise when the gap metric G <= NOISE_FLOOR_G = 2 (G is 1 on
   average for a right model; the null benchmark gives its spread) and nothing is added or recalibrated.
   An added sinusoid is checked against the periodogram (:func:`companion.gap.spectral.line_evidence`):
   the explanation says whether a line carrying its power is there or the Allan bump is some broader shape;
   a sinusoid explanation whose line the periodogram rules out (no peak where it had the power to show one)
   leaves the ranking at every step (:func:`_line_veto`).
7. Known LSB (rate rounding, e.g. int16 mrad/s RAW_IMU): a white term N_q = LSB sqrt(tau0/12) with no free
   parameter is added first when it lowers the deviance of the unrecalibrated model by more than
   chi^2_1(1 - ALPHA); see :mod:`companion.allan.lsb`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from companion.allan.adev import oavar
from companion.allan.lsb import DITHER_RATIO
from companion.gap import explain, selection, trend
from companion.gap.candidates import (MAGNITUDE, SHAPE, Fit, _intervals, fit_terms, lr_inflation,
                                     refine_shapes, unit_column)
from companion.gap.compare import (Measured, disagreements, gap_metric, gap_vs_simulation, measure,
                                   measure_pooled, model_avar)
from companion.gap._edf import local_slope, oavar_edf
from companion.gap.null import null_gap, null_text, resolved_subset, synthesize_model
from companion.gap.spectral import line_evidence, significant_lines
from companion.gap.thermal import regression_check, thermal_term

ALPHA = selection.ALPHA
ALPHA_RECAL = selection.ALPHA_RECAL
NESTED = selection.NESTED
NOISE_FLOOR_G = 2.0
#: steps (an effect added, a term recalibrated, or both) before stopping
MAX_ITER = 6
SHORT_TAU_EFFECTS = selection.SHORT_TAU_EFFECTS
SIM_MAX_SAMPLES = 2_000_000


def delta_crit(k: int) -> float:
    return float(stats.chi2.isf(ALPHA, max(k, 1)))


@dataclass
class GapResult:
    axis: str
    measured: Measured
    terms_before: list
    terms_after: list
    gap_before: float
    gap_after: float
    gap_sim_before: float | None = None
    gap_sim_after: float | None = None
    sim_check_before: float | None = None  # simulated vs analytic, model before
    sim_check_after: float | None = None
    sim_avar_before: np.ndarray | None = None
    sim_avar_after: np.ndarray | None = None
    regions_before: list = field(default_factory=list)
    regions_after: list = field(default_factory=list)
    added: list = field(default_factory=list)  # [{"effect", params..., "ci95", "explanation"}]
    recalibrated: list = field(default_factory=list)  # [{"effect", "param", "model", "fitted", "ratio", ...}]
    iterations: list = field(default_factory=list)
    fits_within_noise: bool = False
    notes: list = field(default_factory=list)
    quantization: dict | None = None
    alternatives: list = field(default_factory=list)  # per chosen step: its runner-up and the margin
    #: G after over the cluster times the record resolves (tau <= a tenth of the longest segment: the
    #: analysis' rule, companion.allan.fit.RESOLVE_RECORD_FACTOR), when longer ones were measured
    gap_after_resolved: float | None = None
    resolved_tau_max: float | None = None
    #: when a gap remains: G's spread for the model after on this record's layout (companion.gap.null)
    gap_after_null: dict | None = None

    def to_dict(self) -> dict:
        m = self.measured
        return {
            "axis": self.axis,
            "gap_before": self.gap_before,
            "gap_after": self.gap_after,
            "gap_metric": "G = mean_i nu_i (a_i/s_i - 1 - ln(a_i/s_i)) / E0(nu_i); 1 on average when the model is right",
            "noise_floor": NOISE_FLOOR_G,
            "gap_after_resolved": self.gap_after_resolved,
            "resolved_tau_max": self.resolved_tau_max,
            "gap_after_null": self.gap_after_null,
            "gap_sim_before": self.gap_sim_before,
            "gap_sim_after": self.gap_sim_after,
            "sim_check_before": self.sim_check_before,
            "sim_check_after": self.sim_check_after,
            "fits_within_noise": self.fits_within_noise,
            "added": self.added,
            "recalibrated": self.recalibrated,
            "iterations": self.iterations,
            "alternatives": self.alternatives,
            "disagreements_before": [r.as_dict() for r in self.regions_before],
            "disagreements_after": [r.as_dict() for r in self.regions_after],
            "terms_before": self.terms_before,
            "terms_after": self.terms_after,
            "quantization": self.quantization,
            "notes": self.notes,
            "measured": {"tau": m.tau.tolist(), "adev": np.sqrt(m.avar).tolist(), "edf": m.nu_raw.tolist(),
                         "rate_hz": m.rate_hz, "samples": m.n},
        }


def detect_lsb(y, rel_tol: float = 1e-3) -> float | None:
    """The quantisation step of ``y`` if (nearly) all values are integer multiples of one step, else None."""
    y = np.asarray(y, dtype=float)
    if y.size < 100:
        return None
    u = np.unique(y[: min(y.size, 200_000)])
    if u.size < 3 or u.size > y.size // 4:
        return None
    d = np.diff(u)
    step = float(np.min(d[d > 0]))
    k = (u - u[0]) / step
    if np.mean(np.abs(k - np.round(k)) < rel_tol * 100) < 0.999:
        return None
    return step


def _simulate(terms, meas: Measured, seed: int, t_series=None):
    """Simulate the model at the measurement's rate and length; its AVAR at the same m, with EDF."""
    n = min(meas.n, SIM_MAX_SAMPLES)
    if not terms:
        return None, None
    y = synthesize_model(terms, meas.rate_hz, n, np.random.default_rng(seed), t_series)
    m = meas.m[meas.m <= n // 2]
    if m.shape[0] < meas.m.shape[0]:
        return None, None
    _, avar, _, _ = oavar(y, meas.rate_hz, m=m)
    s = model_avar(terms, meas.tau, meas.rate_hz)
    nu = oavar_edf(n + 1, m, local_slope(meas.tau, s))
    return avar, nu


def _sim_checks(terms, meas: Measured, seed: int, t_series=None):
    avar, nu = _simulate(terms, meas, seed, t_series)
    if avar is None:
        return None, None, None
    g_meas_sim = gap_vs_simulation(meas, avar, nu)
    sim_meas = Measured(tau=meas.tau, avar=np.maximum(avar, 1e-300), m=meas.m, nu=1.0 / (1.0 / nu + 0.05**2 / 2),
                        rate_hz=meas.rate_hz, n=meas.n)
    g_sim_analytic = gap_metric(sim_meas, model_avar(terms, meas.tau, meas.rate_hz))
    return avar, g_meas_sim, g_sim_analytic


def _strongest_left(res: GapResult) -> str:
    """'; the strongest explanation left, ...' from the last iteration's ranking when nothing was chosen."""
    last = res.iterations[-1] if res.iterations else {}
    t = last.get("test")
    if not t or last.get("chosen") or t["lr"] <= 0:
        return ""
    top = (last.get("explanations") or [{}])[0]
    params = ", ".join(f"{k} = {v:.3g}" for k, v in top.get("params", {}).items())
    params = f" ({params})" if params else ""
    return (f"; the strongest explanation left, {t['effect']}{params}, has LR {t['lr']:.1f} < {t['threshold']:.1f}: "
            "suggestive, not significant at the documented level")


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


def _spectral_line(ranked, y, rate_hz):
    """The strongest sinusoid explanation that fell short of its level (chi^2_2(1 - ALPHA) = 18.4, the
    frequency searched over the Allan profile) is taken at the level of a known-shape term
    (chi^2_1(1 - ALPHA_RECAL) = 10.8) when the periodogram confirms a line at its frequency carrying its
    power (:func:`companion.gap.spectral.line_evidence`, itself a test at 1e-3 over the band's bins):
    the frequency is then a property of the data, as a log's filter cut-off is. Returns (explanation or
    None, note)."""
    for x in ranked[:6]:
        if x.effect != "sinusoid" or x.recal:
            continue
        t = x.added_term()
        if x.delta_dev - x.inflation * selection.RECAL_PENALTY <= 0:
            return None, ""
        ev = line_evidence(y, rate_hz, t["freq_hz"], t["amplitude"])
        if ev is None or not ev["confirmed"]:
            return None, ""
        x.penalty = selection.RECAL_PENALTY
        return x, (f"sinusoid at {t['freq_hz']:.4g} Hz: LR {x.lr:.1f} on the Allan curve is short of the "
                   f"{selection.add_penalty(2):.1f} of a searched frequency, but the periodogram shows the line "
                   f"({ev['peak_ratio']:.1f}x the local level at {ev['f_peak']:.4g} Hz, carrying "
                   f"{ev['amplitude_psd'] / t['amplitude']:.2f} of its amplitude): taken at the level of a known "
                   f"frequency, {selection.RECAL_PENALTY:.1f}")
    return None, ""


def _line_veto(y, rate_hz: float):
    """A veto for :func:`companion.gap.selection.choose`: a sinusoid explanation whose line the periodogram
    rules out (no significant peak in its band, where a line of half its amplitude would show with
    probability >= 1 - 1e-3: :func:`companion.gap.spectral.line_evidence`). Its Allan bump is then some
    other shape: near the Nyquist frequency a line's bump sits on the shortest cluster times, as angle
    quantisation's rise does, and without the veto the line took it. Where the periodogram lacks the
    resolution (a slow line in a short record) the sinusoid stays in the running on the Allan curve alone.
    Returns veto(explanation) -> reason or None."""
    cache: dict = {}

    def veto(x):
        if x.effect != "sinusoid" or x.delta_dev <= 0 or y is None:
            return None
        t = x.added_term()
        key = (round(math.log(t["freq_hz"]), 6), round(math.log(max(t["amplitude"], 1e-300)), 6))
        if key not in cache:
            cache[key] = line_evidence(y, rate_hz, t["freq_hz"], t["amplitude"])
        ev = cache[key]
        if ev is None or not ev["ruled_out"]:
            return None
        return (f"a sinusoid at {t['freq_hz']:.4g} Hz (amplitude {t['amplitude']:.3g}, score {x.score:.1f} on the "
                f"Allan curve) is ruled out by the periodogram: peak {ev['peak_ratio']:.3g}x the local level against "
                f"{ev['threshold']:.3g} needed, where a line of half that amplitude would show with probability "
                f"{ev['power']:.4f}")
    return veto


#: drift-like effects a temperature-driven rate is a look-alike of on the Allan curve
_DRIFTS = ("ramp", "random_walk", "gauss_markov", "sinusoid", "bias_instability")


def _thermal_arbitration(ranked, chosen, y_segs, t_smooth, rate_hz):
    """The temperature channel as independent evidence between look-alikes the Allan curve cannot
    separate: a drift-like winner gives way to the temperature explanation when that one also passes its
    level on the Allan curve (score > 0) and the direct regression of the rate on the channel confirms its
    coefficient; a temperature winner that the regression does not confirm gives way to the best other
    explanation. Returns (explanation to take or None, note)."""
    temp = next((x for x in ranked if x.effect == "temperature" and not x.recal), None)
    if chosen.effect == "temperature":
        chk = regression_check(y_segs, t_smooth, chosen.added_term()["coef"], rate_hz)
        if chk["confirmed"]:
            return chosen, ""
        other = next((x for x in ranked if x.effect != "temperature" and x.score > 0), None)
        return other, ("a temperature-shaped drift fits the Allan curve but the regression on the temperature "
                       f"channel does not confirm it (slope t = {chk['t']:.1f}, ratio {chk.get('ratio', 0):.2g}): "
                       "not named")
    if chosen.effect in _DRIFTS and temp is not None and temp.score > 0:
        chk = regression_check(y_segs, t_smooth, temp.added_term()["coef"], rate_hz)
        if chk["confirmed"]:
            return temp, (f"{chosen.effect} and a temperature-driven rate both explain the Allan curve (scores "
                          f"{chosen.score:.1f}, {temp.score:.1f}); the temperature channel decides: regression "
                          f"slope t = {chk['t']:.1f}, coefficient ratio {chk['ratio']:.2f}")
        return chosen, (f"{chosen.effect} and a temperature-driven rate both explain the Allan curve (scores "
                        f"{chosen.score:.1f}, {temp.score:.1f}); the temperature channel does not confirm the "
                        f"latter beyond a straight drift (regression t = {chk['t']:.1f}, coefficient ratio "
                        f"{chk['ratio']:.2g}): {chosen.effect} is named")
    return chosen, ""


def _refit(meas: Measured, terms, held, n_model: int) -> Fit:
    """Refit the free magnitudes; intervals for them and for the shapes of added Gauss-Markov/sinusoid terms."""
    fit = fit_terms(meas, terms, fixed=sorted(held))
    free = [i for i in range(len(terms)) if i not in held]
    _intervals(meas, fit, free, shape_free=[i for i in range(n_model, len(terms))
                                            if terms[i]["effect"] in SHAPE and i not in held])
    return fit


def _hold_test(meas: Measured, base: Fit, held, i: int, t0) -> tuple:
    """Likelihood ratio of holding the freed model term ``i`` back at its model value (all else refitted),
    divided by the sandwich overdispersion evaluated under that null (score form: a model B larger than
    the data's gets the wider spread of its own flicker). Returns (lr, lr_raw, phi, held fit)."""
    p = MAGNITUDE[t0["effect"]]
    terms = [dict(t) for t in base.terms]
    terms[i][p] = t0[p]
    shaped = [j for j in range(len(terms)) if terms[j]["effect"] in SHAPE and j not in held and j != i]
    hf = refine_shapes(meas, terms, sorted(set(held) | {i}), shaped)
    lr_raw = hf.dev - base.dev
    phi = lr_inflation(meas, hf, None, direction=[unit_column(terms[i], meas.tau, meas.rate_hz)])
    return lr_raw / phi, lr_raw, phi, hf


def _added_level(term, y, rate_hz: float) -> float:
    """The level an added effect passed: chi^2_k(1 - ALPHA) for k free parameters (a Gauss-Markov term's
    tau_c and a sinusoid's searched frequency count), a sinusoid whose line the periodogram confirms at
    that of a known frequency (chi^2_1(1 - ALPHA_RECAL), as when it was taken)."""
    if term["effect"] == "sinusoid" and y is not None:
        ev = line_evidence(y, rate_hz, term["freq_hz"], term["amplitude"])
        if ev is not None and ev.get("confirmed"):
            return selection.RECAL_PENALTY
    return selection.add_penalty(2 if term["effect"] in SHAPE else 1)


def _drop_unneeded(meas: Measured, base: Fit, held, n_model: int, alternatives: dict, y, rate_hz: float):
    """Backward step for added effects, the counterpart of undoing a recalibration: each effect added at
    one step is taken out with the rest refitted (magnitudes; shapes as they stand); when putting it back
    no longer passes the level it passed when it was added (corrected LR, overdispersion under that null), the
    weakest such effect is removed, and the test is repeated. A later addition can make an earlier one
    unnecessary: a sinusoid first fitted at a frequency 7 % off, then a second at the periodogram's line,
    left the first at a tenth of the amplitude. Returns (terms, held, alternatives, notes)."""
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
            level = _added_level(t, y, rate_hz)
            if lr <= level and (weakest is None or lr / level < weakest[0]):
                weakest = (lr / level, i, lr, level, without)
        if weakest is None:
            return terms, held, alternatives, notes
        _, i, lr, level, without = weakest
        t = terms[i]
        notes.append(f"{t['effect']} ({', '.join(f'{k} {v:.3g}' for k, v in _params(t).items())}), added at one "
                     f"step, is no longer needed after a later one (putting it back: LR {lr:.1f} <= {level:.1f}): "
                     "dropped")
        keep = [j for j in range(len(terms)) if j != i]
        index = {j: k for k, j in enumerate(keep)}
        held = {index[j] for j in held if j != i}
        alternatives = {index[j]: v for j, v in alternatives.items() if j != i}
        terms = [dict(without.terms[j]) for j in keep]
        shaped = [j for j in range(n_model, len(terms)) if terms[j]["effect"] in SHAPE and j not in held]
        terms = refine_shapes(meas, terms, sorted(held), shaped).terms  # the state changed: shapes again


def _penalised_dev(meas: Measured, terms, held, terms0, y, rate_hz: float) -> float:
    """Deviance plus the level each added effect passed (a fitted filter on a model's white term 15.1):
    the criterion two final states are compared by."""
    dev = fit_terms(meas, terms, sorted(held), intervals=False).dev
    for i, t in enumerate(terms):
        if i in held:
            continue
        if i >= len(terms0):
            dev += _added_level(t, y, rate_hz)
        elif t.get("cutoff_hz") and not terms0[i].get("cutoff_hz"):
            dev += selection.add_penalty(1)
    return dev


def _filter_or_gauss_markov(meas: Measured, base: Fit, held, terms0, lp, y, rate_hz: float, alternatives: dict,
                            veto):
    """The filter rule decides between a fitted low-pass filter and a short Gauss-Markov term at the step
    where they compete, in the state of that step: with another effect not yet named (a vibration line at
    the Gauss-Markov term's cluster times) the Gauss-Markov fit is pulled to a few samples' tau_c, the filter
    wins, and later steps patch what it leaves (a hidden tau_c 0.25 s term beside a 1.4 Hz line ended as a
    1 Hz filter + the line + quantization). In the final state the filter is taken out and the step weighed
    again (the same choice and rules); when a Gauss-Markov term wins there, the effects it makes unnecessary
    are dropped (backward step) and the two final states are compared by deviance plus the levels their
    added effects passed. Returns (terms, held, alternatives, note) for the Gauss-Markov state when it is
    the better one, else None."""
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
    x = step["chosen"]
    if x is None or x.effect != "gauss_markov":
        return None
    alt = dict(alternatives)
    if step["alternative"] is not None:
        alt[len(x.fit.terms) - 1] = step["alternative"]
    terms, held2, alt, dropped = _drop_unneeded(meas, x.fit, held, n_model, alt, y, rate_hz)
    before = _penalised_dev(meas, base.terms, held, terms0, y, rate_hz)
    after = _penalised_dev(meas, terms, held2, terms0, y, rate_hz)
    if after >= before:
        return None
    fc = ", ".join(f"{base.terms[j]['cutoff_hz']:.3g} Hz" for j in js)
    gm = [t for t in terms[n_model:] if t["effect"] == "gauss_markov"][-1]
    note = (f"the low-pass filter fitted at one step ({fc}) was weighed again in the final state: a "
            f"Gauss-Markov term (tau_c {gm['tau_c']:.3g} s) explains the short cluster times better there "
            f"(deviance + levels {after:.1f} against {before:.1f}) and is taken instead"
            + ("; " + "; ".join(dropped) if dropped else ""))
    return terms, held2, alt, note


def _params(term) -> dict:
    return {k: v for k, v in term.items() if k != "effect"}


def run_gap(y, rate_hz: float, terms, axis: str = "gx", lsb: float | None = None, seed: int = 0,
            simulate: bool = True, max_iter: int = MAX_ITER, cutoff_hz: float | None = None, filter_order: int = 2,
            lowpass: bool = True, segments=None, temperature=None, integrated: bool = False) -> GapResult:
    """Run the whole workflow on rate samples ``y`` (SI) against the model ``terms`` of one axis.

    ``segments``: several still segments of one record (rate arrays); the Allan variance is then pooled
    over them (:func:`companion.gap.compare.measure_pooled`) and ``y`` may be None. ``cutoff_hz``: the
    low-pass cut-off of the logged data from the log's parameters (the filter candidate then uses it; None:
    fitted); ``lowpass`` False leaves the filter out of the candidates (data known to be unfiltered);
    ``integrated``: each logged value is the mean of the filtered rate over its interval (PX4
    sensor_combined), not a point sample."""
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
    lp = (cutoff_hz, int(filter_order), bool(integrated)) if lowpass else None
    if y is not None:  # the lines the periodogram shows are candidates at their own frequency
        meas.lines = significant_lines(y, rate_hz)
    # the log's temperature channel (aligned with ``segments``, or with ``y``): a temperature-driven rate
    y_segs = segments if segments is not None else [y]
    t_segs = None
    if temperature is not None:
        t_segs = temperature if segments is not None else [temperature]
    thermal, t_smooth = thermal_term(t_segs, rate_hz, meas.tau)
    t_series = np.concatenate(t_smooth) if t_smooth else None
    terms0 = [dict(t) for t in terms]
    s0 = model_avar(terms0, meas.tau, rate_hz) if terms0 else np.full_like(meas.tau, 1e-300)
    res = GapResult(axis=axis, measured=meas, terms_before=terms0, terms_after=terms0,
                    gap_before=gap_metric(meas, s0), gap_after=float("nan"))
    res.regions_before = disagreements(meas, s0)
    if simulate and terms0:
        res.sim_avar_before, res.gap_sim_before, res.sim_check_before = _sim_checks(terms0, meas, seed)

    current = [dict(t) for t in terms0]
    fixed: list[int] = []

    # 7. known LSB: rate rounding as a fixed white term
    if lsb is None:
        lsb = detect_lsb(y_all)
    if lsb and not any(t["effect"] == "quantization" for t in terms0):
        N_q = lsb * math.sqrt(1.0 / (12.0 * rate_hz))
        sigma = float(np.std(np.diff(np.asarray(y_all, dtype=float))) / math.sqrt(2.0))
        q = {"lsb": lsb, "N_q": N_q, "sigma_sample_lsb": sigma / lsb, "dithered": sigma >= DITHER_RATIO * lsb,
             "added": False}
        qterm = {"effect": "white_noise", "N": N_q}
        if not q["dithered"]:
            res.notes.append(f"samples rounded to LSB {lsb:.4g}: noise per sample {sigma / lsb:.2f} LSB < "
                             f"{DITHER_RATIO} LSB, not dithered: the rounding error follows the signal, short-tau "
                             "ADEV describes the quantiser, not the sensor; no quantisation term is added")
        elif terms0:
            d_without = fit_terms(meas, current, fixed=range(len(current)), intervals=False).dev
            d_with = fit_terms(meas, current + [qterm], fixed=range(len(current) + 1), intervals=False).dev
            q["delta_dev"] = d_without - d_with
            if d_without - d_with > delta_crit(1):
                current.append(qterm)
                fixed.append(len(current) - 1)
                q["added"] = True
                res.added.append({"effect": "quantization", "form": "rate_lsb", "lsb": lsb, "N": N_q,
                                  "model_term": dict(qterm),
                                  "explanation": explain.explain_rate_quantization(lsb, N_q, axis)})
            else:
                res.notes.append(f"rate rounding to LSB {lsb:.4g} adds white noise N_q = {N_q:.3g}; it does not "
                                 "change the fit measurably (indistinguishable from the model's N)")
        res.quantization = q

    # 4-5. every explanation weighed from the same state by one criterion (companion.gap.selection): an
    # effect added, a model term recalibrated, both; model terms stay at their values unless freed
    held = set(range(len(terms0))) | set(fixed)
    base = _refit(meas, current, held, len(terms0))
    cache: dict = {}

    def detrended():
        """The record with its least-squares line out (measured once, when a ramp and a random walk first
        compete), the fixed terms' indices and the segments' lengths (s)."""
        if "meas" not in cache:
            cache["meas"] = trend.detrended_measure(y_segs, rate_hz)
        return cache["meas"], sorted(fixed), [len(s) / rate_hz for s in y_segs]
    alternatives: dict[int, dict] = {}  # index of a term -> the Gauss-Markov fit it won over
    veto = _line_veto(y, rate_hz)
    for it in range(max_iter):
        recalibratable = [j for j in range(len(terms0)) if j in held]
        shaped = [i for i in range(len(terms0), len(current)) if current[i]["effect"] in SHAPE and i not in held]
        step = selection.choose(meas, base, sorted(held), recalibratable, shaped=shaped, lowpass=lp, thermal=thermal,
                                detrended=detrended, veto=veto)
        ranked, chosen, top, ru = step["ranked"], step["chosen"], step["best"], step["runner_up"]
        if step["vetoed"] and step["vetoed"][0][0].score > max(0.0, ranked[0].score if ranked else 0.0):
            res.notes.append(step["vetoed"][0][1] + "; the next explanation is weighed instead")
        if chosen is None:  # a vibration line the periodogram shows is a known frequency, not a searched one
            chosen, note = _spectral_line(ranked, y, rate_hz)
            if note:
                res.notes.append(note)
                top = chosen
                ru = selection.runner_up(ranked, chosen)
        if thermal is not None and chosen is not None:
            chosen, note = _thermal_arbitration(ranked, chosen, y_segs, t_smooth, rate_hz)
            if note:
                res.notes.append(note)
                top = chosen if chosen is not None else top
                ru = selection.runner_up(ranked, chosen) if chosen is not None else ru
        record = {"iteration": it + 1, "gap_base": base.gap,
                  "candidates": [{"effect": x.effect, "delta_dev": x.delta_dev, "k": x.k, "gap": x.fit.gap,
                                  "params": _params(x.added_term())} for x in ranked if x.effect and not x.recal],
                  "explanations": [x.as_dict(terms0) for x in ranked[:8]],
                  "threshold": {k: selection.add_penalty(k) for k in (1, 2)},
                  "recal_threshold": selection.RECAL_PENALTY}
        if step["vetoed"]:
            record["vetoed"] = [{"explanation": x.label(terms0), "score": x.score, "reason": r}
                                for x, r in step["vetoed"][:4]]
        if step["nested"]:
            record["nested"] = step["nested"]
        if step["trend"]:
            record["trend"] = step["trend"]
            res.notes.append(explain.explain_trend(step["trend"]))
        if top is not None:
            record["test"] = {"effect": top.label(terms0), "lr": top.lr, "lr_raw": top.delta_dev,
                              "inflation": top.inflation, "threshold": top.penalty, "score": top.score}
            record["runner_up"] = ru.as_dict(terms0) if ru is not None else None
        if chosen is None:
            record["chosen"] = None
            res.iterations.append(record)
            break
        record["chosen"] = chosen.label(terms0)
        record["gap_after"] = chosen.fit.gap
        res.iterations.append(record)
        res.alternatives.append({"iteration": it + 1, "chosen": chosen.as_dict(terms0),
                                 "runner_up": ru.as_dict(terms0) if ru is not None else None,
                                 "margin": selection.margin(chosen, ru) if ru is not None else None,
                                 "text": explain.explain_runner_up(chosen.label(terms0), chosen.score,
                                                                   ru.label(terms0) if ru is not None else None,
                                                                   ru.score if ru is not None else None)})
        if step["alternative"] is not None:
            if chosen.effect in (selection.LOWPASS, "temperature"):
                pass
            elif chosen.effect:
                alternatives[len(current)] = step["alternative"]
            else:
                alternatives[[j for j in chosen.recal if current[j]["effect"] == step["nested"]["limit"]][0]] = \
                    step["alternative"]
        current = [dict(t) for t in chosen.fit.terms]
        held -= set(chosen.recal)
        if shaped and (chosen.effect is not None):  # earlier shapes re-optimised in the new state
            current = refine_shapes(meas, current, sorted(held), shaped).terms
        if lp is not None and not lp[0] and chosen.effect in SHORT_TAU_EFFECTS:
            # a fitted cut-off is a shape too: an effect with power at the filter's cluster times (a vibration
            # line near the logger's Nyquist frequency), added after the filter, takes back short-tau power
            # the cut-off had absorbed; a long-tau effect (ramp, random walk) does not compete with it
            current = selection.refine_cutoff(meas, current, sorted(held), lp).terms
        base = _refit(meas, current, held, len(terms0))

    # 5a. an effect that later steps made unnecessary is dropped (backward step, the level it passed)
    current, held, alternatives, dropped = _drop_unneeded(meas, base, held, len(terms0), alternatives, y, rate_hz)
    if dropped:
        res.notes.extend(dropped)
        base = _refit(meas, current, held, len(terms0))

    # 5. a recalibration that later additions made unnecessary is undone (backward step, same test)
    while True:
        weakest = None
        for j in range(len(terms0)):
            if j in held:
                continue
            lr, _, _, hf = _hold_test(meas, base, held, j, terms0[j])
            if lr <= selection.RECAL_PENALTY and (weakest is None or lr < weakest[0]):
                weakest = (lr, j, hf)
        if weakest is None:
            break
        held.add(weakest[1])
        current = [dict(t) for t in weakest[2].terms]
        base = _refit(meas, current, held, len(terms0))
        alternatives.pop(weakest[1], None)

    # 5b. a recalibration taken as the rider of another change (e.g. "gauss_markov + random_walk K" when a
    # ramp also hides in the data) is weighed once more against every effect from the state with that term
    # held: the same score, the recalibration's own (dD - phi x 10.8) against the effect's; against a
    # one-parameter effect that passes its level, the larger likelihood (selection.equal_size_rule)
    for j in range(len(terms0)):
        if j in held or len(current) - len(terms0) >= max_iter:
            continue
        _, lr_raw, phi, hf = _hold_test(meas, base, held, j, terms0[j])
        value = lr_raw - phi * selection.RECAL_PENALTY
        shaped = [i for i in range(len(terms0), len(hf.terms)) if hf.terms[i]["effect"] in SHAPE and i not in held]
        step = selection.choose(meas, hf, sorted(held | {j}), [], shaped=shaped, lowpass=lp, thermal=thermal,
                                detrended=detrended, veto=veto)
        x = step["chosen"]
        if x is None:
            continue
        same_size = x.k == 1 and x.effect not in (selection.LOWPASS, "temperature")
        if (x.delta_dev <= lr_raw) if same_size else (x.score <= value):
            continue
        ru = step["runner_up"]
        mod = terms0[j]["effect"] + " " + MAGNITUDE[terms0[j]["effect"]]
        res.iterations.append({"iteration": len(res.iterations) + 1, "swap": mod, "gap_base": hf.gap,
                               "candidates": [], "explanations": [y.as_dict(terms0) for y in step["ranked"][:8]],
                               "test": {"effect": x.label(terms0), "lr": x.lr, "lr_raw": x.delta_dev,
                                        "inflation": x.inflation, "threshold": x.penalty, "score": x.score},
                               "recalibration_score": value, "chosen": x.label(terms0), "gap_after": x.fit.gap,
                               "runner_up": ru.as_dict(terms0) if ru is not None else None,
                               **({"trend": step["trend"]} if step["trend"] else {})})
        if step["trend"]:
            res.notes.append(explain.explain_trend(step["trend"]))
        res.alternatives.append({"iteration": len(res.iterations), "chosen": x.as_dict(terms0),
                                 "runner_up": {"explanation": f"recalibrated {mod}", "delta_dev": lr_raw,
                                               "inflation": phi, "lr": lr_raw / phi,
                                               "penalty": selection.RECAL_PENALTY, "score": value},
                                 "margin": x.score - value,
                                 "text": explain.explain_runner_up(x.label(terms0), x.score, f"recalibrated {mod}",
                                                                   value)})
        if step["alternative"] is not None and x.effect:
            alternatives[len(hf.terms)] = step["alternative"]
        alternatives.pop(j, None)
        held.add(j)
        current = [dict(t) for t in x.fit.terms]
        base = _refit(meas, current, held, len(terms0))

    # 5c. a fitted filter taken over a short Gauss-Markov term is weighed again in the final state
    if lp is not None and not lp[0]:
        swap = _filter_or_gauss_markov(meas, base, held, terms0, lp, y, rate_hz, alternatives, veto)
        if swap is not None:
            current, held, alternatives, note = swap
            res.notes.append(note)
            base = _refit(meas, current, held, len(terms0))

    final = [dict(t) for t in base.terms]
    for i, t0 in enumerate(terms0):
        p = MAGNITUDE[t0["effect"]]
        entry = {"effect": t0["effect"], "param": p, "model": t0[p]}
        if i in held:  # evidence for freeing it at the final state
            shaped = [j for j in range(len(terms0), len(base.terms)) if base.terms[j]["effect"] in SHAPE
                      and j not in held]
            free_fit = fit_terms(meas, refine_shapes(meas, base.terms, sorted(held - {i}), shaped).terms,
                                 fixed=sorted(held - {i}))
            fitted = free_fit.terms[i][p]
            lo, hi = free_fit.ci95[i].get(p, [fitted, fitted])
            phi = lr_inflation(meas, base, None, direction=[unit_column(base.terms[i], meas.tau, rate_hz)])
            lr_raw = base.dev - free_fit.dev
            lr = lr_raw / phi
        else:  # evidence for holding it back at its model value
            fitted = base.terms[i][p]
            lo, hi = base.ci95[i].get(p, [fitted, fitted])
            lr, lr_raw, phi, _ = _hold_test(meas, base, held, i, t0)
        ratio = fitted / t0[p] if t0[p] > 0 else math.inf
        entry.update(fitted=fitted, ratio=ratio, ci95=[lo, hi], lr=lr, lr_raw=lr_raw, inflation=phi)
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
        res.recalibrated.append(entry)
    for i in range(len(terms0), len(final)):
        t = final[i]
        if i in held:
            continue
        if t[MAGNITUDE[t["effect"]]] <= 0:  # an earlier addition that a later one replaced
            res.notes.append(f"{t['effect']} added at one step was refitted to zero after a later step and is "
                             "dropped")
            continue
        ci = base.ci95[i] if i < len(base.ci95) else {}
        ev = None
        if t["effect"] == "sinusoid" and t["amplitude"] > 0:
            ev = line_evidence(y, rate_hz, t["freq_hz"], t["amplitude"])
        if t["effect"] == "temperature":
            chk = regression_check(y_segs, t_smooth, t["coef"], rate_hz)
            entry = {"effect": "temperature", "coef": t["coef"], "ci95": ci, "check": chk,
                     "explanation": explain.explain_temperature(t["coef"], chk, axis)}
            res.added.append(entry)
            continue
        entry = {**t, "ci95": ci, "explanation": explain.explain_added(t, axis, rate_hz, spectral=ev)}
        if ev is not None:
            entry["spectral"] = ev
        if i in alternatives:
            alt = alternatives[i]
            entry["alternative"] = alt
            entry["explanation"] += " " + explain.explain_alternative(alt, meas.n / rate_hz, rate_hz)
        res.added.append(entry)
    for i, t in enumerate(final):
        if t["effect"] == "white_noise" and t.get("cutoff_hz") and not (i < len(terms0) and terms0[i].get("cutoff_hz")):
            res.added.append(lowpass_entry(t, cutoff_hz, rate_hz, axis, i, terms0))
    final = [t for i, t in enumerate(final) if i < len(terms0) or i in held or t[MAGNITUDE[t["effect"]]] > 0]
    s_final = model_avar(final, meas.tau, rate_hz)
    g_final = gap_metric(meas, s_final)
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
        res.terms_after = final
        res.gap_after = g_final
    res.regions_after = disagreements(meas, model_avar(res.terms_after, meas.tau, rate_hz))
    if simulate:
        if res.terms_after is terms0:
            res.sim_avar_after, res.gap_sim_after, res.sim_check_after = (res.sim_avar_before, res.gap_sim_before,
                                                                          res.sim_check_before)
        else:
            res.sim_avar_after, res.gap_sim_after, res.sim_check_after = _sim_checks(res.terms_after, meas,
                                                                                     seed + 1, t_series)
    record_s = max(len(s_) for s_ in y_segs) / rate_hz
    _resolved_gap(res, meas, record_s)
    _record_rule_notes(res, record_s, rate_hz)
    resolved_over = res.gap_after_resolved is not None and res.gap_after_resolved > NOISE_FLOOR_G
    if changed and (res.gap_after > NOISE_FLOOR_G or resolved_over):
        # how often the model after, on a record like this one, leaves a gap as large (companion.gap.null)
        res.gap_after_null = null_gap(res.terms_after, [len(s_) for s_ in y_segs], rate_hz, res.gap_after,
                                      res.gap_after_resolved, res.resolved_tau_max, seed=seed + 7,
                                      t_segs=t_smooth or None) if simulate else None
        nl = null_text(res.gap_after_null, res.gap_after, res.gap_after_resolved) if res.gap_after_null else ""
        if res.gap_after > NOISE_FLOOR_G:
            res.notes.append(f"a gap remains above the noise floor (G = {res.gap_after:.2f} > {NOISE_FLOOR_G}): "
                             "the data hold something none of the seven effects describes well"
                             + _strongest_left(res) + _resolved_text(res, meas) + nl)
        else:
            res.notes.append(f"over the cluster times the record resolves (tau <= {res.resolved_tau_max:.3g} s, a "
                             f"tenth of the record) G = {res.gap_after_resolved:.2f} > {NOISE_FLOOR_G}, although G "
                             f"over all of them is {res.gap_after:.2f}" + nl)
    return res


def _record_rule_notes(res: GapResult, record_s: float, rate_hz: float) -> None:
    """A long-tau term added from a record shorter than the analysis needs to resolve it
    (:func:`companion.allan.fit.record_needed`): the gap is real, its size is not pinned -- `companion analyze`
    reports a bound for it on the same data, and the two must not read as a contradiction."""
    from companion.allan.fit import record_needed

    added = {a["effect"] for a in res.added}
    plain = [t for t in res.terms_after if t.get("effect") in ("white_noise", "bias_instability", "random_walk",
                                                                "quantization", "ramp")]
    for effect, need in record_needed(plain, 1.0 / rate_hz).items():
        if effect in added and need > record_s:
            res.notes.append(f"{effect} is named from {record_s:.3g} s of data, shorter than the {need:.3g} s a "
                             "resolved value needs (the analysis' record rule): the curve rises there, but the "
                             "size is not pinned; `companion analyze` gives it as a bound on the same data")


def _resolved_gap(res: GapResult, meas: Measured, record_s: float) -> None:
    """G after over the cluster times the record resolves: tau up to a tenth of the longest segment, where
    an Allan variance still has an EDF of about 5 or more whatever the noise (the analysis' rule for a
    long-tau term, companion.allan.fit.RESOLVE_RECORD_FACTOR). Longer octaves are measured and used by the
    fits, but a gap carried by them alone is one the record cannot tell from noise of a few EDF."""
    from companion.allan.fit import RESOLVE_RECORD_FACTOR

    tau_max = record_s / RESOLVE_RECORD_FACTOR
    sub = resolved_subset(meas, tau_max)
    if sub is None:
        return
    res.gap_after_resolved = gap_metric(sub, model_avar(res.terms_after, sub.tau, meas.rate_hz))
    res.resolved_tau_max = float(tau_max)


def _resolved_text(res: GapResult, meas: Measured) -> str:
    if res.gap_after_resolved is None:
        return ""
    out = meas.tau > res.resolved_tau_max
    edf = ", ".join(f"{v:.0f}" for v in meas.nu_raw[out])
    return (f"; over the cluster times the record resolves (tau <= {res.resolved_tau_max:.3g} s, a tenth of the "
            f"record) G = {res.gap_after_resolved:.2f}: the rest sits in {int(out.sum())} longer octave(s) of EDF "
            f"{edf}")
