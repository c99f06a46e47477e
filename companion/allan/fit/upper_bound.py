"""95 % upper bounds of the terms a fit left out, by test inversion.

The bound of a left-out term is the value the data would reject at the one-sided 5 % level: the term is added to
the fitted model and

    theta_u = theta_hat(u) + z_0.95 sd(u),

with the AVAR points' covariance evaluated *at the bound* (the fitted terms as they are, the left-out one at
u = theta_u), solved for the fixed point u = step(u). Evaluated at the fitted value instead (0 or low for a term
the selection left out), the points where the term would show look too precise and the bound falls below the
truth (a rate random walk left out of 2-h records: bounded below its truth for 9 of 17 left-out K that way,
1 of 17 at the bound; benchmarks/bench_fit.py draws).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from companion.allan.fit.constants import NL_SHAPE, NONLINEAR_EFFECTS, ORDER, Z95_ONE_SIDED
from companion.allan.fit.gls import _columns, _Problem
from companion.allan.fit.point_cov import _points_cov, _with_shape_errors
from companion.allan.fit.fit_result import FitResult
from companion.allan.terms import LINEAR_EFFECTS, LINEAR_PARAM, avar_model, white_filter_of

#: the fixed point is reached when log(step(u) / u) is within this
_FIXED_TOL = 1e-3
#: ... or when the bracket of log u is this narrow
_BRACKET_TOL = 2e-3
#: a regula-falsi step closer than this fraction of the bracket to either end is replaced by a bisection
_FALSI_GUARD = 0.05
#: a secant step (before a bracket) moves log u by at most these (down x4, up x16)
_SECANT_RANGE = (math.log(4.0), math.log(16.0))
#: the smallest coefficient taken as non-zero in the covariance's quadratic
_TINY = 1e-300


class _Point(NamedTuple):
    """log u and h = log(step(u) / u) at it: h > 0 where the data do not reject u."""

    x: float
    h: float


class _CovQuadratic(NamedTuple):
    """The points' covariance as an exact quadratic in the bounded term's coefficient u: c0 + u lin + u^2 quad."""

    c0: np.ndarray
    lin: np.ndarray
    quad: np.ndarray

    def at(self, u):
        return self.c0 + (self.lin * u + self.quad * u * u if u else 0.0)


@dataclass
class _BoundData:
    """What every bound of one fit shares: the points, the fitted model (nuisance terms included) and its
    covariance's ingredients."""

    tau: np.ndarray
    v: np.ndarray  # AVAR / scale
    scale: float
    m: np.ndarray
    n: int
    rate_hz: float
    segments: list | None
    white: dict | None
    model_error: float
    plain: list  # the fitted and nuisance terms without intervals
    linear: list
    nonlin: list

    def cov_of(self, terms):
        return _with_shape_errors(_points_cov(terms, self.m, self.n, self.rate_hz, self.segments, self.scale), terms,
                                  self.tau, self.scale, self.white, self.model_error,
                                  avar_model(terms, self.tau) / self.scale)


def _cov_quadratic(bd: _BoundData, effect, A, j) -> _CovQuadratic:
    """The points' covariance is a quadratic form in the terms' squared magnitudes (pair sums, model error), so
    in u it is exactly C0 + u C1 + u^2 C2: three evaluations (u = 0, u_s, 2 u_s) give it at every u. The terms
    go in the fit's order, the bounded one in even at 0: the pair sums are remembered per set of term shapes."""
    p = LINEAR_PARAM[effect]
    others = [t for t in bd.plain if t["effect"] != effect]

    def cov_with(u):
        terms = others + [{"effect": effect, p: math.sqrt(max(u, 0.0) * bd.scale)}]
        return bd.cov_of(sorted(terms, key=lambda t: ORDER.get(t["effect"], len(ORDER))))

    u_s = max(float(np.max(bd.v)) / float(np.max(A[:, j])), _TINY)
    c0, c1, c2 = cov_with(0.0), cov_with(u_s), cov_with(2.0 * u_s)
    return _CovQuadratic(c0, (4.0 * c1 - 3.0 * c0 - c2) / (2.0 * u_s), (c2 - 2.0 * c1 + c0) / (2.0 * u_s**2))


def _next_log_u(lo: _Point | None, hi: _Point | None, prev: _Point | None, here: _Point, f) -> float | None:
    """The next log u of the fixed-point search: regula falsi (bisection near an end) inside a bracket [lo, hi],
    before it a secant step in log u (plain iteration u = step(u) where the secant leaves its range); None where
    the bracket is narrow enough."""
    if lo and hi:
        if hi.x - lo.x <= _BRACKET_TOL:
            return None
        nx = lo.x - lo.h * (hi.x - lo.x) / (hi.h - lo.h)
        d = hi.x - lo.x
        if not lo.x + _FALSI_GUARD * d < nx < hi.x - _FALSI_GUARD * d:
            nx = 0.5 * (lo.x + hi.x)
        return nx
    nx = math.log(f)
    if prev is not None and here.h != prev.h:
        sec = here.x - here.h * (here.x - prev.x) / (here.h - prev.h)
        if math.isfinite(sec) and here.x - _SECANT_RANGE[0] <= sec <= here.x + _SECANT_RANGE[1]:
            nx = sec
    return nx


def _fixed_point(step, max_iter) -> float:
    """u = step(u), from u = step(None). Plain iteration creeps (10-15 % a step where the term would dominate
    the long-tau points) and step() jumps where the NNLS drops a term; so: secant steps in log u until the sign
    of h = log step(u) - log u changes, then regula falsi inside the bracket, and, unconverged, the lowest u found
    rejected (conservative)."""
    u = step(None)
    lo = hi = prev = None  # h > 0 at the largest such u / h < 0 at the smallest
    for _ in range(max_iter):
        f = step(u)
        if not (f > 0 and u > 0):
            return max(f, u)
        here = _Point(math.log(u), math.log(f) - math.log(u))
        if abs(here.h) <= _FIXED_TOL:
            return max(f, u)
        if here.h > 0 and (lo is None or here.x > lo.x):
            lo = here
        if here.h < 0 and (hi is None or here.x < hi.x):
            hi = here
        nx = _next_log_u(lo, hi, prev, here, f)
        if nx is None:
            break
        prev = here
        u = math.exp(nx)
    return math.exp(hi.x) if hi else max(f, u)


def _bound_of(bd: _BoundData, effect, max_iter) -> dict:
    """The 95 % upper bound of the left-out ``effect`` (report format)."""
    p = LINEAR_PARAM[effect]
    lin = [x for x in LINEAR_EFFECTS if x in bd.linear or x == effect]
    A = _columns(lin, bd.nonlin, bd.tau, bd.white)
    j = lin.index(effect)
    cq = _cov_quadratic(bd, effect, A, j)

    def step(u):
        """theta_hat + z sd of the term with the points' covariance evaluated at theta = u (None: without it),
        the term's variance with it freed from the bound 0 (the others as the NNLS left them)."""
        prob = _Problem(bd.tau, bd.v, cq.at(u), bd.white, 1.0 / bd.rate_hz)
        theta, _ = prob.solve(A)
        act = (theta > 0) | (np.arange(len(theta)) == j)
        ct = prob.cov_theta(A[:, act])
        k = int(np.count_nonzero(act[:j]))
        return max(float(theta[j]), 0.0) + Z95_ONE_SIDED * math.sqrt(max(float(ct[k, k]), 0.0))

    b = math.sqrt(max(_fixed_point(step, max_iter), 0.0) * bd.scale)
    return {"effect": effect, p: b, "std": {p: b / Z95_ONE_SIDED}, "ci95": {p: [0.0, b]}, "bound": True}


def upper_bounds(fr: FitResult, tau, avar, *, n, rate_hz, m=None, segments=None,
                 effects=("white_noise", "bias_instability", "random_walk"), max_iter=12) -> list[dict]:
    """95 % upper bounds of the ``effects`` the fit ``fr`` left out (module docstring). Terms the record rule
    made nuisance (``fr.nuisance``) are part of the model of the others' bounds, as in the fit: left out, the
    bounded term would take up their share. ``companion analyze`` reports these bounds. ``tau``, ``avar``: the
    points the fit saw (``fr.tau``). Report format: {"effect", P: bound, "std": {P: bound / z}, "ci95": {P: [0,
    bound]}, "bound": True}."""
    tau = np.asarray(tau, dtype=float)
    avar = np.asarray(avar, dtype=float)
    have = {t["effect"] for t in fr.terms}
    missing = [e for e in effects if e not in have and e in LINEAR_PARAM]
    if not missing or not (fr.terms or fr.nuisance) or tau.size < 3:
        return []
    plain = [{k: v for k, v in t.items() if k != "ci95"} for t in list(fr.terms) + list(fr.nuisance)]
    scale = float(np.median(avar[avar > 0]))
    bd = _BoundData(tau=tau, v=avar / scale, scale=scale,
                    m=np.round(tau * rate_hz).astype(np.int64) if m is None else np.asarray(m, dtype=np.int64),
                    n=n, rate_hz=rate_hz, segments=segments, white=white_filter_of(fr.filter),
                    model_error=fr.model_error, plain=plain,
                    linear=[t["effect"] for t in plain if t["effect"] in LINEAR_EFFECTS],
                    nonlin=[(t["effect"], float(t[NL_SHAPE[t["effect"]]])) for t in plain
                            if t["effect"] in NONLINEAR_EFFECTS])
    return [_bound_of(bd, e, max_iter) for e in missing]
