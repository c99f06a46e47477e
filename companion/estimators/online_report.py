"""What an online estimator reports: the model chosen from the data, resolved values and 95 % bounds.

One code path for ``companion analyze --online`` and ``companion run`` (numpy/scipy only).

Model. The octave bank's Allan variances are fitted with the offline fit's automatic candidates
(quantization, white_noise, bias_instability, random_walk, ramp, gauss_markov; a sinusoid is no automatic
candidate offline either -- on octave-spaced points it fits chance bumps): the offline procedure
:func:`companion.allan.fit.fit_avar` with its automatic selection (BIC over N, B, K; the other effects,
including one Gauss-Markov term with its correlation time, only on very strong evidence; quantization only
where the data show its slope; GLS with the full model covariance of the Allan estimates).
A correlated term the data show is therefore in the model, and its power does not land in N.

Report. For every linear candidate (Q, N, B, K, R):

- *resolved*: the term is in the selected model and the lower end of its 95 % interval (the selection
  envelope below included) is above 0:
  ``{"effect", p: value, "std": {p: 1-sigma}, "ci95": {p: [lo, hi]}, "bound": False}``;
- otherwise a one-sided 95 % *upper bound*: the term is added to the selected model, the GLS is solved
  with theta = p^2 >= 0, and ``ub^2 = max(theta, 0) + 1.645 sd(theta)`` (sd from the inverse Fisher
  information of the GLS; at theta = 0 the marginal with theta freed; for a selected term whose interval
  reaches 0, at least the interval's upper end, and ``"selected": True``):
  ``{"effect", p: ub, "std": {p: ...}, "ci95": {p: [0, ub]}, "bound": True}``.

A bias instability or random walk the record is too short to resolve (fit_avar's record rule) stays in the
model as a nuisance column (``Structure.nuisance``) and is reported as its bound: left out, its share went
into N.

The white-noise term carries the low-pass filter of the logged data as the offline fit models it (the
estimator's ``filter_hz`` from the log, or a roll-off the data show; ``filter_hz`` in the reported term),
so a filter never becomes a Gauss-Markov term (whose tau_c is at least 3 sample periods) nor pulls N's
bound down. Gauss-Markov and sinusoid terms are reported only when selected (their bound would depend on the
unknown shape parameter). Intervals: fit_avar's (scaled chi-square, Satterthwaite); 1-sigma = 95 %
width / 3.92. Coverage is measured in benchmarks/bench_online.py (``coverage``).

Speed. The selection costs 0.2-1 s. :class:`Structure` keeps the chosen model and the covariance of
the Allan estimates at the time of the selection; until the data have grown by ``RESELECT`` (x1.5, or
by 30 min of samples; never before 5 min of new samples) the
coefficients are re-solved with that structure (covariance rescaled by the model ratio per level and by
the number of samples; a few ms), which is what ``companion run`` does between selections.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from companion.allan.terms import BASE_EFFECTS, EFFECTS, LINEAR_EFFECTS, LINEAR_PARAM, white_filter_of
from companion.units import fmt_value as _fmt

#: every effect of the offline model is a candidate of the online model
CANDIDATES = EFFECTS
#: one-sided 95 % normal quantile (upper bounds)
Z_UPPER = 1.6448536269514722
#: re-select the model when the data have grown by this factor since the last selection, or by this many
#: seconds of samples (so that a long run with forgetting still re-selects now and then)
RESELECT = 1.5
RESELECT_MAX_S = 1800.0
#: ... but never before this many seconds of new samples (a selection costs 0.2-1 s: `run` at 30x replay speed)
RESELECT_MIN_S = 300.0
NL_PARAMS = {"gauss_markov": ("sigma", "tau_c"), "sinusoid": ("amplitude", "freq_hz")}


@dataclass
class Structure:
    """The selected model and the covariance of the Allan estimates when it was selected."""

    linear: list
    nonlin: list  # [(effect, shape)]
    m: np.ndarray  # cluster sizes of the fitted levels
    cov: np.ndarray  # SI covariance of the Allan estimates at those levels
    model: np.ndarray  # model AVAR at those levels at selection time
    n: float  # (effective) samples at selection time
    n_raw: int  # samples seen at selection time (for the re-selection rule)
    model_error: float = 0.0
    nl_ci: dict | None = None  # profile intervals of the nonlinear terms from the selection fit
    white: dict | None = None  # low-pass filter of the white-noise term ({"filter_hz", "sample_hz"}), as fitted
    # linear effects the model holds that the record is too short to resolve (fit_avar's record rule): in every
    # solve, never resolved (their bound is reported), so that the others do not take up their share
    nuisance: tuple = ()
    # the cut-off's 95 % interval when the data gave it (N's interval is then profiled over it, as offline)
    white_ci: tuple | None = None
    # the data's first-order reading is in N's profile interval (the selection fit's decision, kept until the next)
    first_order: bool = False


def select(tau, avar, edf, n, rate_hz, candidates=CANDIDATES, n_raw=None, max_ratio=256, white_filter=None,
           detect_filter="point", segments=None):
    """Select the model from the levels with :func:`companion.allan.fit.fit_avar` (automatic selection over
    ``candidates``; the white-noise term's low-pass filter from ``white_filter`` (the log's cut-off) or the data,
    as the offline fit does). Returns ``(FitResult, Structure)``."""
    from companion.allan.confidence import edf_simple
    from companion.allan.fit import AUTO_EFFECTS, fit_avar

    # the offline fit's automatic candidate set (a sinusoid only when the offline fit is asked for one too):
    # one model online and offline, so the same data give the same terms
    candidates = [e for e in candidates if e in AUTO_EFFECTS]
    tau = np.asarray(tau, float)
    m = np.round(tau * rate_hz).astype(np.int64)
    n = max(int(n), int(2 * m.max() + 2)) if m.size else int(n)
    edf0 = np.maximum(edf_simple(n + 1, m, 0), 0.5)
    pooled = segments is not None and len(segments) > 1
    # the selection's linear intervals are not used (report() computes the report's own): not inverted here
    fr = fit_avar(tau, avar, edf0, effects=list(candidates), n=n, rate_hz=rate_hz, m=m, max_ratio=max_ratio,
                  select=True, white_filter=white_filter, detect_filter=detect_filter,
                  segments=list(segments) if pooled else None, inverted_ci=False)
    return fr, structure_from_fit(fr, tau, avar, edf0, rate_hz, n, n_raw)


def structure_from_fit(fr, tau, avar, edf0, rate_hz, n, n_raw=None) -> Structure:
    """The :class:`Structure` of a :func:`companion.allan.fit.fit_avar` result on the levels ``tau, avar``."""
    tau = np.asarray(tau, float)
    m = np.round(tau * rate_hz).astype(np.int64)
    edf0 = np.asarray(edf0, float)
    linear = [t["effect"] for t in fr.terms if t["effect"] in LINEAR_EFFECTS]
    nonlin = [(t["effect"], float(t[NL_PARAMS[t["effect"]][1]])) for t in fr.terms if t["effect"] in NL_PARAMS]
    keep = np.isin(np.round(tau * rate_hz).astype(np.int64), np.round(fr.tau * rate_hz).astype(np.int64))
    cov = fr.avar_cov if fr.avar_cov is not None else np.diag(2.0 * np.asarray(avar)[keep] ** 2 / edf0[keep])
    model = np.maximum(np.asarray(fr.avar_fit, float), 1e-300) if len(fr.avar_fit) else np.asarray(avar)[keep]
    nl_ci = {t["effect"]: t.get("ci95", {}) for t in fr.terms if t["effect"] in NL_PARAMS}
    flt = getattr(fr, "filter", None) or {}
    white = white_filter_of(flt)
    white_ci = tuple(flt["ci95"]) if flt.get("source") == "data" and flt.get("ci95") else None
    nuisance = tuple(t["effect"] for t in getattr(fr, "nuisance", ()) if t["effect"] in LINEAR_EFFECTS)
    return Structure(linear, nonlin, m[keep], np.asarray(cov, float), model, float(n),
                     int(n if n_raw is None else n_raw), float(fr.model_error), nl_ci, white, nuisance, white_ci,
                     bool(flt.get("first_order_in_ci")))


def bounds_for_fit(fr, tau, avar, edf0, rate_hz, n, effects=("white_noise", "bias_instability", "random_walk")):
    """95 % upper bounds (report format, ``"bound": True``) of the ``effects`` an offline fit left out, with
    the same rule as the online report: what ``companion analyze`` prints instead of '-'."""
    if not (fr.terms or getattr(fr, "nuisance", None)):
        return []
    st = structure_from_fit(fr, tau, avar, edf0, rate_hz, n)
    keep = np.isin(np.round(np.asarray(tau, float) * rate_hz).astype(np.int64), st.m)
    have = {t["effect"] for t in fr.terms}
    missing = tuple(e for e in effects if e not in have)
    if not missing:
        return []
    return [t for t in report(np.asarray(tau, float)[keep], np.asarray(avar, float)[keep], st, missing)
            if t.get("bound")]


def _inverted_bounds(fr, tau, avar, n, rate_hz, segments=None) -> list:
    """The 95 % upper bounds by test inversion (:func:`companion.allan.fit.upper_bounds`, what ``companion
    analyze`` reports) of the N/B/K terms the selection ``fr`` left out, on the points it saw. The online
    report's own rule evaluates the points' covariance at the fitted model, where the left-out term is 0, and
    bounded a rate random walk left out of 2-h records below its truth in 9 of 17 draws (1 of 17 here)."""
    from companion.allan.fit import upper_bounds

    if not (fr.terms or getattr(fr, "nuisance", None)):
        return []
    m = np.round(np.asarray(tau, float) * rate_hz).astype(np.int64)
    keep = np.isin(m, np.round(np.asarray(fr.tau, float) * rate_hz).astype(np.int64))
    n = max(int(n), int(2 * m.max() + 2)) if m.size else int(n)
    pooled = segments is not None and len(segments) > 1
    return upper_bounds(fr, np.asarray(tau, float)[keep], np.asarray(avar, float)[keep], n=n, rate_hz=rate_hz,
                        m=m[keep], segments=list(segments) if pooled else None)


def _larger_bound(t: dict, b: dict) -> dict:
    """Of two 95 % upper bounds (report format) of one term, the larger: both hold, the larger surely."""
    p = LINEAR_PARAM[t["effect"]]
    return b if float(b[p]) > float(t[p]) else t


def _model_effects(st: Structure) -> list:
    """The linear columns of the structure's model: the selected effects, then the nuisance ones."""
    return list(st.linear) + [e for e in st.nuisance if e not in st.linear]


def _problem(tau, avar, cov):
    from companion.allan.fit import _Problem

    scale = float(np.median(avar[avar > 0])) if np.any(avar > 0) else 1.0
    return _Problem(tau, avar / scale, cov / scale**2), scale


def _marginal_var(prob, A, theta, i):
    """Variance of theta_i from the Fisher information, with theta_i freed if it sits at the bound 0."""
    Aw = prob._w(A)
    F = Aw.T @ Aw
    idx = np.flatnonzero((theta > 0) | (np.arange(A.shape[1]) == i))
    cov = np.linalg.pinv(F[np.ix_(idx, idx)])
    return float(cov[list(idx).index(i), list(idx).index(i)])


@dataclass
class _Solved:
    """The structure's model solved on the current levels (scaled by ``scale``: the median AVAR)."""

    prob: object  # companion.allan.fit._Problem: the GLS problem of the levels
    scale: float
    mod: list  # the linear columns (selected, then nuisance effects)
    theta: np.ndarray  # linear then nonlinear amplitudes, scaled
    c2: float  # the fit's chi-square
    cov_t: np.ndarray  # covariance of theta (zero rows for terms at the bound)


def report(tau, avar, st: Structure, candidates=CANDIDATES, cov=None, level=0.95):
    """Resolved terms and bounds (see the module docstring) from the levels ``tau, avar`` (restricted to the
    structure's levels) and the covariance ``cov`` of the Allan estimates (default: the structure's)."""
    tau = np.asarray(tau, float)
    avar = np.asarray(avar, float)
    cov = st.cov if cov is None else cov
    out = []
    if tau.size == 0 or not np.any(avar > 0):
        return out
    sol = _solve(tau, avar, st, cov)
    resolved, unsure = _resolved_terms(sol, tau, st, candidates, level)
    for e in LINEAR_EFFECTS:
        if e not in candidates:
            continue
        if e in resolved:
            out.append(resolved[e])
            continue
        out.append(_bound_term(sol, tau, st, e, unsure))
    out += _nonlinear_terms(sol, st, level)
    return out


def _solve(tau, avar, st: Structure, cov) -> _Solved:
    from companion.allan.fit import _columns  # scipy-free

    prob, scale = _problem(tau, avar, cov)
    mod = _model_effects(st)
    A = _columns(mod, st.nonlin, tau, st.white)
    theta, c2 = prob.solve(A) if A.shape[1] else (np.zeros(0), 0.0)
    cov_t = np.zeros((len(theta), len(theta)))
    act = theta > 0
    if act.any():
        cov_t[np.ix_(act, act)] = prob.cov_theta(A[:, act])
    return _Solved(prob, scale, mod, theta, c2, cov_t)


def _resolved_terms(sol: _Solved, tau, st: Structure, candidates, level):
    """({effect: resolved term}, {effect: upper end of the interval of a selected term not resolved}).

    Selection uncertainty: the interval of a resolved term is the envelope of its intervals in the selected
    model and in the model with every base effect (N, B, K) forced in -- a base effect the selection left
    out (e.g. a bias instability hidden under a Gauss-Markov hump) can otherwise shift N beyond its interval
    (solved only when that model has more terms: the selected one with N, B and K in is the same model)."""
    from companion.allan.fit import _profile_white_ci, _scaled_chi2_ci, forced_intervals  # scipy-free

    prob, scale, mod, theta = sol.prob, sol.scale, sol.mod, sol.theta
    sup = [x for x in LINEAR_EFFECTS if x in mod or (x in BASE_EFFECTS and x in candidates)]
    forced = forced_intervals(prob, sup, st.nonlin, tau, st.white, level) if set(sup) != set(mod) else {}
    resolved, unsure = {}, {}
    for j, e in enumerate(st.linear):
        if theta[j] <= 0:
            continue
        lo, hi = _scaled_chi2_ci(theta[j], sol.cov_t[j, j], level)
        if e in forced:
            lo, hi = min(lo, forced[e][0]), max(hi, forced[e][1])
        # resolved only when the envelope, too, stays clear of 0: a term whose interval reaches 0 in the model
        # with N, B and K in is not told from the others; it stays in the model and its bound (at least the
        # envelope's upper end) is reported
        if lo <= 0:
            unsure[e] = hi
            continue
        p = LINEAR_PARAM[e]
        v, lo_p, hi_p = (math.sqrt(x * scale) for x in (theta[j], lo, hi))
        if e == "white_noise" and st.white:
            # N and a cut-off found in the data are correlated: N's profile interval over it (and over the
            # roll-off's order, with the log's cut-off too), as offline
            (lo_p, hi_p), _ = _profile_white_ci([lo_p, hi_p], prob, prob, mod, st.nonlin, tau, st.white,
                                                st.white_ci, sol.c2, scale, level, float(tau[0] / st.m[0]),
                                                first_order=st.first_order)
        resolved[e] = {"effect": e, p: v, "std": {p: (hi_p - lo_p) / 3.92}, "ci95": {p: [lo_p, hi_p]},
                       "bound": False}
        if e == "white_noise" and st.white:
            resolved[e]["filter_hz"] = float(st.white["filter_hz"])
            if st.white.get("filter_order"):
                resolved[e]["filter_order"] = int(st.white["filter_order"])
    return resolved, unsure


def _bound_term(sol: _Solved, tau, st: Structure, e: str, unsure: dict) -> dict:
    """The one-sided 95 % upper bound of a linear effect not resolved: solved with it in (beside the model's
    other linear effects), theta_e + Z_UPPER sd (sd from the Fisher information, freed at the bound 0), at
    least the upper end of its interval when it was selected."""
    from companion.allan.fit import _columns  # scipy-free

    p = LINEAR_PARAM[e]
    lin = [x for x in LINEAR_EFFECTS if x == e or (x in sol.mod and x != e)]
    A2 = _columns(lin, st.nonlin, tau, st.white)
    th2, _ = sol.prob.solve(A2)
    i = lin.index(e)
    var = _marginal_var(sol.prob, A2, th2, i)
    th_i = max(float(th2[i]), 0.0)
    ub = max(th_i + Z_UPPER * math.sqrt(max(var, 0.0)), unsure.get(e, 0.0))
    ub_p = math.sqrt(ub * sol.scale)
    sd_p = math.sqrt((th_i + math.sqrt(max(var, 0.0))) * sol.scale) - math.sqrt(th_i * sol.scale)
    term = {"effect": e, p: ub_p, "std": {p: sd_p}, "ci95": {p: [0.0, ub_p]}, "bound": True}
    if e in unsure:
        term["selected"] = True  # in the model, not resolved: kept there between selections
    return term


def _nonlinear_terms(sol: _Solved, st: Structure, level) -> list:
    """The selected Gauss-Markov / sinusoid terms with their amplitude's interval (the envelope of this fit's
    and the selection fit's profile interval) and the shape parameter's profile interval."""
    from companion.allan.fit import _scaled_chi2_ci  # scipy-free

    out = []
    for k, (e, shape) in enumerate(st.nonlin):
        j = len(sol.mod) + k
        if sol.theta[j] <= 0:
            continue
        lp, sp = NL_PARAMS[e]
        lo, hi = _scaled_chi2_ci(sol.theta[j], sol.cov_t[j, j], level)
        v, lo_p, hi_p = (math.sqrt(x * sol.scale) for x in (sol.theta[j], lo, hi))
        ci = dict((st.nl_ci or {}).get(e, {}))
        lo_p, hi_p = min(lo_p, ci.get(lp, [lo_p])[0]), max(hi_p, ci.get(lp, [0, hi_p])[1])
        out.append({"effect": e, lp: v, sp: shape, "std": {lp: (hi_p - lo_p) / 3.92},
                    "ci95": {lp: [lo_p, hi_p], sp: list(ci.get(sp, [shape, shape]))}, "bound": False})
    return out


def rescaled_cov(st: Structure, tau, avar, n):
    """The selection-time covariance rescaled to the current data: per level by the ratio of the current
    fitted model to the selection-time model (AVAR estimates' sd scale with the AVAR), and by n_sel / n."""
    from companion.allan.fit import _columns

    prob, scale = _problem(tau, avar, st.cov * (st.n / max(float(n), 1.0)))
    A = _columns(_model_effects(st), st.nonlin, tau, st.white)
    if A.shape[1] == 0:
        return st.cov
    theta, _ = prob.solve(A)
    model = np.maximum(A @ theta * scale, 1e-300)
    r = model / st.model
    return st.cov * (st.n / max(float(n), 1.0)) * np.outer(r, r)


def estimator_report(est, candidates=None, full=False):
    """The report of an :class:`companion.estimators.octave_bank.OctaveBankEstimator` (``fit="model"``):
    a fresh selection when ``full`` or when due (no structure yet, or the data grew by RESELECT), else the
    cached structure with a rescaled covariance. Caches the structure on ``est._structure``, and the last
    report on ``est._report_cache``: asked again before a new sample, it is returned as it was."""
    candidates = tuple(candidates or est.effects)
    # the same samples, filter and request give the same report (between two checks in flight or while the
    # vehicle moves no still sample arrives): the last one is returned, at no fitting cost
    key = (est.n_samples, tuple(est.segments()) if hasattr(est, "segments") else (), bool(full), candidates,
           getattr(est, "filter_hz", None), getattr(est, "sampling", None))
    last = getattr(est, "_report_cache", None)
    if last is not None and last[0] == key and last[1] is getattr(est, "_structure", None):
        return copy.deepcopy(last[2])
    out = _estimator_report(est, candidates, full)
    est._report_cache = (key, getattr(est, "_structure", None), copy.deepcopy(out))
    return out


def _estimator_report(est, candidates, full):
    tau, avar, edf = est.avar()
    use = edf >= est.min_edf
    tau, avar, edf = tau[use], avar[use], edf[use]
    if tau.size < 3 or not np.any(avar > 0):
        return []
    n_eff = est.n_effective()
    st = getattr(est, "_structure", None)
    m_now = np.round(tau * est.rate_hz).astype(np.int64)
    grown = est.n_samples - st.n_raw if st is not None else 0
    due = st is None or (grown >= RESELECT_MIN_S * est.rate_hz and
                         (est.n_samples >= RESELECT * st.n_raw or grown >= RESELECT_MAX_S * est.rate_hz))
    if full or due or not np.all(np.isin(st.m, m_now)):
        fh = getattr(est, "filter_hz", None)
        samp = getattr(est, "sampling", "point")
        wf = {"filter_hz": fh, "sample_hz": est.rate_hz if samp == "point" else None} if fh else None
        segs = est.segments() if hasattr(est, "segments") and est.forgetting_s is None else None
        fr, st = select(tau, avar, edf, n_eff, est.rate_hz, candidates, n_raw=est.n_samples, white_filter=wf,
                        detect_filter=samp, segments=segs)
        est._structure = st
        est._bounds = _inverted_bounds(fr, tau, avar, n_eff, est.rate_hz, segs)
        cov = None
    else:
        cov = None
    keep = np.isin(m_now, st.m)
    tau, avar = tau[keep], avar[keep]
    if cov is None and st.n_raw != est.n_samples:
        cov = rescaled_cov(st, tau, avar, n_eff)
    out = report(tau, avar, st, candidates, cov=cov)
    # between selections: a selected term the current data no longer resolve leaves the structure for this
    # refit (kept in, an unsupported column lets the correlated GLS trade it against N: N 10 % low measured)
    gone = [t["effect"] for t in out if t.get("bound") and t["effect"] in st.linear and not t.get("selected")]
    if gone and len(gone) < len(st.linear):
        from dataclasses import replace

        st2 = replace(st, linear=[e for e in st.linear if e not in gone])
        out = report(tau, avar, st2, candidates, cov=cov)
    # a left-out N/B/K: the larger of this refit's bound and the selection's bound by test inversion (the
    # offline analysis' bound; a bound from the data of the selection still bounds the term with more data)
    cached = {b["effect"]: b for b in getattr(est, "_bounds", None) or ()}
    out = [_larger_bound(t, cached[t["effect"]]) if t.get("bound") and t["effect"] in cached else t for t in out]
    # the offline analysis' rules on N: under misfit N from the white-noise region, and N resolved only where
    # white noise dominates above the filter's corner (else its filter-aware bound)
    from companion.allan.confidence import edf_simple
    from companion.allan.white import apply_white_rules

    m = np.round(tau * est.rate_hz).astype(np.int64)
    edf0 = np.maximum(edf_simple(int(n_eff) + 1, m, 0), 0.5)
    out, _ = apply_white_rules(out, tau, avar, edf0, 1.0 / est.rate_hz, st.model_error, st.white)
    return out


# ---------------------------------------------------------------- presentation (tables, summaries)
def value_of(terms, param):
    """``(value, std, bound)`` of ``param`` in a list of reported terms, or None."""
    for t in terms or ():
        if param in t and param in t.get("std", {}):
            return float(t[param]), float(t["std"][param]), bool(t.get("bound", False))
    return None


def health_params(terms):
    """``{param: (value, std)}`` of the resolved linear parameters only: a bound is no value to compare."""
    out = {}
    for t in terms or ():
        p = LINEAR_PARAM.get(t.get("effect"))
        if p and not t.get("bound") and p in t:
            out[p] = (float(t[p]), float(t.get("std", {}).get(p, math.inf)))
    return out




def _digits(v: float, s: float | None) -> str:
    """``v`` with two significant digits of its uncertainty ``s`` (3 significant digits without one)."""
    if s is None or not (s > 0 and math.isfinite(s)) or not math.isfinite(v) or abs(v) >= 1e5 or abs(v) < 1e-3:
        return _fmt(v)
    dec = max(0, 1 - math.floor(math.log10(s)))
    return f"{v:.{dec}f}"


def cell(terms, param, axis, interval=True) -> str:
    """Table text of one reported parameter in datasheet units: ``1.047 [1.041, 1.053]`` for a resolved
    value (``1.047 +- 0.0031`` with ``interval=False``; digits from the uncertainty), ``< 3.1`` for a 95 %
    upper bound, ``n/a`` when the parameter was not estimated."""
    from companion import units

    for t in terms or ():
        if param in t and param not in ("tau_c", "freq_hz"):
            v = units.to_datasheet(param, t[param], axis)
            s = t.get("std", {}).get(param)
            s = units.to_datasheet(param, s, axis) if s is not None else None
            if t.get("bound"):
                return f"< {_fmt(v)}"
            if interval and param in t.get("ci95", {}):
                lo, hi = (units.to_datasheet(param, x, axis) for x in t["ci95"][param])
                return f"{_digits(v, s)} [{_digits(lo, s)}, {_digits(hi, s)}]"
            return f"{_digits(v, s)} +- {_fmt(float(f'{s:.2g}'))}" if s is not None else _fmt(v)
    return "n/a"


def extra_text(terms, axis) -> list[str]:
    """Text of the resolved terms other than N, B, K (Q, R, Gauss-Markov, sinusoid) in datasheet units."""
    from companion import units

    out = []
    for t in terms or ():
        e = t.get("effect")
        if t.get("bound") or e in ("white_noise", "bias_instability", "random_walk"):
            continue
        if e in NL_PARAMS:
            lp, sp = NL_PARAMS[e]
            out.append(f"{e} {lp} {cell([t], lp, axis, False)} {units.datasheet_unit(lp, axis)}, "
                       f"{sp} {_fmt(t[sp])} {units.datasheet_unit(sp, axis)}")
        else:
            p = LINEAR_PARAM[e]
            out.append(f"{p} {cell([t], p, axis, False)} {units.datasheet_unit(p, axis)}")
    return out


def summary_line(terms, axis, baseline=None) -> str:
    """One line per axis for ``companion run``'s summary: N, B, K (value +- 1-sigma, or ``< bound``), the
    ratio to a resolved baseline value for resolved values, then the other resolved terms."""
    from companion import units

    parts = []
    for p in ("N", "B", "K"):
        txt = cell(terms, p, axis, interval=False)
        if txt == "n/a":
            continue
        vb = value_of(terms, p)
        if baseline and vb and not vb[2] and p in baseline and baseline[p][0] > 0:
            txt += f" ({vb[0] / baseline[p][0]:.2f}x baseline)"
        parts.append(f"{p} {txt} {units.datasheet_unit(p, axis)}")
    return "; ".join(parts + extra_text(terms, axis))
