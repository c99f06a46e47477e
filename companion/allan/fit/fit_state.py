"""The state a fit carries from step to step, and the step every other one repeats: select the terms and
weigh the points with the covariance of the model selected (:func:`iterate`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from companion.allan.fit.gls import _columns, _Problem, _terms_from
from companion.allan.fit.point_cov import _points_cov, _with_shape_errors
from companion.allan.fit.term_selection import _select
from companion.allan.terms import BASE_EFFECTS, LINEAR_EFFECTS

#: relative floor of a point's AVAR in the first (data-derived) weights: a point at 0 gets no infinite weight
_V_FLOOR = 1e-6
#: the iteration has converged when the selected terms repeat and their coefficients move less than this
_CONVERGED_RTOL = 1e-3
#: ... absolute part of that test (the coefficients are O(1): the data are scaled by their median)
_CONVERGED_ATOL = 1e-12


@dataclass
class FitData:
    """The points a fit sees and what it knows of the record (fixed once prepared)."""

    tau: np.ndarray  # cluster times (s) of the usable points
    v: np.ndarray  # AVAR / scale
    edf: np.ndarray  # EDF of each point
    scale: float  # the median positive AVAR: the data are O(1)
    effects: list  # candidate effects
    auto: bool  # automatic selection over ``effects``
    full: bool  # n and rate_hz given: the full model covariance (else a diagonal one)
    m: np.ndarray | None  # cluster sizes (samples), with ``full``
    n: int | None  # rate samples
    rate_hz: float | None
    segments: list | None  # segment lengths of a pooled AVAR
    max_ratio: int  # passed to the covariance's pair sums
    max_iter: int  # selection/covariance iterations
    inflate: float = 1.0  # the diagonal covariance's factor for the correlation of neighbouring points
    level: float = 0.95

    @property
    def n_pts(self) -> int:
        return int(self.tau.size)

    @property
    def tau0(self) -> float | None:
        return 1.0 / self.rate_hz if self.rate_hz else None


@dataclass
class ModelFit:
    """One selection with its covariance (:func:`iterate`): the points' covariance ``cov`` (units of scale^2)
    computed from the superset model ``sup_terms`` (model AVAR ``v_sup``), and the selected ``linear`` effects
    and ``nonlin`` (effect, shape) pairs with their chi^2 ``c2``."""

    cov: np.ndarray
    linear: list
    nonlin: list
    c2: float
    v_sup: np.ndarray
    sup_terms: list = field(default_factory=list)


@dataclass
class FitState:
    """What the steps of :func:`companion.allan.fit.steps.fit_avar` read and update."""

    data: FitData
    white: dict | None  # the low-pass filter of the white-noise column (None: plain white noise)
    model: ModelFit | None = None
    filter_info: object | None = None  # the data's roll-off profile the filter step settled on
    floor: float = 0.0  # relative model error added per point under misfit
    notes: list = field(default_factory=list)


def covariance(d: FitData, white, terms_si, v_model, floor) -> np.ndarray:
    """Covariance of the points (units of scale^2) for a model ``terms_si`` (AVAR ``v_model``): the overlapping
    estimator's with the full record known (:func:`~companion.allan.fit.point_cov._points_cov`), else
    diagonal, 2 model^2 / EDF x inflate (the correlation of neighbouring points, an approximation); plus the
    model's shape errors and the model error ``floor`` (:func:`~companion.allan.fit.point_cov._with_shape_errors`)."""
    if d.full and terms_si:
        c = _points_cov(terms_si, d.m, d.n, d.rate_hz, d.segments, d.scale, d.max_ratio)
    else:
        base = v_model if np.all(v_model > 0) else np.maximum(v_model, _V_FLOOR * np.max(d.v))
        c = np.diag(2.0 * base**2 / d.edf * (1.0 if d.full else d.inflate))
    return _with_shape_errors(c, terms_si, d.tau, d.scale, white, floor, v_model)


def iterate(d: FitData, white, floor: float) -> ModelFit:
    """Select and weigh in turn, up to ``max_iter`` times or until the selection repeats: the first weights come
    from the measured points (only to get a first model); then the covariance is computed from a *superset*
    model (all base effects plus the extras selected so far, NNLS-fitted) -- computed from a model that lacks a
    term actually present, the points that term dominates would look far too precise and trap the iteration --
    and the terms are selected again under it (:func:`~companion.allan.fit.term_selection._select`)."""
    cov = np.diag(2.0 * np.maximum(d.v, _V_FLOOR * d.v.max()) ** 2 / d.edf)
    base = [e for e in LINEAR_EFFECTS if e in d.effects and (e in BASE_EFFECTS or not d.auto)]
    linear, nonlin, c2 = list(base), [], 0.0
    prev, v_sup, sup_terms = None, d.v, []
    prob = _Problem(d.tau, d.v, cov, white, d.tau0)
    for _ in range(d.max_iter):
        # prob: under the covariance of the step before (its solves remembered from that step's selection)
        sup_lin = [e for e in LINEAR_EFFECTS if e in base or e in linear]
        A_sup = _columns(sup_lin, nonlin, d.tau, white)
        th_sup, _ = prob.solve(A_sup)
        v_sup = A_sup @ th_sup
        sup_terms = _terms_from(sup_lin, nonlin, th_sup, d.scale, white)
        cov = covariance(d, white, sup_terms, v_sup, floor)
        prob = _Problem(d.tau, d.v, cov, white, d.tau0)
        sel = _select(prob, d.tau, d.effects, d.n_pts, d.auto)
        linear, nonlin = sel.linear, sel.nonlin
        theta, c2 = prob.solve(_columns(linear, nonlin, d.tau, white))
        key = (tuple(linear), tuple(e for e, _ in nonlin))
        if (prev is not None and key == prev[0]
                and np.allclose(theta, prev[1], rtol=_CONVERGED_RTOL, atol=_CONVERGED_ATOL)):
            break
        prev = (key, theta)
    return ModelFit(cov, linear, nonlin, c2, v_sup, sup_terms)
