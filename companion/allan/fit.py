"""Automatic fit of a measured Allan variance with the IEEE Std 952 terms, with calibrated 95 % intervals.

Model (IEEE 952 Annex C; Miao et al. 2014 eq. (3.6)): sigma^2(tau) = sum_j theta_j phi_j(tau) + nonlinear terms,
theta = [Q^2, N^2, B^2, K^2, R^2] with phi = [3/tau^2, 1/tau, 2 ln2/pi, tau/3, tau^2/2]
(:func:`companion.allan.terms.linear_basis`), plus optionally one Gauss-Markov term (sigma^2 linear,
tau_c nonlinear) and one sinusoid (A^2 linear, freq_hz nonlinear).

Estimator: generalised least squares with theta >= 0,
    theta_hat = argmin_{theta >= 0} (v - A theta)^T C^-1 (v - A theta),
solved as NNLS after whitening with the Cholesky factor of C. C is the covariance of the overlapping AVAR
estimates computed from the *model* (not from the noisy measured points, whose use biases the fit low) by
:func:`companion.allan.confidence.oavar_covariance`: it holds the variances (the EDF) and the strong
correlation between neighbouring cluster times, so the fit neither over-weights a run of correlated points
nor reports intervals that are too narrow. C is recomputed from each new fit (iterated, ``max_iter``).
When the caller gives no ``n``/``rate_hz`` (only tau, avar and the EDF), C is diagonal,
2 model^2 / EDF, inflated by 2 x (points per octave) for the correlation of neighbouring points
(an approximation; analyze always uses the full C).

Term selection (``effects=None``): every subset of the usual gyro model {white_noise, bias_instability,
random_walk} is fitted and the one with the least Bayesian information criterion BIC = chi^2 + k ln(n_points)
is kept (k = non-zero coefficients; Schwarz 1978). Then quantization (only when AVAR at the two smallest
cluster times falls at least like tau^-1.5, :func:`quantization_slope`: a quantization term without its
slope region stands in for an output line or a filter's bump and moves N), ramp and one Gauss-Markov term
(2 parameters; tau_c found by a grid over the tau range -- AVAR peak 1.89 tau_c within
[4 tau_min, tau_max/4] -- refined by a bounded 1-D minimisation, and kept only at an interior optimum: a
tau_c pinned to the edge of the range is not identified) are tried in turn (a sinusoid, same way, only
when ``effects`` names it) and kept only if they lower the BIC by more than EXTRA_BIC_MARGIN = 10
("very strong" evidence, Kass & Raftery 1995): with ~18 strongly correlated points, plain BIC lets a ramp
stand in for a random walk in about one seed out of five. A forward pass then brings back any base term
whose return lowers the BIC (an extra term may have displaced it), and a backward pass drops any term whose
removal costs less than its penalty (a term picked early may have stood in for one picked later).
A slope region absent from the data simply leaves its coefficient at 0: never NaN.

Intervals: the covariance of the selected coefficients is (A^T C^-1 A)^-1; each theta_j is treated as a
scaled chi-square with nu_j = 2 theta_j^2 / var(theta_j) degrees of freedom (Satterthwaite 1946), so its
``level`` interval is [theta nu / chi2_{(1+level)/2}(nu), theta nu / chi2_{(1-level)/2}(nu)] (for nu < 4,
a barely identified term, the normal interval theta +- z sd truncated at 0); parameters are the square
roots. tau_c and freq_hz: profile likelihood, chi^2 <= chi^2_min + chi2_level(1); sigma and amplitude (and N
over a low-pass cut-off found in the data), correlated with the shape parameter: their profile-likelihood
interval over it, the union of their conditional intervals at the level each shape value's chi^2 excess leaves
(:func:`_profile_union`).
With a bias-instability term the covariance of the AVAR points used for these intervals also holds the
flicker's uncertain shape at the first cluster times (:func:`_flicker_shape_cov`): it looks like white noise
there, so it widens N's interval where B reaches the short taus. Coverage is measured in
benchmarks/bench_fit.py.

Model misfit (real sensors: an internal low-pass filter bends the ADEV at a few tau0, temperature drifts
are no IEEE 952 term): when chi^2 exceeds dof + 3 sqrt(2 dof), a relative model error e (same for every
point, added as (e sigma^2_model)^2 to the diagonal of C) is chosen so that chi^2 = dof -- the Birge-ratio /
random-effects remedy -- and the selection and fit are redone. The intervals widen accordingly and the
result carries ``model_error`` and a note. Without it the thousands of effective degrees of freedom of the
short-tau points would let a small systematic misfit there outweigh the whole long-tau region.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from companion.allan.confidence import flicker_sampling_excess, oavar_covariance
from companion.allan.lsq import nnls
from companion.allan.memo import BoundedMemo
from companion.allan.special import brentq, chi2_cdf, chi2_ppf, minimize_scalar_bounded
from companion.allan.terms import (BASE_EFFECTS, LINEAR_EFFECTS, LINEAR_PARAM, avar_model, avar_term,
                                   avar_white_noise, linear_basis, white_filter_of)

NONLINEAR_EFFECTS = ("gauss_markov", "sinusoid")
#: quantization, ramp, gauss_markov and sinusoid enter only if they lower the BIC by more than this
#: ("very strong" evidence on the scale of Kass & Raftery 1995: 2 ln(Bayes factor) > 10)
EXTRA_BIC_MARGIN = 10.0
#: the log's low-pass cut-off stands unless it lies outside the data's profile interval at this level
FILTER_LOG_LEVEL = 0.99
#: what effects=None tries; a sinusoid is fitted only when asked for (on octave-spaced points its
#: oscillating AVAR fits chance bumps too easily)
AUTO_EFFECTS = LINEAR_EFFECTS + ("gauss_markov",)
_NL_LINEAR = {"gauss_markov": "sigma", "sinusoid": "amplitude"}
_NL_SHAPE = {"gauss_markov": "tau_c", "sinusoid": "freq_hz"}
#: a Gauss-Markov correlation time shorter than this many sample periods is a filter's or the sampling's shape
GM_MIN_SAMPLES = 3.0
#: quantization is a candidate only where the data show its slope: AVAR between the two smallest cluster times
#: falls at least as fast as tau^QUANT_SLOPE (quantization alone: tau^-2; white noise: tau^-1, less under a
#: filter). Without that region a quantization term only stands in for something else at short tau (an output
#: line near the Nyquist frequency, a filter's bump) and moves N.
QUANT_SLOPE = -1.5
#: ... and, where there is a third, between the second and third at least as fast as tau^QUANT_SLOPE2: a
#: quantization term that passes the first test is at least 1.41x the white noise at the smallest cluster time,
#: so the next octave still falls like tau^-1.34 or faster, where white noise alone falls like tau^-1. An output
#: line near the Nyquist frequency lifts the smallest cluster time alone (point samples alternate, pairs
#: average it out) and passes the first test; it fails this one, and a quantization term standing in for it
#: pulled N 10 % low (10 Hz, 60 s, a line at 4.9 Hz of half the white power: N's interval covered the truth in
#: 22 of 40 records)
QUANT_SLOPE2 = -1.2
#: relative uncertainty of a modelled low-pass filter's shape, per unit of its bend 1 - AVAR tau / N^2
FILTER_SHAPE_ERROR = 0.25
#: uncertainty of the bias-instability (flicker) AVAR at the first cluster times, in units of the excess a
#: sampled flicker without anti-alias filter has over the plateau (:func:`flicker_sampling_excess`: +19 % at
#: tau0, +9 % at 2 tau0, +3 % at 4 tau0); fully correlated over tau (one unknown shape)
FLICKER_SHAPE_ERROR = 1.0


@dataclass
class FitResult:
    """Result of :func:`fit_avar`. ``terms``: fitted term dicts (SI) each with ``"ci95"``."""

    terms: list[dict]
    tau: np.ndarray
    avar_fit: np.ndarray
    chi2: float = 0.0
    dof: int = 0
    criterion: str = "bic"
    score: float = 0.0
    covariance_mode: str = "full"
    avar_cov: np.ndarray | None = field(default=None, repr=False)
    notes: list[str] = field(default_factory=list)
    model_error: float = 0.0  # relative AVAR model error added per point when the model misfits (0: none)
    filter: dict | None = None  # the low-pass filter modelled in the white-noise term (None: none)
    # terms in the model (avar_fit, avar_cov and the others' intervals include them) that the record is too
    # short to resolve (fit_avar's record rule): not reported; the caller gives their upper bounds
    nuisance: list[dict] = field(default_factory=list)

    def term(self, effect: str) -> dict | None:
        for t in self.terms:
            if t["effect"] == effect:
                return t
        return None

    def to_dict(self) -> dict:
        return {"terms": self.terms, "chi2": self.chi2, "dof": self.dof, "criterion": self.criterion,
                "model_error": self.model_error, "filter": self.filter,
                "score": self.score, "covariance": self.covariance_mode, "notes": list(self.notes)}


def _shape_column(effect: str, shape: float, tau) -> np.ndarray:
    """AVAR per unit of the linear parameter squared for a nonlinear effect at fixed shape parameter."""
    if effect == "gauss_markov":
        return avar_term({"effect": effect, "sigma": 1.0, "tau_c": shape}, tau)
    return avar_term({"effect": effect, "amplitude": 1.0, "freq_hz": shape}, tau)


def _shape_range(effect: str, tau, tau0=None) -> tuple[float, float]:
    """Shape parameters whose AVAR peak (1.89 tau_c; 0.371/f) lies inside [4 tau_min, tau_max / 4]; a
    Gauss-Markov tau_c of at least GM_MIN_SAMPLES sample periods ``tau0`` (shorter, it is the shape of a
    low-pass filter or of the sampling, which the white-noise term's filter models)."""
    lo, hi = 4.0 * tau[0], tau[-1] / 4.0
    if effect == "gauss_markov":
        return max(lo / 1.89, GM_MIN_SAMPLES * (tau0 or 0.0)), hi / 1.89
    return 0.371 / hi, 0.371 / lo


class _Problem:
    """Whitened GLS problem for a fixed covariance C (scaled so the data are O(1))."""

    def __init__(self, tau, v, cov, white=None, tau0=None):
        self.tau, self.v = tau, v
        self.white, self.tau0 = white, tau0  # the white-noise term's filter (dict or None), sample period
        cov = 0.5 * (cov + cov.T)
        d = np.sqrt(np.maximum(np.diag(cov), 1e-300))
        corr = cov / np.outer(d, d)
        # the truncated sums of oavar_covariance can leave the matrix slightly indefinite: clip eigenvalues
        w, U = np.linalg.eigh(0.5 * (corr + corr.T))
        corr = (U * np.maximum(w, 1e-6)) @ U.T
        self.L = np.linalg.cholesky(corr) * d[:, None]
        self.vw = self._w(v)

    def _w(self, x):
        return np.linalg.solve(self.L, x) if np.ndim(x) == 1 else np.linalg.solve(self.L, x)

    def solve(self, A):
        # a candidate whose covariance is ~0 at some point (a term that vanishes there) whitens to 1e150 and
        # beyond: its chi^2 is inf (the candidate loses), not a RuntimeWarning on the user's screen
        with np.errstate(over="ignore", invalid="ignore"):
            Aw = self._w(A)
            scale = np.maximum(np.sqrt((Aw**2).sum(axis=0)), 1e-300)
            theta, _ = nnls(Aw / scale, self.vw, max_iter=50 * A.shape[1] + 50)
            theta = theta / scale
            r = self.vw - Aw @ theta
            c2 = float(r @ r)
        return theta, (c2 if math.isfinite(c2) else math.inf)

    def cov_theta(self, A):
        Aw = self._w(A)
        return np.linalg.pinv(Aw.T @ Aw)


_FILTERED_COLUMNS = BoundedMemo(256, read_only=True)


def _filtered_white_column(tau, white):
    """The filtered white-noise column at ``tau``, remembered: the model search asks for the same one hundreds
    of times per fit (each shape-grid point, each candidate set) and each costs a phase-structure evaluation."""
    key = (np.asarray(tau, dtype=float).tobytes(), white.get("filter_hz"), white.get("sample_hz"),
           white.get("filter_order"))
    return _FILTERED_COLUMNS.get(key, lambda: avar_white_noise(tau, 1.0, **white))


def _columns(linear, nonlinear, tau, white=None):
    """Design matrix; ``white``: {"filter_hz", "sample_hz"[, "filter_order"]} of a low-pass filter seen by the
    white noise."""
    cols = [_filtered_white_column(tau, white) if (e == "white_noise" and white) else linear_basis(tau, [e])[:, 0]
            for e in linear]
    cols += [_shape_column(e, s, tau) for e, s in nonlinear]
    return np.column_stack(cols) if cols else np.zeros((len(tau), 0))


def _best_shape(prob, effect, linear, others, tau):
    """Grid + bounded refinement of the shape parameter of ``effect``; returns (shape, chi2, theta)."""
    lo, hi = _shape_range(effect, tau, prob.tau0)
    if not hi > lo > 0:
        return None

    def chi(log_s):
        A = _columns(linear, others + [(effect, math.exp(log_s))], tau, prob.white)
        return prob.solve(A)[1]

    grid = np.linspace(math.log(lo), math.log(hi), 25 if effect == "gauss_markov" else 61)
    vals = np.array([chi(g) for g in grid])
    i = int(np.argmin(vals))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    res_x, res_fun = minimize_scalar_bounded(chi, a, b, xatol=1e-3)
    best = float(res_x) if res_fun < vals[i] else float(grid[i])
    span = grid[-1] - grid[0]
    interior = grid[0] + 0.02 * span < best < grid[-1] - 0.02 * span
    return math.exp(best), min(float(res_fun), float(vals[i])), grid, vals, interior


def _select(prob, tau, effects, n_pts, auto):
    """Model selection for fixed C: returns (linear effects, [(nonlinear effect, shape)], chi2)."""
    lin_cand = [e for e in effects if e in LINEAR_EFFECTS]
    nl_cand = [e for e in effects if e in NONLINEAR_EFFECTS]
    if not auto:
        nonlin = []
        for e in nl_cand:
            r = _best_shape(prob, e, lin_cand, nonlin, tau)
            if r:
                nonlin.append((e, r[0]))
        theta, c2 = prob.solve(_columns(lin_cand, nonlin, tau, prob.white))
        return lin_cand, nonlin, c2
    base = [e for e in lin_cand if e in BASE_EFFECTS]
    extra_lin = [e for e in lin_cand if e not in BASE_EFFECTS]
    best = None
    for k in range(1, len(base) + 1):
        for subset in itertools.combinations(base, k):
            theta, c2 = prob.solve(_columns(list(subset), [], tau, prob.white))
            kk = int(np.count_nonzero(theta > 0))
            bic = c2 + kk * math.log(n_pts)
            if best is None or bic < best[0] - 1e-9:
                best = (bic, [e for e, t in zip(subset, theta) if t > 0], c2)
    if best is None:
        best = (float("inf"), [], 0.0)
    bic, linear, c2 = best
    nonlin: list = []
    # extra effects, each kept only on strong evidence (BIC lower by more than EXTRA_BIC_MARGIN)
    for e in extra_lin + nl_cand:
        if e in LINEAR_EFFECTS:
            cand_lin, cand_nl = linear + [e], nonlin

        else:
            r = _best_shape(prob, e, linear, nonlin, tau)
            if r is None or not r[4]:
                continue  # no interior optimum of the shape parameter: the term is not identified
            cand_lin, cand_nl = linear, nonlin + [(e, r[0])]

        theta, c2n = prob.solve(_columns(cand_lin, cand_nl, tau, prob.white))
        if theta[len(cand_lin) - 1 if e in LINEAR_EFFECTS else -1] <= 0:
            continue
        kk = int(np.count_nonzero(theta > 0)) + len(cand_nl)
        bic_n = c2n + kk * math.log(n_pts)
        if bic_n < bic - EXTRA_BIC_MARGIN:
            # the base terms may now be redundant: keep only those with a non-zero coefficient
            keep = theta[: len(cand_lin)] > 0
            linear = [x for x, kp in zip(cand_lin, keep) if kp]
            nonlin = cand_nl
            bic, c2 = bic_n, c2n
    # forward pass over the base effects: an extra term may have taken the place of a base one that the data
    # still need beside it (a public plane log's warm-up ramp displaced the random walk that had stood in for
    # it, white noise with it: the model was the ramp alone, chi^2 526 for 9 dof where white noise + ramp
    # gives 12, and the misfit inflation that followed hid the ramp from the selection); a base effect comes
    # back when it lowers the BIC
    while True:
        best_add = None
        for e in base:
            if e in linear:
                continue
            lin2 = [x for x in LINEAR_EFFECTS if x in linear or x == e]
            th2, c2a = prob.solve(_columns(lin2, nonlin, tau, prob.white))
            if th2[lin2.index(e)] <= 0:
                continue
            gain = (c2 - c2a) - math.log(n_pts)  # > 0: better with it
            if gain > 0 and (best_add is None or gain > best_add[0]):
                best_add = (gain, [x for x, t in zip(lin2, th2[:len(lin2)]) if t > 0], c2a)
        if best_add is None:
            break
        _, linear, c2 = best_add
    # backward pass: a term added early may have stood in for one added later (e.g. a quantization or a
    # bias-instability term for a Gauss-Markov bump); drop any term whose removal does not cost its
    # penalty (ln n for a base term, ln n + EXTRA_BIC_MARGIN for an extra one)
    while len(linear) + len(nonlin) > 1:
        best_drop = None
        for i in range(len(linear) + len(nonlin)):
            lin2 = [e for j, e in enumerate(linear) if j != i]
            nl2 = [x for j, x in enumerate(nonlin) if j + len(linear) != i]
            name = linear[i] if i < len(linear) else nonlin[i - len(linear)][0]
            th2, c2d = prob.solve(_columns(lin2, nl2, tau, prob.white))
            k_params = (1 if name in LINEAR_EFFECTS else 2)
            margin = 0.0 if name in BASE_EFFECTS else EXTRA_BIC_MARGIN
            gain = (c2 - c2d) + k_params * math.log(n_pts) + margin  # > 0: better without it
            if gain > 0 and (best_drop is None or gain > best_drop[0]):
                best_drop = (gain, lin2, nl2, c2d)
        if best_drop is None:
            break
        _, linear, nonlin, c2 = best_drop
    return linear, nonlin, c2


def _terms_from(linear, nonlinear, theta, scale, white=None):
    terms = []
    for e, t in zip(linear, theta[: len(linear)]):
        terms.append({"effect": e, LINEAR_PARAM[e]: math.sqrt(max(t, 0.0) * scale)})
        if e == "white_noise" and white:
            terms[-1].update(_filter_params(white))
    for (e, s), t in zip(nonlinear, theta[len(linear):]):
        terms.append({"effect": e, _NL_LINEAR[e]: math.sqrt(max(t, 0.0) * scale), _NL_SHAPE[e]: s})
    return [t for t in terms if any(v > 0 for k, v in t.items() if k in ("Q", "N", "B", "K", "R", "sigma", "amplitude"))]


def _scaled_chi2_ci(theta, var, level):
    """Interval of a positive quadratic-form estimate theta ~ theta_true chi2(nu)/nu, nu = 2 theta^2/var."""
    if theta <= 0:
        return 0.0, 0.0
    if not var > 0:
        return theta, theta
    nu = 2.0 * theta**2 / var
    a = (1.0 - level) / 2.0
    if nu < 4.0:
        # barely identified (sd > theta / sqrt 2): the chi-square pivot's upper end explodes; use the
        # normal interval on theta, truncated at 0
        z = chi2_ppf(level, 1) ** 0.5
        sd = math.sqrt(var)
        return max(theta - z * sd, 0.0), theta + z * sd
    return theta * nu / chi2_ppf(1.0 - a, nu), theta * nu / chi2_ppf(a, nu)



#: The interval of a linear term is found by test inversion (:func:`_inverted_ci`) unless the pivot's nu at the
#: estimate is at least this (relative sd <= 1.4 %): the covariance then hardly changes over the interval and the
#: pivot is the same interval (N of hours at tens of Hz, nu ~ 1e5-1e6), at a tenth of the cost.
INVERT_MAX_NU = 1e4

_ORDER = {x: i for i, x in enumerate(LINEAR_EFFECTS + NONLINEAR_EFFECTS)}


def _cov_along(effect, sup_terms, cov_sup, theta, linear, scale, covariance, floor, tau, m):
    """The AVAR points' covariance (units of ``scale``^2) as a function of the coefficient u of ``effect``, the
    other terms of the covariance's model held (``sup_terms``, the superset model the fit's covariance
    ``cov_sup`` was computed from): an exact quadratic in u (pair sums, model error), so ``cov_sup`` and two
    evaluations give it everywhere. The flicker's shape error (:func:`_flicker_shape_cov`) is added as in the
    fit's intervals, with B at u when ``effect`` is the bias instability."""
    p = LINEAR_PARAM[effect]
    rest = [t for t in sup_terms if t["effect"] != effect]
    own = next((t for t in sup_terms if t["effect"] == effect), None)
    u_sup = own[p] ** 2 / scale if own is not None else 0.0
    own = dict(own) if own is not None else {"effect": effect}

    def at(u):
        terms = sorted(rest + [dict(own, **{p: math.sqrt(max(u, 0.0) * scale)})],
                       key=lambda t: _ORDER.get(t["effect"], len(_ORDER)))
        return covariance(terms, avar_model(terms, tau) / scale, floor)

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
                 max_steps=12):
    """Interval of the linear coefficient ``theta_hat`` (column ``j`` of ``A``) by test inversion: u is inside
    when the GLS estimate with the points' covariance evaluated *at u* (``cov_at(u)``) lies between the
    (1 -+ level) / 2 quantiles of u chi2(nu_u) / nu_u, nu_u = 2 u^2 / var_u(estimate). Evaluated at the estimate
    instead (:func:`_scaled_chi2_ci`), nu is too large where the estimate lies high: the estimate's variance
    is only partly the term's own (the rest comes from the other terms' share of the same points), so a
    random walk kept when its long-tau points happen to lie high got an interval that missed it high (found K
    of random 2-h records covered in 76 of 83, against 82 of 83 here; benchmarks/bench_fit.py draws). The
    covariance at u also moves the estimate (its weights), which is part of the test. ``guess_lo``, ``guess_hi``:
    where to look first (the interval at the estimate). 0 when no u far below is rejected."""
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

#: A long-tau term (bias instability, rate random walk) is "resolved" only when the record shows it: it must
#: dominate the fitted AVAR (at least half of it) from a cluster time tau_d no longer than a tenth of the
#: record, where a single-segment Allan variance still has an EDF of about 5 or more (rate random walk: EDF
#: ~ N/m at tau = T/10), so that the octaves tau_d .. T/2 carry it. A record therefore needs to be at least
#: RESOLVE_RECORD_FACTOR x tau_d long, tau_d being the shortest tau from which the term dominates. (Twenty
#: tau_d was tried and is too strict: K of a 2000 s record with tau_d = 173 s is recovered within its
#: interval, tests/test_estimators.py.) The refit without such a term uses only the taus below tau_d.
RESOLVE_RECORD_FACTOR = 10.0
RESOLVE_EFFECTS = ("bias_instability", "random_walk")
#: ... and never from less than a minute of record: the rule above is scale-free, so a short record whose
#: AVAR rises early (33 s of a copter at rest, a 0.29 s batch-sampler burst) would "resolve" a rate random
#: walk or a bias instability from cluster times of a second or of milliseconds, where a drift, a slow filter
#: or temperature look the same; below 60 s the analysis deems even N unusable (analysis.limits.FIT_MIN_SECONDS).
RESOLVE_MIN_RECORD_S = 60.0


def dominates_from(terms, tau0: float) -> dict[str, float]:
    """For each of ``RESOLVE_EFFECTS`` in ``terms`` (fitted, SI): the shortest tau (>= tau0) from which it is
    at least half of the model AVAR, or, where it never is, the tau where its share is largest: a bias
    instability between white noise and a rate random walk may never reach half anywhere, yet it is best
    seen (and only resolvable) where its share peaks; requiring half there made it a bound on any record and
    moved its share into K (the sample tlog's gx: K 1120 [969, 1330] deg/h^1.5 against a truth of 742)."""
    plain = [{k: v for k, v in t.items() if k != "ci95"} for t in terms]
    grid = np.exp(np.linspace(math.log(tau0), math.log(tau0) + math.log(1e9), 2000))
    total = avar_model(plain, grid)
    out = {}
    for t in plain:
        if t["effect"] not in RESOLVE_EFFECTS:
            continue
        share = avar_term(t, grid) / np.where(total > 0, total, np.inf)
        dom = np.flatnonzero(share >= min(0.5, float(share.max())))
        out[t["effect"]] = float(grid[dom[0]]) if dom.size and share.max() > 0 else math.inf
    return out


def record_needed(terms, tau0: float) -> dict[str, float]:
    """For each of ``RESOLVE_EFFECTS`` in ``terms`` (fitted, SI): the record length (s) it needs to be
    resolved, RESOLVE_RECORD_FACTOR x the shortest tau from which it dominates (:func:`dominates_from`;
    inf if it never does), at least RESOLVE_MIN_RECORD_S."""
    return _record_for(dominates_from(terms, tau0))


def _record_for(tau_d: dict[str, float]) -> dict[str, float]:
    return {e: max(RESOLVE_RECORD_FACTOR * t, RESOLVE_MIN_RECORD_S) for e, t in tau_d.items()}


def quantization_slope(tau, avar) -> bool:
    """True when AVAR at the two smallest cluster times falls like quantization noise (log-log slope at most
    QUANT_SLOPE) and, where there is a third, still falls faster than white noise between the second and third
    (QUANT_SLOPE2): the region a quantization term needs before it is a candidate of the automatic selection."""
    if len(tau) < 2 or not (avar[0] > 0 and avar[1] > 0 and tau[1] > tau[0]):
        return False
    if math.log(avar[1] / avar[0]) / math.log(tau[1] / tau[0]) > QUANT_SLOPE:
        return False
    if len(tau) < 3 or not (avar[2] > 0 and tau[2] > tau[1]):
        return True
    return math.log(avar[2] / avar[1]) / math.log(tau[2] / tau[1]) <= QUANT_SLOPE2


def fit_avar(tau, avar, edf=None, effects=None, *, n=None, rate_hz=None, m=None, level=0.95,
             max_iter=4, max_ratio=256, segments=None, select=None, white_filter=None,
             detect_filter=None, inverted_ci=True) -> FitResult:
    """Fit measured overlapping AVAR ``avar`` at ``tau`` (s); see the module docstring (and :func:`_fit_avar`
    for the arguments; ``inverted_ci=False``: the linear terms keep the scaled chi-square interval at the
    estimate, for a caller that computes its own intervals, as the online report does). With ``n`` and ``rate_hz`` (the record is known), a bias-instability or rate
    random-walk term the record is too short to resolve (:func:`record_needed`) is not reported: it moves
    from ``terms`` to ``nuisance`` (it stays in the model), with a note giving the record length it would
    need; the caller reports a bound. So even when it is the only term the data select: a bias instability
    alone on a 14-s record is no resolved value (everything is then a bound)."""
    res = _fit_avar(tau, avar, edf, effects, n=n, rate_hz=rate_hz, m=m, level=level, max_iter=max_iter,
                    max_ratio=max_ratio, segments=segments, select=select, white_filter=white_filter,
                    detect_filter=detect_filter, inverted_ci=inverted_ci)
    if n is None or not rate_hz or not res.terms:
        return res
    record = (max(segments) if segments else n) / float(rate_hz)
    tau_d = dominates_from(res.terms, 1.0 / float(rate_hz))
    needs = _record_for(tau_d)
    drop = {e: need for e, need in needs.items() if need > record}
    if not drop:
        return res
    # the record rule decides what is reported, not what is modelled: the dropped term stays in the model
    # (its share of the curve is there, resolved or not) as a nuisance term, and the kept terms keep their
    # values and intervals from that model. Refitted without it, the kept terms take up its share wherever
    # it is not negligible: a bias instability at 20-45 % of the AVAR from 1 to 330 s (a copter at 50 Hz,
    # 20 min of record) went into N (1.4-1.6x the truth, +-0.5 %) or, through a Gauss-Markov term moved to
    # the 3-sample edge where it mimics the low-pass filter, into a model that left the curve altogether
    res2 = replace(res, terms=[t for t in res.terms if t["effect"] not in drop],
                   nuisance=[t for t in res.terms if t["effect"] in drop], notes=list(res.notes))
    for e, need in drop.items():
        res2.notes.append(f"{e} not resolved: the record ({record:.3g} s) is shorter than the "
                          + (f"{need:.3g} s it needs (it dominates the Allan variance only from tau {tau_d[e]:.3g} s, "
                             f"and needs that tau within a tenth of the record)"
                             if math.isfinite(need) and need > RESOLVE_MIN_RECORD_S
                             else f"{need:.3g} s a long-tau term needs at least" if math.isfinite(need)
                             else "record it needs (it dominates the Allan variance at no tau)")
                          + "; given as an upper bound")
    return res2


def _fit_avar(tau, avar, edf=None, effects=None, *, n=None, rate_hz=None, m=None, level=0.95,
              max_iter=4, max_ratio=256, segments=None, select=None, white_filter=None,
              detect_filter=None, inverted_ci=True) -> FitResult:
    """Fit measured overlapping AVAR ``avar`` at ``tau`` (s); see the module docstring.

    ``edf``: EDF of each point (used for the first weights, and for the diagonal covariance when ``n`` or
    ``rate_hz`` is not given). ``effects``: None = automatic selection among all effects, or a list of effect
    names to fit (all kept unless their NNLS coefficient is 0). ``n``, ``rate_hz`` (and ``m``, default
    round(tau rate_hz)): number of rate samples and their rate, for the full model covariance.
    ``segments``: lengths (samples) of the segments of a pooled AVAR (:mod:`companion.allan.pooled`); the
    covariance is then the pooled one and ``n`` may be their sum.
    ``select``: True runs the automatic selection over the candidates ``effects`` (e.g. with a sinusoid,
    which the default candidate set leaves out); default: selection only when ``effects`` is None.
    ``white_filter``: {"filter_hz": f_c, "sample_hz": fs or None} of a 2-pole low-pass filter the white noise
    went through before logging (:func:`companion.allan.terms.avar_white_noise`): the white-noise column is the
    filtered shape, so N comes from every cluster time, the roll-off included; the fitted white_noise term
    carries the filter. None: plain white noise.
    ``detect_filter``: "point" or "average" (how the logged samples were taken from the filtered signal):
    look for a roll-off in the data (:func:`_profile_filter`, a 2-pole shape, see below for a first-order one);
    without ``white_filter`` it is modelled only when it lowers chi^2 by more than ln(points) + EXTRA_BIC_MARGIN
    against no filter; ``white_filter``'s cut-off (the log's) stands unless it lies outside the data's
    FILTER_LOG_LEVEL profile interval (chi^2 scaled by the Birge ratio of the best fit). The data's shape may
    also be first-order (below FIRST_ORDER_MAX of the sample rate), where it fits better than the best 2-pole by
    FILTER_LOG_LEVEL, judged under the covariance of the model fitted with the log's cut-off (or none) and,
    where the first-order shape fits better but not by the rule's margin (than that model, or than the 2-pole the
    data put in its place), again under its own model's selection and covariance.
    The result's ``filter`` says what was used: {"filter_hz", "sample_hz", "source": "log" | "data", "ci95",
    "filter_order" when 1}.
    """
    tau = np.asarray(tau, dtype=float)
    avar = np.asarray(avar, dtype=float)
    ok = np.isfinite(avar) & np.isfinite(tau) & (tau > 0) & (avar >= 0)
    notes = []
    edf_all = np.full(tau.shape, 10.0) if edf is None else np.broadcast_to(np.asarray(edf, dtype=float), tau.shape)
    ok &= np.isfinite(edf_all) & (edf_all > 0)
    tau, avar, edf_v = tau[ok], avar[ok], edf_all[ok]
    full = n is not None and rate_hz is not None
    white = white_filter_of(white_filter)
    tau0 = 1.0 / rate_hz if rate_hz else None
    if full:
        m = np.round(tau * rate_hz).astype(np.int64) if m is None else np.asarray(m, dtype=np.int64)[ok]
    if tau.size == 0 or not np.any(avar > 0):
        return FitResult([], tau, np.zeros_like(tau), covariance_mode="full" if full else "diagonal",
                         notes=["no variance to fit (constant data)"])
    auto = effects is None if select is None else bool(select)
    effects = list(AUTO_EFFECTS) if effects is None else list(effects)
    bad = [e for e in effects if e not in LINEAR_EFFECTS + NONLINEAR_EFFECTS]
    if bad:
        raise ValueError(f"unknown effect {bad[0]!r}")
    if auto and "quantization" in effects and not quantization_slope(tau, avar):
        effects.remove("quantization")
    if tau.size < 3:
        effects = [e for e in effects if e in ("white_noise",)] or effects[:1]
        notes.append("fewer than 3 cluster times: only white noise fitted")
    scale = float(np.median(avar[avar > 0]))
    v = avar / scale
    n_pts = tau.size
    if not full:
        dens = (n_pts - 1) / max(math.log2(tau[-1] / tau[0]), 1e-9) if n_pts > 1 else 1.0
        inflate = 2.0 * max(1.0, dens)

    def covariance(terms_si, v_model, floor):
        if full and terms_si:
            c = _points_cov(terms_si, m, n, rate_hz, segments, scale, max_ratio)
        else:
            base = v_model if np.all(v_model > 0) else np.maximum(v_model, 1e-6 * np.max(v))
            c = np.diag(2.0 * base**2 / edf_v * (1.0 if full else inflate))
        return _with_shape_errors(c, terms_si, tau, scale, white, floor, v_model)

    def iterate(floor):
        # start: weights from the measured points (only to get a first model). The covariance is then
        # computed from a *superset* model (all base effects plus the extras selected so far, NNLS-fitted):
        # computing it from a model that lacks a term actually present would make the points dominated by
        # that term look far too precise and trap the iteration.
        cov = np.diag(2.0 * np.maximum(v, 1e-6 * v.max()) ** 2 / edf_v)
        base = [e for e in LINEAR_EFFECTS if e in effects and (e in BASE_EFFECTS or not auto)]
        linear, nonlin, c2 = list(base), [], 0.0
        prev, v_sup, sup_terms = None, v, []
        for it in range(max_iter):
            prob = _Problem(tau, v, cov, white, tau0)
            sup_lin = [e for e in LINEAR_EFFECTS if e in base or e in linear]
            A_sup = _columns(sup_lin, nonlin, tau, white)
            th_sup, _ = prob.solve(A_sup)
            v_sup = A_sup @ th_sup
            sup_terms = _terms_from(sup_lin, nonlin, th_sup, scale, white)
            cov = covariance(sup_terms, v_sup, floor)
            prob = _Problem(tau, v, cov, white, tau0)
            linear, nonlin, c2 = _select(prob, tau, effects, n_pts, auto)
            theta, c2 = prob.solve(_columns(linear, nonlin, tau, white))
            key = (tuple(linear), tuple(e for e, _ in nonlin))
            if prev is not None and key == prev[0] and np.allclose(theta, prev[1], rtol=1e-3, atol=1e-12):
                break
            prev = (key, theta)
        return cov, linear, nonlin, c2, v_sup, sup_terms

    cov, linear, nonlin, c2, v_sup, sup_terms = iterate(0.0)
    filter_info = None
    if detect_filter and "white_noise" in effects and tau0 and n_pts >= 5:
        # a low-pass roll-off: claimed only when the data show one (the filtered white-noise shape lowers
        # chi^2 by more than one parameter's BIC penalty + EXTRA_BIC_MARGIN); the log's cut-off, when given,
        # stands unless the data's profile interval excludes it
        sampling = "point" if detect_filter != "average" else "average"

        def data_filter(info):
            return white_filter_of({"filter_hz": info["filter_hz"], "sample_hz": rate_hz if sampling == "point" else None,
                             "filter_order": info["filter_order"]})

        def decide(cov_d, linear_d, nonlin_d):
            lin_f = linear_d if "white_noise" in linear_d else ["white_noise"] + list(linear_d)
            infos = _profile_filter(_Problem(tau, v, cov_d, None, tau0), lin_f, nonlin_d, tau0, sampling, given)
            dof_f = max(n_pts - len(lin_f) - 2 * len(nonlin_d) - 1, 1)
            # the 2-pole Butterworth is the autopilots' filter; a first-order shape only where the data exclude
            # the 2-pole's best at the 99 % level (a short correlated process, a sensor's own roll-off)
            info, one = infos[2], infos[1]
            margin = chi2_ppf(FILTER_LOG_LEVEL, 1) * max(1.0, one["chi2"] / dof_f)
            if one["interior"] and one["chi2"] < info["chi2"] - margin:
                info = one
            if given:
                # the log's cut-off is a prior, not a claim to test: it is set aside when the data put it outside
                # their 99 % profile interval (chi^2 scaled by the Birge ratio where the model misfits). A nominal
                # cut-off need not be the 2-pole equivalent of the real filter (an MPU-6000's "5 Hz" DLPF setting
                # fits as 8.4-8.6 Hz on a 2014 ArduPilot rover log), and N follows the shape it is given.
                thr = chi2_ppf(FILTER_LOG_LEVEL, 1) * max(1.0, info["chi2"] / dof_f)
                base_c2 = info["chi2_given"]
            else:
                thr = math.log(n_pts) + EXTRA_BIC_MARGIN
                base_c2 = info["chi2_plain"]
            # (the profile, whether the data set the log's cut-off or no filter aside, the first-order shape
            # where it fits better than that)
            return (info, bool(info["interior"] and info["chi2"] < base_c2 - thr),
                    one if one["interior"] and one["chi2"] < base_c2 else None,
                    one if one["interior"] and one["chi2"] < infos[2]["chi2"] else None)

        def under_own_model(shape):
            """decide's (profile, set aside) under the model fitted with the data's ``shape`` (its own selection
            and covariance), and that fit; ``white`` is left at ``shape``."""
            nonlocal white
            white = data_filter(shape)
            fit_d = iterate(0.0)
            return decide(*fit_d[:3])[:2] + (fit_d,)

        given = white
        filter_info, aside, better, over_two = decide(cov, linear, nonlin)
        if aside and filter_info["filter_order"] == 2 and over_two is not None:
            # the same where the data set the log's cut-off (or no filter) aside for a 2-pole of their own: the
            # 2-pole's model may have kept a drift term for the difference (a bias instability the record cannot
            # resolve), and the first-order shape is judged against it with that term in both. Judged again
            # under its own model (its own selection and covariance), by the same rules, it replaces the 2-pole
            # only if the data there put the 2-pole's best outside the margin too
            info2, aside2, fit_data = under_own_model(over_two)
            if aside2 and info2["filter_order"] == 1:
                filter_info = info2
                cov, linear, nonlin, c2, v_sup, sup_terms = fit_data
            else:
                white = given
        if not aside and better is not None:
            # the covariance above is the model's with the log's 2-pole shape (or no filter): where the data roll
            # off with another shape, the drift terms take up the difference and overshoot the long cluster
            # times, whose variance then looks larger than it is, and that model is judged leniently there (a
            # 20-s MPU-6000 axis: the log's 2-pole + an unresolved bias instability at 2.5x the data's ADEV at 5 s,
            # chi^2 5.5 for 7 dof). A first-order shape that fits better than that model is judged again under the
            # covariance of its own, by the same rules; it replaces the log's (or no filter) only if the data
            # exclude that there
            info2, aside, fit_data = under_own_model(better)
            if aside:
                filter_info = info2
                cov, linear, nonlin, c2, v_sup, sup_terms = fit_data
            else:
                white = given
        if aside:
            given_hz = given["filter_hz"] if given else None
            new_white = data_filter(filter_info)
            if new_white != white:
                white = new_white
                cov, linear, nonlin, c2, v_sup, sup_terms = iterate(0.0)
            filter_info["source"] = "data"
            order, fc = filter_info["filter_order"], filter_info["filter_hz"]
            notes.append(f"low-pass roll-off seen in the data: {order}-pole {fc:.3g} Hz "
                         f"[{filter_info['ci95'][0]:.3g}, {filter_info['ci95'][1]:.3g}] modelled in the white-noise term"
                         + (f" (the log's {given_hz:.3g} Hz set aside: outside the data's "
                            f"{100 * FILTER_LOG_LEVEL:.0f} % interval)" if given_hz else "")
                         + (f"; a first-order roll-off is also the shape of a Gauss-Markov process of tau_c "
                            f"{1.0 / (2.0 * math.pi * fc):.2g} s (the two look alike): N is the white level above it"
                            if order == 1 else ""))
        elif given:
            filter_info["source"] = "log"
        else:
            filter_info["source"] = None
    floor = 0.0
    dof0 = n_pts - len(linear) - 2 * len(nonlin)
    if dof0 >= 2 and c2 > dof0 + 3.0 * math.sqrt(2.0 * dof0):
        # Model misfit (real sensors: internal filters at short tau, temperature, ...): add a relative
        # model error `floor` to every point, chosen so that chi^2 = dof (as a Birge ratio / random-effects
        # term does), then select and fit again. Simulated data consistent with the model never get here.
        A = _columns(linear, nonlin, tau, white)

        def excess(lf):
            return _Problem(tau, v, cov + np.diag((math.exp(lf) * v_sup) ** 2), white, tau0).solve(A)[1] - dof0

        lo_f, hi_f = math.log(1e-4), math.log(3.0)
        if excess(hi_f) < 0:
            for _ in range(40):
                mid = 0.5 * (lo_f + hi_f)
                lo_f, hi_f = (mid, hi_f) if excess(mid) > 0 else (lo_f, mid)
            floor = math.exp(hi_f)
        else:
            floor = 3.0
        chi_before = c2
        cov, linear, nonlin, c2, v_sup, sup_terms = iterate(floor)
        notes.append(f"model misfit (chi2 {chi_before:.0f} for {dof0} dof): a model error of {100 * floor:.1f} % "
                     "of AVAR per point was added to the covariance")
    prob = _Problem(tau, v, cov, white, tau0)
    A = _columns(linear, nonlin, tau, white)
    theta, c2 = prob.solve(A)
    active = theta > 0
    # the intervals of the linear terms also carry the flicker's shape at the first cluster times
    # (:func:`_flicker_shape_cov`); the selection and the estimates do not use it
    prob_ci = prob
    if full and "bias_instability" in linear and theta[linear.index("bias_instability")] > 0:
        b_si = {"effect": "bias_instability", "B": math.sqrt(theta[linear.index("bias_instability")] * scale)}
        prob_ci = _Problem(tau, v, cov + _flicker_shape_cov(b_si, m, tau) / scale**2, white, tau0)
    cov_t = np.zeros((len(theta), len(theta)))
    if np.any(active):
        cov_t[np.ix_(active, active)] = prob_ci.cov_theta(A[:, active])
    terms = []
    for j, e in enumerate(linear + [e for e, _ in nonlin]):
        if theta[j] <= 0:
            continue
        lo, hi = _scaled_chi2_ci(theta[j], cov_t[j, j], level)
        if e in LINEAR_EFFECTS and full and inverted_ci and 2.0 * theta[j] ** 2 < INVERT_MAX_NU * cov_t[j, j]:
            lo, hi = _inverted_ci(theta[j], j, A, _cov_along(e, sup_terms, cov, theta, linear, scale, covariance, floor,
                                                            tau, m), tau, v, white, tau0, level, lo, hi)
        if e in LINEAR_EFFECTS:
            p = LINEAR_PARAM[e]
            t = {"effect": e, p: math.sqrt(theta[j] * scale), "ci95": {p: [math.sqrt(lo * scale), math.sqrt(hi * scale)]}}
            if e == "white_noise" and white:
                t.update(_filter_params(white))
        else:
            shape = dict(nonlin)[e]
            p, s = _NL_LINEAR[e], _NL_SHAPE[e]
            others = [x for x in nonlin if x[0] != e]
            s_lo, s_hi = _profile_ci(prob, e, shape, linear, others, tau, c2, level)
            # sigma (amplitude) and the shape parameter are correlated: the interval of the linear parameter
            # is its profile-likelihood interval over the shape (:func:`_profile_union`)
            designs = [_columns(linear, others + [(e, float(sh))], tau, white)
                       for sh in np.exp(np.linspace(math.log(s_lo), math.log(s_hi), 13))]
            lo, hi = _profile_union(lo, hi, prob, prob, len(linear) + len(others), designs, c2, level)
            t = {"effect": e, p: math.sqrt(theta[j] * scale), s: shape,
                 "ci95": {p: [math.sqrt(lo * scale), math.sqrt(hi * scale)], s: [s_lo, s_hi]}}
        terms.append(t)
    sup = [e for e in LINEAR_EFFECTS if e in linear or (e in BASE_EFFECTS and e in effects)]
    if auto and full and set(sup) != set(linear):
        _selection_envelope(terms, prob_ci, sup, nonlin, tau, white, scale, level)
    first_order = False
    if white:
        # N and the cut-off found in the data are correlated: N's interval is its profile-likelihood interval
        # over the cut-off, the union over f_c of N's conditional intervals at the level left once f_c's own
        # chi^2 excess is spent (chi^2(f_c) - chi^2_min + z^2 <= chi2_level(1)). The envelope of full-level
        # conditional intervals over f_c's interval (the projection) allowed twice that excess and covered
        # 99-100 % where a 95 % interval was asked for. With the log's cut-off (not profiled), over the order
        wt = next((t for t in terms if t["effect"] == "white_noise"), None)
        if wt is not None:
            wt["ci95"]["N"], first_order = _profile_white_ci(
                wt["ci95"]["N"], prob, prob_ci, linear, nonlin, tau, white,
                filter_info["ci95"] if (filter_info or {}).get("source") == "data" else None,
                c2, scale, level, tau0, notes)
    kk = int(np.count_nonzero(active)) + len(nonlin)
    avar_fit = avar_model([{k: v_ for k, v_ in t.items() if k != "ci95"} for t in terms], tau)
    return FitResult(terms=terms, tau=tau, avar_fit=avar_fit, chi2=c2, dof=max(n_pts - kk, 0),
                     criterion="bic", score=c2 + kk * math.log(n_pts),
                     covariance_mode="full" if full else "diagonal", avar_cov=cov * scale**2, notes=notes,
                     model_error=floor, filter=_filter_summary(white, filter_info, first_order))


def _profile_union(lo, hi, prob, prob_ci, j, designs, c2, level):
    """The interval [lo, hi] (``prob``'s theta units) of the linear parameter in column ``j`` widened to its
    profile-likelihood interval over a shape parameter: ``designs`` holds the model's columns at each shape
    value of a grid; at each, the conditional interval at the level left once that shape's chi^2 excess over
    the minimum (``c2`` at the estimate, or the grid's least) is spent: chi^2(shape) - chi^2_min + z^2 <=
    chi2_level(1). The envelope of full-level conditional intervals over the shape's interval (a projection)
    allows twice that excess: N's over a cut-off found in the data covered 99-100 %, a Gauss-Markov sigma's
    over its tau_c 99 % (191 of 193) where 95 % was asked for."""
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
        l2, h2 = _scaled_chi2_ci(th2[j], ct[k, k], max(chi2_cdf(left, 1), 1e-6))
        lo, hi = min(lo, l2), max(hi, h2)
    return lo, hi


def _profile_white_ci(ci, prob, prob_ci, linear, nonlin, tau, white, fc_ci, c2, scale, level, tau0=None,
                      notes=None, first_order=None):
    """N's interval ``ci`` (at the fitted cut-off) widened to its profile-likelihood interval over the roll-off's
    shape (:func:`_profile_union`): f_c on a log grid over its interval ``fc_ci`` widened by half its log-width
    each side (the final covariance, with any model error, may allow more than the first profile did; None: the
    log's cut-off, which is not profiled) and, for a 2-pole, the first-order shape over its whole range
    (FILTER_ORDERS, FIRST_ORDER_MAX; sample period ``tau0``): where the record cannot tell the two orders apart,
    N's interval spans both readings (on 20 s of a first-order roll-off the 2-pole + an unresolved drift term
    read N at half the level the 1-pole reads); a note then goes to ``notes`` (a list) when given.
    ``first_order``: whether the first-order shape is in the profile, as decided before (the online report takes
    its selection's, between re-selections); None: decided here. Returns (interval, first_order)."""
    designs = []
    if fc_ci is not None:
        lo_l, hi_l = math.log(fc_ci[0]), math.log(fc_ci[1])
        pad = 0.5 * (hi_l - lo_l)
        designs = [_columns(linear, nonlin, tau, dict(white, filter_hz=float(fc)))
                   for fc in np.exp(np.linspace(lo_l - pad, hi_l + pad, 13))]
    grid1 = _cutoff_grid(1, tau, tau0) if tau0 else np.empty(0)
    if int(white.get("filter_order") or 2) == 2 and grid1.size and first_order is not False:
        ones = [_columns(linear, nonlin, tau, dict(white, filter_hz=float(fc), filter_order=1))
                for fc in np.exp(grid1)]
        # only a first-order roll-off the data show (its best cut-off inside the range, as the order's choice
        # asks, the profile's `interior`): one pressed against the range's top is no roll-off below a tenth of
        # the sample rate
        if first_order is None:
            first_order = int(np.argmin([prob.solve(A1)[1] for A1 in ones])) < len(ones) - 3
        if first_order:
            if notes is not None:
                two = _profile_union(ci[0] ** 2 / scale, ci[1] ** 2 / scale, prob, prob_ci,
                                     linear.index("white_noise"), designs, c2, level)
            designs += ones
        else:
            notes = None
    else:
        notes, first_order = None, False
    lo, hi = _profile_union(ci[0] ** 2 / scale, ci[1] ** 2 / scale, prob, prob_ci, linear.index("white_noise"),
                            designs, c2, level)
    out = [math.sqrt(lo * scale), math.sqrt(hi * scale)]
    if notes is not None and (lo < 0.98 * two[0] or hi > 1.02 * two[1]):
        notes.append(f"N's interval spans a first-order roll-off's reading too: the record does not tell it from the "
                     f"2-pole (within the {100 * FILTER_LOG_LEVEL:.0f} % margin)")
    return out, bool(first_order)


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
    # terms that pull the estimate that way. Without them the forced model gave the selected model's
    # covariance back: on 60 s at 10 Hz of white noise + flicker + random walk, the selection kept N and K in
    # 712 of 2000 records, B came out at zero in the forced model in many of them, and N (+3 % there, the
    # flicker's share) was covered in 92.6 % of them; with them 95.9 %, white noise alone as wide as before
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
    moves its share into the kept terms. Measured on random 2-h N/B/K draws (benchmarks/bench_fit.py draws):
    a rate random walk too weak to be selected went into B, whose interval then missed the truth high
    (1.02-1.08 x) in 7-8 of 100 draws. Estimates are unchanged."""
    forced = forced_intervals(prob, sup, nonlin, tau, white, level)
    for t in terms:
        e = t["effect"]
        if e not in forced:
            continue
        p = LINEAR_PARAM[e]
        lo_s, hi_s = forced[e]
        lo, hi = t["ci95"][p]
        t["ci95"][p] = [min(lo, math.sqrt(max(lo_s, 0.0) * scale)), max(hi, math.sqrt(max(hi_s, 0.0) * scale))]


def _points_cov(terms_si, m, n, rate_hz, segments, scale, max_ratio=256) -> np.ndarray:
    """Model covariance of the AVAR points (in units of ``scale``^2) for noise made of ``terms_si``: the
    overlapping estimator's (:func:`~companion.allan.confidence.oavar_covariance`), pooled over ``segments``
    when there are several."""
    if segments is not None and len(segments) > 1:
        from companion.allan.pooled import pooled_oavar_covariance

        return pooled_oavar_covariance(terms_si, m, segments, rate_hz, max_ratio=max_ratio) / scale**2
    return oavar_covariance(terms_si, m, n, rate_hz, max_ratio=max_ratio) / scale**2


def _with_shape_errors(c, terms_si, tau, scale, white, floor, v_model) -> np.ndarray:
    """``c`` plus the model's own uncertainty: the modelled filter's shape and the relative model error
    ``floor`` (of the model AVAR ``v_model``, in units of ``scale``)."""
    wt = next((t for t in terms_si if t["effect"] == "white_noise"), None) if white else None
    if wt is not None:
        # a real filter chain is no exact 2-pole Butterworth at exactly f_c: the modelled shape is uncertain
        # in proportion to how far it bends the point (FILTER_SHAPE_ERROR of the bend), so the bent points
        # count less as the record grows -- the soft form of leaving them out
        bend = 1.0 - avar_white_noise(tau, 1.0, **white) * tau
        c = c + np.diag((FILTER_SHAPE_ERROR * np.maximum(bend, 0.0) * avar_term(wt, tau) / scale) ** 2)
    return c + np.diag((floor * v_model) ** 2)


def _flicker_shape_cov(bias_term, m, tau) -> np.ndarray:
    """Covariance (SI) of the fitted AVAR's bias-instability share from the uncertain shape of the flicker at the
    first cluster times. The plateau (2 ln2 / pi) B^2 holds only from a few tau0 on: how a sensor samples its
    flicker (aliasing folds power in, a filter takes it out) moves the first points by up to ~20 %
    (:func:`companion.allan.confidence.flicker_sampling_excess`, +19 % at tau0 for a flicker sampled without
    anti-alias filter). Those points carry most of N's information (EDF ~ 10^5 on hours of data) and the
    departure falls roughly like 1/tau there -- the white-noise shape -- so no fit can tell it from N: where B
    reaches the short taus (white noise meets the flicker floor within a few seconds) it moved N by 1-3 of N's
    standard deviations and N's interval covered the truth in 88 % of random draws. One shape error of
    FLICKER_SHAPE_ERROR x that excess, fully correlated over tau (a rank-one term), widens N's interval by what
    it can move N, and by nothing where B is negligible at tau0."""
    sh = FLICKER_SHAPE_ERROR * flicker_sampling_excess(m) * avar_term(bias_term, tau)
    return np.outer(sh, sh)


def _filter_params(white) -> dict:
    """A white-noise term's filter parameters from the column's filter: numbers, the order an integer."""
    return {k: (int(v) if k == "filter_order" else float(v)) for k, v in white.items() if v}


def _filter_summary(white, info, first_order=False):
    if not white:
        return None
    out = {"filter_hz": float(white["filter_hz"]), "sample_hz": white.get("sample_hz"),
           "source": (info or {}).get("source") or "log"}
    if white.get("filter_order"):
        out["filter_order"] = int(white["filter_order"])
    if info and info.get("source") == "data":
        out["ci95"] = list(info["ci95"])
    if first_order:
        out["first_order_in_ci"] = True  # the data's first-order reading is in N's profile interval
    return out


#: the data's roll-off: the filter orders profiled, and the lowest cut-off of each in units of 1 / tau_max (a
#: 2-pole at 30 / tau_max and a 1-pole at 8 / tau_max lower the AVAR at the longest cluster time by 0.5 % and 3 %)
FILTER_ORDERS = {2: 30.0, 1: 8.0}
#: a first-order roll-off is looked for only below this fraction of the sample rate: above it a first-order and
#: a 2-pole roll-off differ at the first two or three octave points only, where how the samples were taken
#: (point or averaged, a digital filter, a sensor's averaging window) shapes the curve as much as the order, and
#: FILTER_SHAPE_ERROR carries that (measured: the ADIS16405's and a PX4 log's roll-offs fitted as 1-pole
#: 29-53 Hz moved N by up to 5 % and out of its interval)
FIRST_ORDER_MAX = 0.1


def _profile_filter(prob, linear, nonlin, tau0, sampling, given=None, level=0.95) -> dict:
    """Profile chi^2 of the white-noise term's low-pass cut-off f_c, for each order of FILTER_ORDERS (a dict
    order -> result), over a log grid from its lowest cut-off to 3 / tau0 (a filter above that bends no
    cluster time; a first-order one to FIRST_ORDER_MAX / tau0), refined by a bounded 1-D minimisation.
    ``interior``: the optimum is not at the grid's upper end (there the data look unfiltered). ``ci95``: the
    cut-off's ``level`` profile interval at that order; ``chi2_plain`` and ``chi2_given``: without a filter and
    with the log's."""
    sample_hz = 1.0 / tau0 if sampling == "point" else None
    plain = prob.solve(_columns(linear, nonlin, prob.tau, None))[1]
    given_c2 = (prob.solve(_columns(linear, nonlin, prob.tau, white_filter_of(dict(given, sample_hz=sample_hz))))[1]
                if given else None)
    return {order: _profile_filter_order(prob, linear, nonlin, tau0, sample_hz, level, order, plain, given_c2)
            for order in FILTER_ORDERS}


def _cutoff_grid(order, tau, tau0) -> np.ndarray:
    """The log cut-offs profiled for a roll-off of ``order``: from FILTER_ORDERS[order] / tau_max to 3 / tau0
    (2-pole) or FIRST_ORDER_MAX / tau0 (first-order); empty where the record is too short for that range."""
    lo, hi = FILTER_ORDERS[order] / tau[-1], (3.0 if order == 2 else FIRST_ORDER_MAX) / tau0
    return np.linspace(math.log(lo), math.log(hi), 41 if order == 2 else 21) if hi > lo else np.empty(0)


def _profile_filter_order(prob, linear, nonlin, tau0, sample_hz, level, order, plain, given_c2):
    tau = prob.tau
    extra = {} if order == 2 else {"filter_order": order}

    def chi(lf):
        w = {"filter_hz": math.exp(lf), "sample_hz": sample_hz, **extra}
        return prob.solve(_columns(linear, nonlin, tau, w))[1]

    out = {"chi2_plain": plain, "filter_hz": None, "chi2": plain, "interior": False, "ci95": [None, None],
           "filter_order": order, "chi2_given": given_c2}
    grid = _cutoff_grid(order, tau, tau0)
    if grid.size == 0:
        return out
    vals = np.array([chi(g) for g in grid])
    i = int(np.argmin(vals))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    x, fx = minimize_scalar_bounded(chi, a, b, xatol=1e-3)
    best, c2 = (x, fx) if fx < vals[i] else (grid[i], float(vals[i]))
    thr = c2 + chi2_ppf(level, 1)
    inside = np.flatnonzero(vals <= thr)
    if inside.size == 0:
        inside = np.array([i])
    i0, i1 = int(inside.min()), int(inside.max())

    def g(lf):
        return chi(lf) - thr

    ci = [math.exp(brentq(g, grid[i0 - 1], min(grid[i0], best), xtol=1e-3)) if i0 > 0 and g(grid[i0 - 1]) > 0 > g(min(grid[i0], best)) else math.exp(grid[max(i0 - 1, 0)]),
          math.exp(brentq(g, max(grid[i1], best), grid[i1 + 1], xtol=1e-3)) if i1 < len(grid) - 1 and g(grid[i1 + 1]) > 0 > g(max(grid[i1], best)) else math.exp(grid[min(i1 + 1, len(grid) - 1)])]
    out.update(filter_hz=math.exp(best), chi2=float(c2), interior=bool(best < grid[-3]),
               ci95=[min(ci[0], math.exp(best)), max(ci[1], math.exp(best))])
    return out


def _profile_ci(prob, effect, shape, linear, others, tau, c2min, level):
    """Profile-likelihood interval of a shape parameter (tau_c or freq_hz) on a log grid."""
    lo, hi = _shape_range(effect, tau, prob.tau0)
    lo, hi = min(lo, shape), max(hi, shape)
    grid = np.exp(np.linspace(math.log(lo) - 1.0, math.log(hi) + 1.0, 121))
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


#: one-sided 95 % normal quantile of an upper bound
_Z95 = 1.6448536269514722


def upper_bounds(fr: FitResult, tau, avar, *, n, rate_hz, m=None, segments=None,
                 effects=("white_noise", "bias_instability", "random_walk"), max_iter=12) -> list[dict]:
    """95 % upper bounds of the ``effects`` the fit ``fr`` left out, each the value the data would reject at
    the one-sided 5 % level: the term is added to the fitted model, theta_u = theta_hat + z sd, with the AVAR
    points' covariance evaluated *at the bound* (the fitted terms as they are, the left-out one at theta_u)
    and solved for the fixed point (a test inversion). Evaluated at the fitted value instead (0 or low for a
    term the selection left out), the points where the term would show look too precise and the bound falls
    below the truth: a rate random walk left out of 2-h records was bounded below its truth for 9 of 17 left-out
    K, against 1 of 17 here (benchmarks/bench_fit.py draws). Terms the record rule made nuisance
    (``fr.nuisance``) are part of the model. ``companion analyze`` reports these bounds. ``tau``, ``avar``: the
    points the fit saw (``fr.tau``). Report format: {"effect", P: bound, "std": {P: bound / z}, "ci95": {P: [0,
    bound]}, "bound": True}."""
    tau = np.asarray(tau, dtype=float)
    avar = np.asarray(avar, dtype=float)
    have = {t["effect"] for t in fr.terms}
    missing = [e for e in effects if e not in have and e in LINEAR_PARAM]
    if not missing or not (fr.terms or fr.nuisance) or tau.size < 3:
        return []
    # a term the record is too short to resolve (fr.nuisance) stays in the model of the others' bounds, as in
    # the fit: left out, the bounded term would take up its share
    m = np.round(tau * rate_hz).astype(np.int64) if m is None else np.asarray(m, dtype=np.int64)
    white = white_filter_of(fr.filter)
    plain = [{k: v for k, v in t.items() if k != "ci95"} for t in list(fr.terms) + list(fr.nuisance)]
    linear = [t["effect"] for t in plain if t["effect"] in LINEAR_EFFECTS]
    nonlin = [(t["effect"], float(t[_NL_SHAPE[t["effect"]]])) for t in plain if t["effect"] in NONLINEAR_EFFECTS]
    scale = float(np.median(avar[avar > 0]))
    v = avar / scale

    def cov_at(terms):
        return _with_shape_errors(_points_cov(terms, m, n, rate_hz, segments, scale), terms, tau, scale, white,
                                  fr.model_error, avar_model(terms, tau) / scale)

    out = []
    for e in missing:
        p = LINEAR_PARAM[e]
        lin = [x for x in LINEAR_EFFECTS if x in linear or x == e]
        A = _columns(lin, nonlin, tau, white)
        j = lin.index(e)
        others = [t for t in plain if t["effect"] != e]

        order = {x: i for i, x in enumerate(LINEAR_EFFECTS + NONLINEAR_EFFECTS)}

        def cov_with(u):
            # the terms in the fit's order, the bounded one in even at 0: the covariance's pair sums are
            # remembered per set of term shapes, and the fit computed this set's for its superset model
            terms = others + [{"effect": e, p: math.sqrt(max(u, 0.0) * scale)}]
            return cov_at(sorted(terms, key=lambda t: order.get(t["effect"], len(order))))

        # the points' covariance is a quadratic form in the terms' squared magnitudes (pair sums, model error),
        # so in u it is exactly C0 + u C1 + u^2 C2: three evaluations give it at every u the search asks for
        u_s = max(float(np.max(v)) / float(np.max(A[:, j])), 1e-300)
        c0, c1, c2 = cov_with(0.0), cov_with(u_s), cov_with(2.0 * u_s)
        lin_c, quad_c = (4.0 * c1 - 3.0 * c0 - c2) / (2.0 * u_s), (c2 - 2.0 * c1 + c0) / (2.0 * u_s**2)

        def step(u):
            """theta_hat + z sd of the term with the points' covariance evaluated at theta = u (None: without it)."""
            prob = _Problem(tau, v, c0 + (lin_c * u + quad_c * u * u if u else 0.0), white, 1.0 / rate_hz)
            theta, _ = prob.solve(A)
            # the term's variance with it freed from the bound 0 (the others as the NNLS left them)
            act = (theta > 0) | (np.arange(len(theta)) == j)
            ct = prob.cov_theta(A[:, act])
            k = int(np.count_nonzero(act[:j]))
            return max(float(theta[j]), 0.0) + _Z95 * math.sqrt(max(float(ct[k, k]), 0.0))

        # the bound is the fixed point u = step(u): below it the data do not reject u (h = log step(u) - log u
        # > 0), above it they do. Plain iteration creeps (10-15 % a step where the term would dominate the
        # long-tau points) and step() jumps where the NNLS drops a term; so: secant steps in log u until the
        # sign of h changes, then regula falsi with bisection inside the bracket, and, unconverged, the lowest
        # u found rejected (conservative)
        u = step(None)
        lo = hi = prev = None  # (log u, h) with h > 0 (the largest such u) / h < 0 (the smallest)
        ub = None
        for _ in range(max_iter):
            f = step(u)
            if not (f > 0 and u > 0):
                ub = max(f, u)
                break
            x, h = math.log(u), math.log(f) - math.log(u)
            if abs(h) <= 1e-3:
                ub = max(f, u)
                break
            if h > 0 and (lo is None or x > lo[0]):
                lo = (x, h)
            if h < 0 and (hi is None or x < hi[0]):
                hi = (x, h)
            if lo and hi:
                if hi[0] - lo[0] <= 2e-3:
                    break
                nx = lo[0] - lo[1] * (hi[0] - lo[0]) / (hi[1] - lo[1])
                d = hi[0] - lo[0]
                if not lo[0] + 0.05 * d < nx < hi[0] - 0.05 * d:
                    nx = 0.5 * (lo[0] + hi[0])
            else:
                nx = math.log(f)
                if prev is not None and h != prev[1]:
                    sec = x - h * (x - prev[0]) / (h - prev[1])
                    if math.isfinite(sec) and x - math.log(4.0) <= sec <= x + math.log(16.0):
                        nx = sec
            prev = (x, h)
            u = math.exp(nx)
        if ub is None:
            ub = math.exp(hi[0]) if hi else max(f, u)
        b = math.sqrt(max(ub, 0.0) * scale)
        out.append({"effect": e, p: b, "std": {p: b / _Z95}, "ci95": {p: [0.0, b]}, "bound": True})
    return out
