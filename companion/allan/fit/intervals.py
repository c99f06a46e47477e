"""Intervals of the fitted terms.

Each theta_j is treated as a scaled chi-square with nu_j = 2 theta_j^2 / var(theta_j) degrees of freedom
(Satterthwaite 1946), var from (A^T C^-1 A)^-1, so its ``level`` interval is
[theta nu / chi2_{(1+level)/2}(nu), theta nu / chi2_{(1-level)/2}(nu)] (:func:`_scaled_chi2_ci`; for nu < 4, a
barely identified term, the normal interval theta +- z sd truncated at 0); parameters are the square roots.
Where the points' covariance depends on the term itself the interval is found by test inversion
(:func:`_inverted_ci`). tau_c and freq_hz: profile likelihood, chi^2 <= chi^2_min + chi2_level(1)
(:func:`_profile_ci`); a linear parameter correlated with a shape parameter: its profile-likelihood interval
over it (:func:`_profile_union`). A base effect the selection left out widens the kept terms' intervals to the
model with it forced in (:func:`forced_intervals`, :func:`_selection_envelope`). Coverage is measured in
benchmarks/bench_fit.py.
"""

from __future__ import annotations

import math

import numpy as np

from companion.allan.fit.constants import ORDER
from companion.allan.fit.fit_state import FitState, covariance
from companion.allan.fit.gls import _columns, _Problem, _shape_range
from companion.allan.fit.point_cov import _flicker_shape_cov
from companion.allan.special import brentq, chi2_cdf, chi2_ppf
from companion.allan.terms import LINEAR_PARAM, avar_model

#: a pivot with fewer degrees of freedom than this is barely identified (sd > theta / sqrt 2): the chi-square
#: pivot's upper end explodes, the normal interval truncated at 0 is used instead
_MIN_PIVOT_NU = 4.0
#: the inverted interval's search doubles its step at most this many times from the estimate
_INVERT_STEPS = 12
#: a profile's shape grid: this many points over the shape range widened by one e-fold each side
_SHAPE_PROFILE_POINTS = 121
#: the least level a conditional interval of the profile union is taken at (a shape at the edge of its region)
_MIN_LEVEL = 1e-6


def _scaled_chi2_ci(theta, var, level):
    """Interval of a positive quadratic-form estimate theta ~ theta_true chi2(nu)/nu, nu = 2 theta^2/var."""
    if theta <= 0:
        return 0.0, 0.0
    if not var > 0:
        return theta, theta
    nu = 2.0 * theta**2 / var
    a = (1.0 - level) / 2.0
    if nu < _MIN_PIVOT_NU:
        # barely identified (sd > theta / sqrt 2): the chi-square pivot's upper end explodes; use the
        # normal interval on theta, truncated at 0
        z = chi2_ppf(level, 1) ** 0.5
        sd = math.sqrt(var)
        return max(theta - z * sd, 0.0), theta + z * sd
    return theta * nu / chi2_ppf(1.0 - a, nu), theta * nu / chi2_ppf(a, nu)


def _cov_along(effect, st: FitState, theta):
    """The AVAR points' covariance (units of scale^2) as a function of the coefficient u of ``effect``, the
    other terms of the covariance's model held (the superset model ``st.model.sup_terms`` the fit's covariance
    ``st.model.cov`` was computed from): an exact quadratic in u (pair sums, model error),

        C(u) = C0 + u C1 + u^2 C2,

    so the fit's covariance and two evaluations give it everywhere. The flicker's shape error
    (:func:`~companion.allan.fit.point_cov._flicker_shape_cov`) is added as in the fit's intervals, with B at u
    when ``effect`` is the bias instability. ``theta``: the fitted coefficients of ``st.model.linear``."""
    d = st.data
    sup_terms, cov_sup, linear = st.model.sup_terms, st.model.cov, st.model.linear
    scale, tau, m = d.scale, d.tau, d.m
    p = LINEAR_PARAM[effect]
    rest = [t for t in sup_terms if t["effect"] != effect]
    own = next((t for t in sup_terms if t["effect"] == effect), None)
    u_sup = own[p] ** 2 / scale if own is not None else 0.0
    own = dict(own) if own is not None else {"effect": effect}

    def at(u):
        terms = sorted(rest + [dict(own, **{p: math.sqrt(max(u, 0.0) * scale)})],
                       key=lambda t: ORDER.get(t["effect"], len(ORDER)))
        return covariance(d, st.white, terms, avar_model(terms, tau) / scale, st.floor)

    if u_sup > 0:
        # C(u) = C(u_sup) + (u - u_sup) L + (u^2 - u_sup^2) Q from C at 0 and at 2 u_sup
        d0, d2 = at(0.0) - cov_sup, at(2.0 * u_sup) - cov_sup
        quad_c = (d0 + d2) / (2.0 * u_sup**2)
        lin_c = (d2 - 3.0 * u_sup**2 * quad_c) / u_sup
        c0 = cov_sup - u_sup * lin_c - u_sup**2 * quad_c
    else:
        u_s = max(float(theta[linear.index(effect)]), 1e-300)
        c0, c1, c2 = at(0.0), at(u_s), at(2.0 * u_s)
        lin_c, quad_c = (4.0 * c1 - 3.0 * c0 - c2) / (2.0 * u_s), (c2 - 2.0 * c1 + c0) / (2.0 * u_s**2)
    b_fit = theta[linear.index("bias_instability")] if "bias_instability" in linear else 0.0
    flick = None
    if effect == "bias_instability" or b_fit > 0:
        # rank one, its vector proportional to B^2: the matrix is theta_B^2 times the one at theta_B = 1
        flick = _flicker_shape_cov({"effect": "bias_instability", "B": math.sqrt(scale)}, m, tau) / scale**2

    def cov_at(u):
        c = c0 + lin_c * u + quad_c * u * u
        if flick is not None:
            c = c + flick * (u if effect == "bias_instability" else b_fit) ** 2
        return c

    return cov_at


def _inverted_ci(theta_hat, j, A, cov_at, tau, v, white, tau0, level, guess_lo=None, guess_hi=None,
                 max_steps=_INVERT_STEPS):
    """Interval of the linear coefficient ``theta_hat`` (column ``j`` of ``A``) by test inversion: u is inside
    when the GLS estimate with the points' covariance evaluated *at u* (``cov_at(u)``) lies between the
    (1 -+ level) / 2 quantiles of u chi2(nu_u) / nu_u, nu_u = 2 u^2 / var_u(estimate). Evaluated at the estimate
    instead (:func:`_scaled_chi2_ci`), nu is too large where the estimate lies high: the estimate's variance
    is only partly the term's own (the rest comes from the other terms' share of the same points), so a
    random walk kept when its long-tau points happen to lie high gets an interval that misses it high (K of
    random 2-h records: covered in 76 of 83 at the estimate, 82 of 83 by inversion; benchmarks/bench_fit.py
    draws). The covariance at u also moves the estimate (its weights), which is part of the test.
    ``guess_lo``, ``guess_hi``: where to look first (the interval at the estimate). 0 when no u far below is rejected."""
    if theta_hat <= 0:
        return 0.0, 0.0
    a = (1.0 - level) / 2.0
    idx = np.arange(A.shape[1])

    def g(x, q):
        """log(estimate at u) - log(q-quantile of u chi2(nu_u)/nu_u), u = e^x: > 0 where the estimate lies above."""
        u = math.exp(x)
        prob = _Problem(tau, v, cov_at(u), white, tau0)
        th, _ = prob.solve(A)
        act = (th > 0) | (idx == j)
        ct = prob.cov_theta(A[:, act])
        k = int(np.count_nonzero(act[:j]))
        var = float(ct[k, k])
        if not var > 0:
            return math.log(max(th[j], 1e-300)) - x
        nu = 2.0 * u * u / var
        return math.log(max(th[j], 1e-300 * u)) - x - math.log(chi2_ppf(q, nu) / nu)

    x0 = math.log(theta_hat)
    ends = []
    for q, guess in ((1.0 - a, guess_lo), (a, guess_hi)):
        # from the estimate, step away by the distance to the guess (the interval at the estimate), doubled
        # each time, until u is rejected; then solve in the bracket
        want = 1.0 if q > 0.5 else -1.0  # the sign of g where u is rejected
        sign = -want
        d = abs(math.log(guess) - x0) if guess and guess > 0 and guess != theta_hat else math.log(2.0)
        d = min(max(d, 1e-4), math.log(2.0))
        x_in, x_out, step = x0, None, d
        for _ in range(max_steps):
            x = x_in + sign * step
            if g(x, q) * want > 0:
                x_out = x
                break
            x_in, step = x, 2.0 * step
        if x_out is None:
            ends.append(0.0 if sign < 0 else math.exp(x_in))
            continue
        if x_in == x0 and g(x0, q) * want > 0:  # the estimate itself is rejected (tiny nu): keep it inside
            ends.append(theta_hat)
            continue
        ends.append(math.exp(brentq(lambda x: g(x, q), min(x_in, x_out), max(x_in, x_out),
                                    xtol=1e-3 * abs(x_out - x0))))
    return min(ends[0], theta_hat), max(ends[1], theta_hat)


def _profile_union(lo, hi, prob, prob_ci, j, designs, c2, level):
    """The interval [lo, hi] (``prob``'s theta units) of the linear parameter in column ``j`` widened to its
    profile-likelihood interval over a shape parameter: ``designs`` holds the model's columns at each shape
    value of a grid; at each, the conditional interval at the level left once that shape's chi^2 excess over
    the minimum (``c2`` at the estimate, or the grid's least) is spent: chi^2(shape) - chi^2_min + z^2 <=
    chi2_level(1). The envelope of full-level conditional intervals over the shape's interval (a projection)
    allows twice that excess and over-covers (99-100 % for N over a cut-off found in the data, 99 % for a
    Gauss-Markov sigma over its tau_c, where 95 % is asked for)."""
    thr = chi2_ppf(level, 1)
    rows = [(A2,) + tuple(prob.solve(A2)) for A2 in designs]
    c2min = min([c2] + [r[2] for r in rows])
    for A2, th2, c2f in rows:
        left = thr - (c2f - c2min)
        if th2[j] <= 0 or left <= 0:
            continue
        act = th2 > 0
        k = int(np.count_nonzero(act[:j]))
        ct = prob_ci.cov_theta(A2[:, act])
        l2, h2 = _scaled_chi2_ci(th2[j], ct[k, k], max(chi2_cdf(left, 1), _MIN_LEVEL))
        lo, hi = min(lo, l2), max(hi, h2)
    return lo, hi


def _profile_ci(prob, effect, shape, linear, others, tau, c2min, level):
    """Profile-likelihood interval of a shape parameter (tau_c or freq_hz) on a log grid."""
    lo, hi = _shape_range(effect, tau, prob.tau0)
    lo, hi = min(lo, shape), max(hi, shape)
    grid = np.exp(np.linspace(math.log(lo) - 1.0, math.log(hi) + 1.0, _SHAPE_PROFILE_POINTS))
    thr = c2min + chi2_ppf(level, 1)
    chis = np.array([prob.solve(_columns(linear, others + [(effect, g)], tau, prob.white))[1] for g in grid])
    idx = np.flatnonzero(chis <= thr)
    if idx.size == 0:
        return shape, shape

    def f(lg):
        return prob.solve(_columns(linear, others + [(effect, math.exp(lg))], tau, prob.white))[1] - thr

    lg = np.log(grid)
    i0, i1 = int(idx.min()), int(idx.max())
    lo_v = math.exp(brentq(f, lg[i0 - 1], lg[i0], xtol=1e-4)) if i0 > 0 else float(grid[0])
    hi_v = math.exp(brentq(f, lg[i1], lg[i1 + 1], xtol=1e-4)) if i1 < len(grid) - 1 else float(grid[-1])
    return float(min(lo_v, shape)), float(max(hi_v, shape))


def forced_intervals(prob, sup, nonlin, tau, white, level) -> dict:
    """Intervals (scaled chi-square, in ``prob``'s theta units) of the linear terms in the model with the
    effects ``sup`` forced in, for each term with a positive estimate there, each end widened by the terms
    estimated at zero that pull it that way: the other half of the selection envelope
    (:func:`_selection_envelope` offline; the online report uses it the same way)."""
    A_s = _columns(sup, nonlin, tau, white)
    th_s, _ = prob.solve(A_s)
    act = th_s > 0
    if not act.any():
        return {}
    cov_a = np.zeros((len(th_s), len(th_s)))
    cov_a[np.ix_(act, act)] = prob.cov_theta(A_s[:, act])
    out = {e: _scaled_chi2_ci(th_s[k], cov_a[k, k], level) for k, e in enumerate(sup) if act[k]}
    if act.all():
        return out
    # a term estimated at zero here still shares the points with the others: were it above zero, another
    # would move by cov[k, z] / cov[z, z] per unit of it (the whole model's covariance). It can only go up, so
    # it widens one end: each end of an interval comes from the covariance of the active terms and the zero
    # terms that pull the estimate that way. Without them the forced model would give the selected model's
    # covariance back where B comes out at zero in it (60 s at 10 Hz of white noise + flicker + random walk: N,
    # +3 % there from the flicker's share, covered in 92.6 % of records; with them 95.9 %, white noise alone
    # as wide as without)
    cov_f = prob.cov_theta(A_s)
    covs = {}  # the column sets repeat between terms and ends
    for k, e in enumerate(sup):
        if not act[k]:
            continue
        ends = list(out[e])
        for side, sign in ((0, -1.0), (1, 1.0)):
            cols = act | (~act & (sign * cov_f[k] > 0))
            if np.array_equal(cols, act):
                continue
            key = cols.tobytes()
            if key not in covs:
                covs[key] = prob.cov_theta(A_s[:, cols])
            kk = int(np.count_nonzero(cols[:k]))
            ends[side] = _scaled_chi2_ci(th_s[k], covs[key][kk, kk], level)[side]
        out[e] = tuple(ends)
    return out


def _selection_envelope(terms, prob, sup, nonlin, tau, white, scale, level):
    """Widen each resolved linear term's interval to the envelope of it and its interval in the model with every
    base effect (N, B, K) forced in (``sup``), as the online report does: a base effect the selection left out
    moves its share into the kept terms (on random 2-h N/B/K draws, benchmarks/bench_fit.py draws, a rate random
    walk too weak to be selected goes into B, whose interval alone misses the truth high, 1.02-1.08 x, in 7-8
    of 100 draws). Estimates are unchanged."""
    forced = forced_intervals(prob, sup, nonlin, tau, white, level)
    for t in terms:
        e = t["effect"]
        if e not in forced:
            continue
        p = LINEAR_PARAM[e]
        lo_s, hi_s = forced[e]
        lo, hi = t["ci95"][p]
        t["ci95"][p] = [min(lo, math.sqrt(max(lo_s, 0.0) * scale)), max(hi, math.sqrt(max(hi_s, 0.0) * scale))]

