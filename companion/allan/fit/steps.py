"""The fit's orchestrator :func:`fit_avar` and its steps, each a function over a :class:`FitState`.

Steps, in order: the usable points (:func:`_usable_points`); the candidates and the state
(:func:`_initial_state`); selection and weighting (:func:`~companion.allan.fit.fit_state.iterate`); the
low-pass roll-off (:func:`~companion.allan.fit.rolloff.model_rolloff`); the model error under misfit
(:func:`absorb_misfit`); the final estimates (:func:`final_estimates`); the terms' intervals
(:func:`term_intervals`, :func:`selection_envelope`, :func:`white_profile`); the result (:func:`_result`) and the
record rule (:func:`~companion.allan.fit.record_rule.apply_record_rule`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from companion.allan.fit.constants import (AUTO_EFFECTS, DEFAULT_EDF, INVERT_MAX_NU, MISFIT_SIGMAS, MODEL_ERROR_RANGE,
                                           MODEL_ERROR_STEPS, NL_LINEAR, NL_SHAPE, NONLINEAR_EFFECTS, PROFILE_POINTS)
from companion.allan.fit.fit_state import FitData, FitState, iterate
from companion.allan.fit.gls import _columns, _filter_params, _Problem
from companion.allan.fit.intervals import (_cov_along, _inverted_ci, _profile_ci, _profile_union, _scaled_chi2_ci,
                                           _selection_envelope)
from companion.allan.fit.point_cov import _flicker_shape_cov
from companion.allan.fit.record_rule import apply_record_rule
from companion.allan.fit.fit_result import FitResult
from companion.allan.fit.rolloff import _filter_summary, _profile_white_ci, model_rolloff
from companion.allan.fit.term_selection import quantization_slope
from companion.allan.terms import BASE_EFFECTS, LINEAR_EFFECTS, LINEAR_PARAM, avar_model, white_filter_of

#: the least log2 span of the cluster times taken for the diagonal covariance's density of points
_MIN_OCTAVES = 1e-9


class _Points(NamedTuple):
    """The finite, positive-tau, non-negative points with a positive EDF."""

    tau: np.ndarray
    avar: np.ndarray
    edf: np.ndarray
    m: np.ndarray | None  # cluster sizes, with the record known (else as given)
    full: bool  # n and rate_hz given


@dataclass
class FinalFit:
    """The estimates under the final model (:func:`final_estimates`): the GLS problem ``prob`` and, for the
    intervals, ``prob_ci`` (with the flicker's shape error), the design ``A``, the coefficients ``theta`` (units
    of scale), chi^2 ``c2`` and the coefficients' covariance ``cov_t`` (zero rows for the terms at 0)."""

    prob: _Problem
    prob_ci: _Problem
    A: np.ndarray
    theta: np.ndarray
    c2: float
    cov_t: np.ndarray


def _usable_points(tau, avar, edf, n, rate_hz, m) -> _Points:
    """Step: keep the points with finite tau > 0, AVAR >= 0 and a finite EDF > 0 (DEFAULT_EDF when none is
    given); with the record known (``n``, ``rate_hz``) the cluster sizes m (default round(tau rate_hz))."""
    tau = np.asarray(tau, dtype=float)
    avar = np.asarray(avar, dtype=float)
    ok = np.isfinite(avar) & np.isfinite(tau) & (tau > 0) & (avar >= 0)
    edf_all = (np.full(tau.shape, DEFAULT_EDF) if edf is None
               else np.broadcast_to(np.asarray(edf, dtype=float), tau.shape))
    ok &= np.isfinite(edf_all) & (edf_all > 0)
    full = n is not None and rate_hz is not None
    if full:
        m = np.round(tau[ok] * rate_hz).astype(np.int64) if m is None else np.asarray(m, dtype=np.int64)[ok]
    return _Points(tau[ok], avar[ok], edf_all[ok], m, full)


def _initial_state(pts: _Points, effects, select, white, *, n, rate_hz, segments, level, max_iter,
                   max_ratio) -> FitState:
    """Step: the candidates (quantization only where :func:`quantization_slope` sees its slope; white noise
    alone on fewer than 3 points), the data scaled by their median AVAR, and the diagonal covariance's inflation
    2 x (points per octave) for the correlation of neighbouring points when the record is not known."""
    auto = effects is None if select is None else bool(select)
    effects = list(AUTO_EFFECTS) if effects is None else list(effects)
    bad = [e for e in effects if e not in LINEAR_EFFECTS + NONLINEAR_EFFECTS]
    if bad:
        raise ValueError(f"unknown effect {bad[0]!r}")
    tau, avar = pts.tau, pts.avar
    notes = []
    if auto and "quantization" in effects and not quantization_slope(tau, avar):
        effects.remove("quantization")
    if tau.size < 3:
        effects = [e for e in effects if e in ("white_noise",)] or effects[:1]
        notes.append("fewer than 3 cluster times: only white noise fitted")
    scale = float(np.median(avar[avar > 0]))
    n_pts = tau.size
    inflate = 1.0
    if not pts.full:
        dens = (n_pts - 1) / max(math.log2(tau[-1] / tau[0]), _MIN_OCTAVES) if n_pts > 1 else 1.0
        inflate = 2.0 * max(1.0, dens)
    data = FitData(tau=tau, v=avar / scale, edf=pts.edf, scale=scale, effects=effects, auto=auto, full=pts.full,
                   m=pts.m, n=n, rate_hz=rate_hz, segments=segments, max_ratio=max_ratio, max_iter=max_iter,
                   inflate=inflate, level=level)
    return FitState(data=data, white=white, notes=notes)


def _model_error(st: FitState, dof0: int) -> float:
    """The relative model error e with chi^2 = dof under C + diag((e v_sup)^2): bisection in log e over
    MODEL_ERROR_RANGE (its top where even that leaves chi^2 above dof)."""
    d, mf = st.data, st.model
    A = _columns(mf.linear, mf.nonlin, d.tau, st.white)

    def excess(lf):
        cov = mf.cov + np.diag((math.exp(lf) * mf.v_sup) ** 2)
        return _Problem(d.tau, d.v, cov, st.white, d.tau0).solve(A)[1] - dof0

    lo_f, hi_f = math.log(MODEL_ERROR_RANGE[0]), math.log(MODEL_ERROR_RANGE[1])
    if not excess(hi_f) < 0:
        return MODEL_ERROR_RANGE[1]
    for _ in range(MODEL_ERROR_STEPS):
        mid = 0.5 * (lo_f + hi_f)
        lo_f, hi_f = (mid, hi_f) if excess(mid) > 0 else (lo_f, mid)
    return math.exp(hi_f)


def absorb_misfit(st: FitState) -> None:
    """Step: under model misfit (chi^2 > dof + MISFIT_SIGMAS sqrt(2 dof); real sensors: internal filters at short
    tau, temperature drifts, which are no IEEE 952 term) add a relative model error e to every point, (e
    sigma^2_model)^2 on the diagonal of C, chosen so that chi^2 = dof -- the Birge-ratio / random-effects remedy --
    and select and fit again. Without it the thousands of effective degrees of freedom of the short-tau points
    would let a small systematic misfit there outweigh the whole long-tau region. Simulated data consistent with
    the model do not get here."""
    mf = st.model
    dof0 = st.data.n_pts - len(mf.linear) - 2 * len(mf.nonlin)
    if not (dof0 >= 2 and mf.c2 > dof0 + MISFIT_SIGMAS * math.sqrt(2.0 * dof0)):
        return
    st.floor = _model_error(st, dof0)
    st.model = iterate(st.data, st.white, st.floor)
    st.notes.append(f"model misfit (chi2 {mf.c2:.0f} for {dof0} dof): a model error of {100 * st.floor:.1f} % "
                    "of AVAR per point was added to the covariance")


def final_estimates(st: FitState) -> FinalFit:
    """Step: the coefficients under the final model and their covariance (A^T C^-1 A)^-1. For the intervals of
    the linear terms C also holds the flicker's shape at the first cluster times
    (:func:`~companion.allan.fit.point_cov._flicker_shape_cov`); the selection and the estimates do not use it."""
    d, mf = st.data, st.model
    prob = _Problem(d.tau, d.v, mf.cov, st.white, d.tau0)
    A = _columns(mf.linear, mf.nonlin, d.tau, st.white)
    theta, c2 = prob.solve(A)
    active = theta > 0
    prob_ci = prob
    if d.full and "bias_instability" in mf.linear and theta[mf.linear.index("bias_instability")] > 0:
        b_si = {"effect": "bias_instability", "B": math.sqrt(theta[mf.linear.index("bias_instability")] * d.scale)}
        prob_ci = _Problem(d.tau, d.v, mf.cov + _flicker_shape_cov(b_si, d.m, d.tau) / d.scale**2, st.white, d.tau0)
    cov_t = np.zeros((len(theta), len(theta)))
    if np.any(active):
        cov_t[np.ix_(active, active)] = prob_ci.cov_theta(A[:, active])
    return FinalFit(prob, prob_ci, A, theta, c2, cov_t)


def _linear_term(st: FitState, ff: FinalFit, j, e, lo, hi, inverted_ci) -> dict:
    """A linear term with its interval: the scaled chi-square one ``lo, hi``, or by test inversion with the
    points' covariance along the term (:func:`~companion.allan.fit.intervals._inverted_ci`) unless its pivot's
    nu is at least INVERT_MAX_NU."""
    d = st.data
    theta = ff.theta
    if d.full and inverted_ci and 2.0 * theta[j] ** 2 < INVERT_MAX_NU * ff.cov_t[j, j]:
        lo, hi = _inverted_ci(theta[j], j, ff.A, _cov_along(e, st, theta), d.tau, d.v, st.white, d.tau0, d.level,
                              lo, hi)
    p = LINEAR_PARAM[e]
    t = {"effect": e, p: math.sqrt(theta[j] * d.scale),
         "ci95": {p: [math.sqrt(lo * d.scale), math.sqrt(hi * d.scale)]}}
    if e == "white_noise" and st.white:
        t.update(_filter_params(st.white))
    return t


def _nonlinear_term(st: FitState, ff: FinalFit, j, e, lo, hi) -> dict:
    """A nonlinear term: its shape's profile-likelihood interval, and its linear parameter's interval over the
    shape (sigma or amplitude and the shape are correlated: :func:`~companion.allan.fit.intervals._profile_union`
    over PROFILE_POINTS shapes of that interval)."""
    d, linear, nonlin = st.data, st.model.linear, st.model.nonlin
    shape = dict(nonlin)[e]
    p, s = NL_LINEAR[e], NL_SHAPE[e]
    others = [x for x in nonlin if x[0] != e]
    s_lo, s_hi = _profile_ci(ff.prob, e, shape, linear, others, d.tau, ff.c2, d.level)
    designs = [_columns(linear, others + [(e, float(sh))], d.tau, st.white)
               for sh in np.exp(np.linspace(math.log(s_lo), math.log(s_hi), PROFILE_POINTS))]
    lo, hi = _profile_union(lo, hi, ff.prob, ff.prob, len(linear) + len(others), designs, ff.c2, d.level)
    return {"effect": e, p: math.sqrt(ff.theta[j] * d.scale), s: shape,
            "ci95": {p: [math.sqrt(lo * d.scale), math.sqrt(hi * d.scale)], s: [s_lo, s_hi]}}


def term_intervals(st: FitState, ff: FinalFit, inverted_ci: bool) -> list:
    """Step: the report-format terms with a positive coefficient, each with its ``level`` interval."""
    terms = []
    for j, e in enumerate(st.model.linear + [e for e, _ in st.model.nonlin]):
        if ff.theta[j] <= 0:
            continue
        lo, hi = _scaled_chi2_ci(ff.theta[j], ff.cov_t[j, j], st.data.level)
        if e in LINEAR_EFFECTS:
            terms.append(_linear_term(st, ff, j, e, lo, hi, inverted_ci))
        else:
            terms.append(_nonlinear_term(st, ff, j, e, lo, hi))
    return terms


def selection_envelope(st: FitState, ff: FinalFit, terms: list) -> None:
    """Step: with automatic selection and the record known, widen the linear terms' intervals to the model with
    every base effect forced in (:func:`~companion.allan.fit.intervals._selection_envelope`)."""
    d, linear = st.data, st.model.linear
    sup = [e for e in LINEAR_EFFECTS if e in linear or (e in BASE_EFFECTS and e in d.effects)]
    if d.auto and d.full and set(sup) != set(linear):
        _selection_envelope(terms, ff.prob_ci, sup, st.model.nonlin, d.tau, st.white, d.scale, d.level)


def white_profile(st: FitState, ff: FinalFit, terms: list) -> bool:
    """Step: N and the cut-off of a filtered white-noise term are correlated: N's interval becomes its
    profile-likelihood interval over the cut-off (:func:`~companion.allan.fit.rolloff._profile_white_ci`), the
    union over f_c of N's conditional intervals at the level left once f_c's own chi^2 excess is spent
    (chi^2(f_c) - chi^2_min + z^2 <= chi2_level(1)); the envelope of full-level conditional intervals over f_c's
    interval (the projection) would allow twice that excess. With the log's cut-off (not profiled), over the
    order. Returns whether the first-order reading is in N's interval."""
    wt = next((t for t in terms if t["effect"] == "white_noise"), None) if st.white else None
    if wt is None:
        return False
    d, info = st.data, st.filter_info
    wt["ci95"]["N"], first_order = _profile_white_ci(
        wt["ci95"]["N"], ff.prob, ff.prob_ci, st.model.linear, st.model.nonlin, d.tau, st.white,
        info.ci95 if info is not None and info.source == "data" else None,
        ff.c2, d.scale, d.level, d.tau0, st.notes)
    return first_order


def _result(st: FitState, ff: FinalFit, terms: list, first_order: bool) -> FitResult:
    """Step: the :class:`FitResult`, scored by BIC = chi^2 + k ln(n_points) (k: non-zero coefficients and the
    nonlinear terms' shapes)."""
    d = st.data
    kk = int(np.count_nonzero(ff.theta > 0)) + len(st.model.nonlin)
    avar_fit = avar_model([{k: v_ for k, v_ in t.items() if k != "ci95"} for t in terms], d.tau)
    return FitResult(terms=terms, tau=d.tau, avar_fit=avar_fit, chi2=ff.c2, dof=max(d.n_pts - kk, 0),
                     criterion="bic", score=ff.c2 + kk * math.log(d.n_pts),
                     covariance_mode="full" if d.full else "diagonal", avar_cov=st.model.cov * d.scale**2,
                     notes=st.notes, model_error=st.floor,
                     filter=_filter_summary(st.white, st.filter_info, first_order))


def fit_avar(tau, avar, edf=None, effects=None, *, n=None, rate_hz=None, m=None, level=0.95,
             max_iter=4, max_ratio=256, segments=None, select=None, white_filter=None,
             detect_filter=None, inverted_ci=True) -> FitResult:
    """Fit measured overlapping AVAR ``avar`` at ``tau`` (s) with the IEEE 952 terms (:mod:`companion.allan.fit`).

    ``edf``: EDF of each point (used for the first weights, and for the diagonal covariance when ``n`` or
    ``rate_hz`` is not given). ``effects``: None = automatic selection among AUTO_EFFECTS, or a list of effect
    names to fit (all kept unless their NNLS coefficient is 0). ``n``, ``rate_hz`` (and ``m``, default
    round(tau rate_hz)): number of rate samples and their rate, for the full model covariance.
    ``segments``: lengths (samples) of the segments of a pooled AVAR (:mod:`companion.allan.pooled`); the
    covariance is then the pooled one and ``n`` may be their sum. ``select``: True runs the automatic selection
    over the candidates ``effects`` (e.g. with a sinusoid, which the default candidate set leaves out); default:
    selection only when ``effects`` is None. ``white_filter``: {"filter_hz": f_c, "sample_hz": fs or None} of a
    2-pole low-pass filter the white noise went through before logging
    (:func:`companion.allan.terms.avar_white_noise`): the white-noise column is the filtered shape, so N comes
    from every cluster time, the roll-off included; the fitted white_noise term carries the filter. None: plain
    white noise. ``detect_filter``: "point" or "average" (how the logged samples were taken from the filtered
    signal): look for a roll-off in the data (:mod:`companion.allan.fit.rolloff`). ``inverted_ci=False``: the
    linear terms keep the scaled chi-square interval at the estimate, for a caller that computes its own
    intervals (the online report). The result's ``filter`` says what was used: {"filter_hz", "sample_hz",
    "source": "log" | "data", "ci95", "filter_order" when 1}.

    With ``n`` and ``rate_hz`` (the record is known), a bias-instability or rate random-walk term the record is
    too short to resolve (:func:`companion.allan.fit.record_rule.record_needed`) is not reported: it moves from
    ``terms`` to ``nuisance`` (it stays in the model), with a note giving the record length it would need; the
    caller reports a bound. So even when it is the only term the data select: a bias instability alone on a 14-s
    record is no resolved value (everything is then a bound).
    """
    pts = _usable_points(tau, avar, edf, n, rate_hz, m)
    white = white_filter_of(white_filter)
    if pts.tau.size == 0 or not np.any(pts.avar > 0):
        return FitResult([], pts.tau, np.zeros_like(pts.tau), covariance_mode="full" if pts.full else "diagonal",
                         notes=["no variance to fit (constant data)"])
    st = _initial_state(pts, effects, select, white, n=n, rate_hz=rate_hz, segments=segments, level=level,
                        max_iter=max_iter, max_ratio=max_ratio)
    st.model = iterate(st.data, st.white, 0.0)
    model_rolloff(st, detect_filter)
    absorb_misfit(st)
    ff = final_estimates(st)
    terms = term_intervals(st, ff, inverted_ci)
    selection_envelope(st, ff, terms)
    first_order = white_profile(st, ff, terms)
    return apply_record_rule(_result(st, ff, terms, first_order), n, rate_hz, segments)
