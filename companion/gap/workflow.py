"""The simulation-vs-measurement gap workflow: compare, name the missing effect, add it, refit, re-simulate.

1. Measured overlapping AVAR with EDF and 95 % band (:func:`companion.gap.compare.measure`).
2. The model's AVAR, analytic from its terms, and confirmed by simulating the model with
   :func:`companion.sim.synth.synthesize_axis` (same rate and length, fixed seed): G_sim compares the
   measurement with the simulated curve, and the simulated curve with the analytic one.
3. Disagreement regions: consecutive cluster times where the measurement leaves the model's 95 % band.
4. Evidence rule. Every candidate effect the model lacks (quantization, white_noise, bias_instability,
   random_walk, ramp; gauss_markov and sinusoid even when one is present: a second time scale) is fitted
   jointly with the model's own terms (magnitudes free) by maximum likelihood (candidates.py). The
   candidate with the smallest D + 2 k (AIC; k its number of parameters) is added when its deviance gain
   over the recalibrated model, Delta D = D_base - D_cand (a likelihood ratio, chi^2_k under the null by
   Wilks' theorem), divided by the sandwich overdispersion phi of its magnitude at the base fit
   (:func:`companion.gap.candidates.lr_inflation` in the direction of its unit column: correlated, low-EDF
   long-tau estimates under flicker and random-walk noise), exceeds chi^2_k(1 - ALPHA), ALPHA = 1e-4 (a
   stringent level: grids over tau_c and freq_hz make the nominal level optimistic; the null benchmark in
   benchmarks/bench_gap.py measures the real false-alarm rate). Repeat until no candidate passes.
5. Mis-sized terms: a model term is recalibrated only when holding it at its model value (all else
   refitted) costs more deviance than chi^2_1(1 - ALPHA_RECAL), ALPHA_RECAL = 1e-3 (likelihood-ratio test,
   divided by the sandwich overdispersion phi_i of :func:`companion.gap.candidates.lr_inflation`, which
   accounts for the correlated, low-EDF long-tau estimates of flicker and random-walk noise; evaluated
   under the null, i.e. at the fit with the term held);
   otherwise the model value is kept. A term refitted to zero that fails the test is reported as not seen.
   Among candidates, a two-parameter effect gives way to the one-parameter limit it is near (Gauss-Markov
   with tau_c in the upper half of the log tau range -> random walk, lower half -> white noise) unless it is
   significantly better (:func:`_nested_test`: against random walk the
   likelihood ratio corrected for correlated long-tau estimates exceeds chi^2_1(1 - ALPHA_RECAL); against
   white noise the raw one exceeds chi^2_1(1 - ALPHA)). When the limit wins, the Gauss-Markov fit is
   reported as an alternative the record cannot rule out.
6. Noise floor: the model fits within the noise when the gap metric G <= NOISE_FLOOR_G = 2 (G is 1 on
   average for a right model; the null benchmark gives its spread) and nothing is added or recalibrated.
   An added sinusoid is checked against the periodogram (:func:`companion.gap.spectral.line_evidence`):
   the explanation says whether a line carrying its power is there or the Allan bump is some broader shape.
7. Known LSB (rate rounding, e.g. int16 mrad/s RAW_IMU): a white term N_q = LSB sqrt(tau0/12) with no free
   parameter is added first when it lowers the deviance of the unrecalibrated model by more than
   chi^2_1(1 - ALPHA); see :mod:`companion.allan.lsb`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats

from companion.allan.adev import oavar
from companion.allan.lsb import DITHER_RATIO
from companion.gap import explain
from companion.gap.candidates import (MAGNITUDE, N_PARAMS, SHAPE, _intervals, fit_terms, fit_with_candidate,
                                     gm_rw_direction, lr_inflation, unit_column)
from companion.gap.compare import (Measured, disagreements, gap_metric, gap_vs_simulation, measure,
                                   model_avar)
from companion.gap._edf import local_slope, oavar_edf
from companion.gap.spectral import line_evidence
from companion.sim.synth import synthesize_axis

ALPHA = 1e-4
#: level of the per-term likelihood-ratio test that declares a model term mis-sized
ALPHA_RECAL = 1e-3
#: one-parameter limits of two-parameter effects (Gauss-Markov: tau_c >> T is a rate random walk,
#: tau_c << tau0 white noise; IEEE 952 C.6)
NESTED = {"gauss_markov": ("random_walk", "white_noise")}
NOISE_FLOOR_G = 2.0
MAX_ITER = 4
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

    def to_dict(self) -> dict:
        m = self.measured
        return {
            "axis": self.axis,
            "gap_before": self.gap_before,
            "gap_after": self.gap_after,
            "gap_metric": "G = mean_i nu_i (a_i/s_i - 1 - ln(a_i/s_i)) / E0(nu_i); 1 on average when the model is right",
            "noise_floor": NOISE_FLOOR_G,
            "gap_sim_before": self.gap_sim_before,
            "gap_sim_after": self.gap_sim_after,
            "sim_check_before": self.sim_check_before,
            "sim_check_after": self.sim_check_after,
            "fits_within_noise": self.fits_within_noise,
            "added": self.added,
            "recalibrated": self.recalibrated,
            "iterations": self.iterations,
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


def _simulate(terms, meas: Measured, seed: int):
    """Simulate the model at the measurement's rate and length; its AVAR at the same m, with EDF."""
    n = min(meas.n, SIM_MAX_SAMPLES)
    if not terms:
        return None, None
    y = synthesize_axis(terms, meas.rate_hz, n, np.random.default_rng(seed))
    m = meas.m[meas.m <= n // 2]
    if m.shape[0] < meas.m.shape[0]:
        return None, None
    _, avar, _, _ = oavar(y, meas.rate_hz, m=m)
    s = model_avar(terms, meas.tau, meas.rate_hz)
    nu = oavar_edf(n + 1, m, local_slope(meas.tau, s))
    return avar, nu


def _sim_checks(terms, meas: Measured, seed: int):
    avar, nu = _simulate(terms, meas, seed)
    if avar is None:
        return None, None, None
    g_meas_sim = gap_vs_simulation(meas, avar, nu)
    sim_meas = Measured(tau=meas.tau, avar=np.maximum(avar, 1e-300), m=meas.m, nu=1.0 / (1.0 / nu + 0.05**2 / 2),
                        rate_hz=meas.rate_hz, n=meas.n)
    g_sim_analytic = gap_metric(sim_meas, model_avar(terms, meas.tau, meas.rate_hz))
    return avar, g_meas_sim, g_sim_analytic


def _nearer_limit(meas: Measured, cand) -> str | None:
    """The one-parameter limit a two-parameter candidate is near: for Gauss-Markov, random walk when its
    tau_c lies in the upper half of the measured tau range (log scale), white noise in the lower half."""
    limits = NESTED.get(cand[1])
    if not limits:
        return None
    tau_c = cand[2].terms[-1]["tau_c"]
    return limits[0] if tau_c >= math.sqrt(meas.tau[0] * meas.tau[-1]) else limits[1]


def _nested_test(meas: Measured, best, limit) -> dict:
    """Is the two-parameter candidate ``best`` significantly better than its one-parameter limit ``limit``?

    Likelihood ratio LR = D_limit - D_best. Gauss-Markov against random walk (lambda = 1/tau_c -> 0): the
    long-tau octave estimates that carry the difference are correlated and few in EDF, so the raw LR is
    overdispersed (64 random-walk draws, 2 h at 20 Hz, benchmarks/bench_gap.py: raw up to 20.3, corrected up
    to 7.2); it is divided by the sandwich
    factor phi_lambda of :func:`companion.gap.candidates.lr_inflation` in the direction
    :func:`companion.gap.candidates.gm_rw_direction` and compared with chi^2_1(1 - ALPHA_RECAL) = 10.8, the
    level of the mis-sized test. Against white noise (tau_c << tau0) the raw LR is compared with
    chi^2_1(1 - ALPHA) = 15.1."""
    lr_raw = best[3] - limit[3]
    if limit[1] == "random_walk":
        fit_limit = limit[2]
        i = len(fit_limit.terms) - 1
        phi = lr_inflation(meas, fit_limit, i, direction=gm_rw_direction(meas, fit_limit.terms[i]["K"]))
        threshold = float(stats.chi2.isf(ALPHA_RECAL, 1))
    else:
        phi, threshold = 1.0, delta_crit(1)
    return {"limit": limit[1], "lr": lr_raw / phi, "lr_raw": lr_raw, "inflation": phi, "threshold": threshold}


def _strongest_left(res: GapResult) -> str:
    """'; the strongest candidate left, ...' from the last iteration's rejected test, or ''."""
    last = res.iterations[-1] if res.iterations else {}
    t = last.get("test")
    if not t or last.get("chosen") or t["lr"] <= 0:
        return ""
    cand = next((c for c in last["candidates"] if c["effect"] == t["effect"]), None)
    params = ", ".join(f"{k} = {v:.3g}" for k, v in (cand or {}).get("params", {}).items())
    return (f"; the strongest candidate left, {t['effect']} ({params}), has LR {t['lr']:.1f} < {t['threshold']:.1f}: "
            "suggestive, not significant at the documented level")


def _candidate_effects(terms) -> list[str]:
    present = {t["effect"] for t in terms}
    return [e for e in MAGNITUDE if e not in present or e in SHAPE]


def _params(term) -> dict:
    return {k: v for k, v in term.items() if k != "effect"}


def run_gap(y, rate_hz: float, terms, axis: str = "gx", lsb: float | None = None, seed: int = 0,
            simulate: bool = True, max_iter: int = MAX_ITER) -> GapResult:
    """Run the whole workflow on rate samples ``y`` (SI) against the model ``terms`` of one axis."""
    meas = measure(y, rate_hz)
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
        lsb = detect_lsb(y)
    if lsb and not any(t["effect"] == "quantization" for t in terms0):
        N_q = lsb * math.sqrt(1.0 / (12.0 * rate_hz))
        sigma = float(np.std(np.diff(np.asarray(y, dtype=float))) / math.sqrt(2.0))
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

    # 4-5. iterate: recalibrate, try every candidate, add the best significant one
    base = fit_terms(meas, current, fixed=fixed)
    alternatives: dict[int, dict] = {}  # index of an added term -> the two-parameter effect it won over
    for it in range(max_iter):
        cands = []
        for effect in _candidate_effects(current):
            f = fit_with_candidate(meas, current, fixed, effect)
            k = N_PARAMS[effect]
            mag = f.terms[-1][MAGNITUDE[effect]]
            cands.append((f.dev + 2 * k, effect, f, base.dev - f.dev, k, mag))
        cands.sort(key=lambda c: c[0])
        record = {"iteration": it + 1, "gap_base": base.gap,
                  "candidates": [{"effect": c[1], "delta_dev": c[3], "k": c[4], "gap": c[2].gap,
                                  "params": _params(c[2].terms[-1])} for c in cands],
                  "threshold": {k: delta_crit(k) for k in (1, 2)}}
        best = next((c for c in cands if c[5] > 0), None)
        alternative = None
        if best is not None:  # Occam: a nested one-parameter limit that is not significantly worse wins
            near = _nearer_limit(meas, best)
            for c in cands:
                if c[1] == near and c[5] > 0:
                    nested = _nested_test(meas, best, c)
                    record["nested"] = nested
                    if nested["lr"] < nested["threshold"]:
                        alternative = {**_params(best[2].terms[-1]), "effect": best[1], "lr": nested["lr"],
                                       "instead_of": c[1]}
                        best = c
                    break
        if best is not None:  # the same overdispersion correction as the mis-sized test (score form)
            phi = lr_inflation(meas, base, None, direction=unit_column(best[2].terms[-1], meas.tau, rate_hz))
            record["test"] = {"effect": best[1], "lr": best[3] / phi, "lr_raw": best[3], "inflation": phi,
                              "threshold": delta_crit(best[4])}
        if best is None or best[3] / phi <= delta_crit(best[4]):
            record["chosen"] = None
            res.iterations.append(record)
            break
        _, effect, f, dd, k, _ = best
        record["chosen"] = effect
        record["gap_after"] = f.gap
        res.iterations.append(record)
        if alternative is not None:
            alternatives[len(current)] = alternative
        current = f.terms
        fixed = list(fixed)
        base = fit_terms(meas, current, fixed=fixed)
        # shapes of the added GM/sinusoid: intervals with the shape free
        free = [i for i in range(len(current)) if i not in fixed]
        _intervals(meas, base, free, shape_free=[i for i in range(len(terms0), len(current))
                                                 if current[i]["effect"] in SHAPE and i not in fixed])

    # 5. keep model values that the data do not contradict
    final = [dict(t) for t in base.terms]
    for i, t0 in enumerate(terms0):
        p = MAGNITUDE[t0["effect"]]
        fitted = base.terms[i][p]
        lo, hi = base.ci95[i].get(p, [fitted, fitted])
        ratio = fitted / t0[p] if t0[p] > 0 else math.inf
        entry = {"effect": t0["effect"], "param": p, "model": t0[p], "fitted": fitted, "ratio": ratio,
                 "ci95": [lo, hi]}
        # likelihood-ratio test: this term held at its model value, everything else refitted
        held = [dict(t) for t in base.terms]
        held[i][p] = t0[p]
        held_fit = fit_terms(meas, held, fixed=sorted(set(fixed) | {i}), intervals=False)
        lr_raw = held_fit.dev - base.dev
        # overdispersion evaluated under the null hypothesis (the term at its model value), as in a score
        # test: a model B larger than the data's gets the wider spread of its own flicker
        phi = lr_inflation(meas, replace(held_fit, fixed=list(fixed)), i)
        lr = lr_raw / phi
        entry.update(lr=lr, lr_raw=lr_raw, inflation=phi)
        if lr <= float(stats.chi2.isf(ALPHA_RECAL, 1)):
            final[i][p] = t0[p]
            entry["verdict"] = "consistent"
        elif fitted == 0:
            entry["verdict"] = "not seen"
            entry["text"] = (f"{t0['effect']} {p}: not seen in the data (95 % upper bound {hi:.3g}, model "
                             f"{t0[p]:.3g})")
        else:
            entry["verdict"] = "too small" if ratio > 1 else "too large"
            entry["text"] = explain.explain_missized(t0["effect"], p, ratio)
        res.recalibrated.append(entry)
    for i in range(len(terms0), len(final)):
        t = final[i]
        if i in fixed:
            continue
        ci = base.ci95[i] if i < len(base.ci95) else {}
        ev = None
        if t["effect"] == "sinusoid" and t["amplitude"] > 0:
            ev = line_evidence(y, rate_hz, t["freq_hz"], t["amplitude"])
        entry = {**t, "ci95": ci, "explanation": explain.explain_added(t, axis, rate_hz, spectral=ev)}
        if ev is not None:
            entry["spectral"] = ev
        if i in alternatives:
            alt = alternatives[i]
            entry["alternative"] = alt
            entry["explanation"] += " " + explain.explain_alternative(alt, meas.n / rate_hz, rate_hz)
        res.added.append(entry)
    s_final = model_avar(final, meas.tau, rate_hz)
    g_final = gap_metric(meas, s_final)
    changed = any(e["verdict"] != "consistent" for e in res.recalibrated) or len(final) > len(terms0)
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
                                                                                     seed + 1)
    if changed and res.gap_after > NOISE_FLOOR_G:
        res.notes.append(f"a gap remains above the noise floor (G = {res.gap_after:.2f} > {NOISE_FLOOR_G}): "
                         "the data hold something none of the seven effects describes well" + _strongest_left(res))
    return res
