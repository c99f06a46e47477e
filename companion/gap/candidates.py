"""Fit noise terms to a measured Allan variance by maximum likelihood, and weigh candidate effects.

Likelihood: each overlapping AVAR estimate a_i is s_i chi^2_{nu_i} / nu_i (NIST SP 1065 sec. 5.3), so
-2 ln L = D + const with the Gamma deviance D = sum nu_i (a_i/s_i - 1 - ln(a_i/s_i)) (see compare.py).
The model AVAR s = s_fixed + A c is linear in the squared magnitudes c_j = p_j^2 (Q^2, N^2, B^2, K^2, R^2,
sigma^2, amplitude^2; IEEE 952 Annex C, Miao 2014 eq. (3.6)) once the shape parameters (tau_c,
freq_hz) are fixed.

* Magnitudes: Fisher scoring for the Gamma family with identity link, i.e. iteratively reweighted
  non-negative least squares  c <- argmin_{c >= 0} sum nu_i (a_i - s_fixed,i - (A c)_i)^2 / s_i^2  with
  s from the previous step (its fixed point solves the likelihood equations on the active set).
* Shape parameters: profile likelihood, D_p(theta) = min_c D(c, theta), on a log grid then a bounded scalar
  refinement (tau_c: 8 per decade; freq_hz: 30 per decade, the sinusoid's profile being rugged).
* Uncertainty: Fisher information I = 1/2 sum nu_i / s_i^2 (ds_i/dtheta)(ds_i/dtheta)^T for theta = ln p,
  inflated by sqrt(max(1, G)) (quasi-likelihood overdispersion, G the gap metric of the fit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar, nnls

from companion.allan.memo import BoundedMemo
from companion.gap.likelihood import MODEL_FLOOR, Measured, deviance, gap_metric, term_avar

#: The magnitude parameter of each effect (AVAR proportional to its square).
MAGNITUDE = {"quantization": "Q", "white_noise": "N", "bias_instability": "B", "random_walk": "K",
             "ramp": "R", "gauss_markov": "sigma", "sinusoid": "amplitude",
             # a rate proportional to the log's temperature (companion.gap.temperature_candidate); offered only when the
             # log has a temperature channel, never by the generic candidate loop
             "temperature": "coef"}
#: The shape parameter of effects that have one.
SHAPE = {"gauss_markov": "tau_c", "sinusoid": "freq_hz"}
#: Number of free parameters a candidate adds (its magnitude and its shape).
N_PARAMS = {e: 1 + (e in SHAPE) for e in MAGNITUDE}


#: unit columns by term shape, cluster times and rate: a workflow asks for a few hundred distinct ones
_UNIT_COLUMNS = BoundedMemo(4096, read_only=True)


def unit_column(term, tau, rate_hz):
    """AVAR of ``term`` with its magnitude set to 1 (the column of A). Remembered by the term's shape: a
    workflow's profiles and tests ask for the same base columns tens of thousands of times."""
    t = dict(term)
    mag = MAGNITUDE[t["effect"]]
    t[mag] = 1.0
    shape = tuple(sorted((k, v) for k, v in t.items() if k != mag))
    try:
        key = (shape, np.asarray(tau, dtype=float).tobytes(), float(rate_hz))
        hash(key)
    except TypeError:  # a term carrying arrays (the temperature record): computed each time
        return term_avar(t, tau, rate_hz)
    return _UNIT_COLUMNS.get(key, lambda: term_avar(t, tau, rate_hz))


@dataclass
class Fit:
    """Fitted terms, their deviance and gap, and 95 % intervals of the magnitudes (and shapes)."""

    terms: list
    fixed: list  # indices of terms held fixed (not refitted)
    dev: float
    gap: float
    s: np.ndarray
    ci95: list = field(default_factory=list)  # per term: {param: [lo, hi]}
    se_log: list = field(default_factory=list)  # per term: {param: se of ln(param)}


TOL = 1e-7  # IRLS stops when no point's model moves by more than this (relative) ...
STALL = 10  # ... or when this many iterations in a row found no lower deviance (an active set flipping)


def fit_magnitudes(meas: Measured, A: np.ndarray, s_fixed: np.ndarray, iters: int = 80):
    """IRLS-NNLS for c >= 0 in s = s_fixed + A c; returns (c, s, D), the iterate of least deviance.

    The stops (TOL, STALL) are set where, over the fits of the gap tests' workflows, they change the
    deviance by at most 5e-14 (relative) against running to the 80-iteration cap."""
    a, nu = meas.avar, meas.nu
    floor = 1e-9 * a
    k = A.shape[1]
    if k == 0:
        s = np.maximum(s_fixed, floor)
        return np.zeros(0), s, deviance(meas, s)
    # the loop runs tens of thousands of times per workflow on a few dozen points: what does not change
    # between iterations is computed once
    sq_nu, rhs = np.sqrt(nu), a - s_fixed
    s = a.copy()
    best = (np.inf, None, None)
    since = 0
    for _ in range(iters):
        w = sq_nu / s
        M = w[:, None] * A
        norms = np.sqrt(np.add.reduce(M * M, axis=0))  # np.linalg.norm(M, axis=0)
        norms[norms == 0] = 1.0
        c, _ = nnls(M / norms, w * rhs, maxiter=50 * k)
        c = c / norms
        s_new = np.maximum(s_fixed + A @ c, floor)
        d = deviance(meas, s_new)
        if d < best[0] * (1.0 - 1e-12):
            best, since = (d, c, s_new), 0
        else:
            since += 1
            if d < best[0]:
                best = (d, c, s_new)
        if since >= STALL or np.max(np.abs(s_new - s) / s) < TOL:
            break
        s = s_new
    d, c, s = best
    return c, s, d


def _assemble(meas, terms, fixed):
    rate = meas.rate_hz
    s_fixed = np.zeros_like(meas.tau)
    cols, free = [], []
    for i, t in enumerate(terms):
        if i in fixed:
            s_fixed = s_fixed + term_avar(t, meas.tau, rate)
        else:
            cols.append(unit_column(t, meas.tau, rate))
            free.append(i)
    A = np.column_stack(cols) if cols else np.zeros((meas.tau.shape[0], 0))
    return A, s_fixed, free


def fit_terms(meas: Measured, terms, fixed=(), intervals: bool = True) -> Fit:
    """Refit the magnitudes of every term not in ``fixed`` (shapes as given)."""
    terms = [dict(t) for t in terms]
    fixed = sorted(set(fixed))
    A, s_fixed, free = _assemble(meas, terms, fixed)
    c, s, d = fit_magnitudes(meas, A, s_fixed)
    for j, i in enumerate(free):
        terms[i][MAGNITUDE[terms[i]["effect"]]] = float(math.sqrt(max(c[j], 0.0)))
    fit = Fit(terms=terms, fixed=fixed, dev=d, gap=gap_metric(meas, s), s=s)
    if intervals:
        _intervals(meas, fit, free)
    return fit


def _intervals(meas: Measured, fit: Fit, free, shape_free=()) -> None:
    """Fisher-information 95 % intervals of the free magnitudes (and listed shape params), in log space."""
    rate, s = meas.rate_hz, fit.s
    grads, labels = [], []
    for i in free:
        t = fit.terms[i]
        p = MAGNITUDE[t["effect"]]
        if t[p] > 0:
            grads.append(2.0 * term_avar(t, meas.tau, rate))  # d s / d ln p
        else:
            grads.append(unit_column(t, meas.tau, rate) * 1e-300)  # placeholder, handled below
        labels.append((i, p))
    for i in shape_free:
        t = fit.terms[i]
        q = SHAPE[t["effect"]]
        h = 1e-4
        up, dn = dict(t), dict(t)
        up[q] = t[q] * math.exp(h)
        dn[q] = t[q] * math.exp(-h)
        grads.append((term_avar(up, meas.tau, rate) - term_avar(dn, meas.tau, rate)) / (2 * h))
        labels.append((i, q))
    fit.ci95 = [dict() for _ in fit.terms]
    fit.se_log = [dict() for _ in fit.terms]
    if not grads:
        return
    G = np.column_stack(grads)
    info = 0.5 * (G * (meas.nu / s**2)[:, None]).T @ G
    infl = math.sqrt(max(1.0, fit.gap))
    try:
        cov = np.linalg.pinv(info)
    except np.linalg.LinAlgError:
        return
    for j, (i, p) in enumerate(labels):
        val = fit.terms[i][p]
        if val > 0 and cov[j, j] > 0:
            se = min(math.sqrt(cov[j, j]) * infl, 300.0)
            fit.se_log[i][p] = se
            fit.ci95[i][p] = [val * math.exp(-1.96 * se), val * math.exp(1.96 * se)]
        elif val == 0:
            # upper bound from the curvature in c = p^2 at c = 0
            col = unit_column(fit.terms[i], meas.tau, rate)
            info_c = 0.5 * np.sum(meas.nu * col**2 / s**2)
            fit.ci95[i][p] = [0.0, math.sqrt(1.96 * infl / math.sqrt(info_c)) if info_c > 0 else math.inf]


def shape_grid(effect: str, meas: Measured) -> np.ndarray:
    """Log grid of the shape parameter over values whose signature falls inside the measured tau range."""
    t0, t1 = float(meas.tau[0]), float(meas.tau[-1])
    if effect == "gauss_markov":  # ADEV peak at 1.89 tau_c
        # tau_c >= 3 tau0: below that the sampled process (what the simulator and a sensor produce) is
        # nearly white with N^2 = sigma^2 tau0 (1+phi)/(1-phi), phi = e^(-tau0/tau_c), not the continuous
        # 2 sigma^2 tau_c of IEEE 952 C.6 (15 % off in ADEV at tau_c = tau0/2, 1 % at 3 tau0)
        lo, hi, per = max(t0 / 2.0, 3.0 / meas.rate_hz), 2.0 * t1, 8
    else:  # sinusoid: ADEV peak at 0.371 / f0, below Nyquist
        lo, hi, per = 0.371 / (2.0 * t1), min(0.371 / (t0 / 2.0), 0.45 * meas.rate_hz), 30
    n = max(int(math.ceil(math.log10(hi / lo) * per)) + 1, 2)
    return np.logspace(math.log10(lo), math.log10(hi), n)


def fit_with_candidate(meas: Measured, base_terms, fixed, effect: str, near: float | None = None) -> Fit:
    """Fit ``base_terms`` (magnitudes free except ``fixed``) plus one new term of ``effect``.

    ``near``: a shape value found for the same effect in a closely related fit (the same state with one
    more term free); the profile then runs over every third grid point plus +-3 grid steps around it, a
    third of the work, for the many "effect + recalibrated term" fits."""
    mag = MAGNITUDE[effect]
    new_index = len(base_terms)
    if effect not in SHAPE:
        fit = fit_terms(meas, list(base_terms) + [{"effect": effect, mag: 1.0}], fixed)
        return fit
    q = SHAPE[effect]
    grid = shape_grid(effect, meas)
    if near is not None and near > 0:
        per = 8 if effect == "gauss_markov" else 30
        local = near * 10.0 ** (np.arange(-3, 4) / per)
        grid = np.unique(np.concatenate([grid[::3], local[(local >= grid[0]) & (local <= grid[-1])]]))

    def profile(log_v):
        return fit_terms(meas, list(base_terms) + [{"effect": effect, mag: 1.0, q: float(math.exp(log_v))}],
                         fixed, intervals=False)

    devs = np.array([profile(math.log(v)).dev for v in grid])
    # the profile is rugged (a sinusoid's Allan curve has notches, the taus are octaves apart): refine
    # around the three lowest local minima of the grid, not only the lowest grid point
    n = len(grid)
    minima = [k for k in range(n) if (k == 0 or devs[k] <= devs[k - 1]) and (k == n - 1 or devs[k] <= devs[k + 1])]
    best_u, best_d = math.log(grid[int(np.argmin(devs))]), float(np.min(devs))
    for k in sorted(minima, key=lambda k: devs[k])[:3]:
        lo = math.log(grid[max(k - 1, 0)])
        hi = math.log(grid[min(k + 1, n - 1)])
        if hi > lo:
            res = minimize_scalar(lambda u: profile(u).dev, bounds=(lo, hi), method="bounded",
                                  options={"xatol": 1e-4})
            if res.fun < best_d:
                best_u, best_d = float(res.x), float(res.fun)
    u = best_u
    fit = profile(u)
    free = [i for i in range(len(fit.terms)) if i not in fit.fixed]
    _intervals(meas, fit, free, shape_free=[new_index] if fit.terms[new_index][mag] > 0 else [])
    return fit


def estimate_covariance(meas: Measured, fit: Fit) -> np.ndarray:
    """Model covariance of the octave AVAR estimates under ``fit``: Cov_model + diag(MODEL_FLOOR^2 s^2).

    Cov_model is :func:`companion.allan.confidence.oavar_covariance` (Greenhall & Riley 2003, across
    cluster sizes) for the fitted stochastic terms (a ramp carries no sampling covariance of its own); the
    floor is the 5 % model floor of :func:`companion.gap.compare.measure`."""
    from companion.allan.confidence import oavar_covariance

    rate = meas.rate_hz
    s = np.maximum(fit.s, 1e-300)
    stoch = [dict(t, f0=t.get("f0") or rate / 2.0) if t["effect"] == "bias_instability" else dict(t)
             for t in fit.terms if t["effect"] not in ("ramp", "temperature") and t[MAGNITUDE[t["effect"]]] > 0]
    cov = oavar_covariance(stoch, meas.m, meas.n, rate) if stoch else np.zeros((s.shape[0],) * 2)
    return cov + np.diag((MODEL_FLOOR * s) ** 2)


def lr_inflation(meas: Measured, fit: Fit, i: int | None, direction=None, sigma=None) -> float:
    """Overdispersion phi >= 1 of a likelihood-ratio statistic at ``fit`` (sandwich, quasi-likelihood).

    The deviance treats the octave estimates as independent with nu EDF each, i.e. Cov(a) = Sigma_0 =
    diag(2 s^2 / nu). With flicker (bias instability) or random-walk noise, neighbouring long-tau estimates
    are strongly correlated and few in EDF, so Sigma_0 understates the spread of the fitted magnitudes.
    With c the free magnitudes (s = s_fixed + A c), D = diag(nu / (2 s^2)), I = A^T D A (Fisher information of
    the Gamma likelihood) and Sigma the model covariance (:func:`estimate_covariance`), the sandwich V = I^-1 (A^T D Sigma D A) I^-1 is the actual covariance of c, I^-1 the one the
    deviance assumes, and the LR statistic of c_k is rescaled by phi = max(1, V_kk / (I^-1)_kk) (never below
    1: deterministic terms carry no sampling covariance, so the correction only makes a test more cautious).
    Terms at zero or fixed are left out of A.

    * ``direction`` None: the tested parameter is the magnitude of term ``i`` (mis-sized test).
    * ``direction`` given (ds/dtheta over ``meas.tau``): a parameter theta that ``fit`` holds at 0 (score-test
      form), appended as a last column with every free nonzero term (and term ``i``, if not None) free: the
      magnitude of a candidate effect the model lacks (its unit column), or 1/tau_c of a Gauss-Markov term at
      its random-walk limit (:func:`gm_rw_direction`).
    * ``direction`` a list of such columns: a joint test of several parameters (an effect added together
      with a recalibrated term). The statistic is then divided by the largest eigenvalue of P^-1 V_TT,
      P = (I^-1)_TT and V_TT the naive and sandwich covariances of the k tested parameters T (the
      conservative bound of Rao & Scott 1981: LR / delta_max is stochastically below chi^2_k). Not the
      first-order (mean) factor: a useless extra direction with little overdispersion would lower the mean
      and let "effect + needless recalibration" outscore the effect alone. The largest eigenvalue over a
      larger set of directions is never smaller, so a combination never gains from its correction; for
      k = 1 it is the ratio above.
    """
    rate = meas.rate_hz
    free = [j for j, t in enumerate(fit.terms)
            if j not in fit.fixed and (j == i or fit.terms[j][MAGNITUDE[t["effect"]]] > 0)]
    if direction is None and i not in free:
        return 1.0
    cols = [unit_column(fit.terms[j], meas.tau, rate) for j in free]
    extra = []
    if direction is not None:
        extra = [np.asarray(d, dtype=float) for d in direction] if isinstance(direction, (list, tuple)) \
            else [np.asarray(direction, dtype=float)]
        cols += extra
    A = np.column_stack(cols)
    s = np.maximum(fit.s, 1e-300)
    if sigma is None:  # the callers weighing many directions at one fit pass it once
        sigma = estimate_covariance(meas, fit)
    Dw = meas.nu / (2.0 * s**2)
    DA = Dw[:, None] * A
    info = A.T @ DA
    try:
        inv = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return 1.0
    V = inv @ (DA.T @ sigma @ DA) @ inv
    T = [free.index(i)] if direction is None else list(range(len(free), len(free) + len(extra)))
    P, VT = inv[np.ix_(T, T)], V[np.ix_(T, T)]
    if not (np.all(np.isfinite(VT)) and np.all(np.diag(P) > 0)):
        return 1.0
    try:
        ratio = float(np.max(np.real(np.linalg.eigvals(np.linalg.solve(P, VT)))))
    except np.linalg.LinAlgError:
        return 1.0
    return float(max(1.0, ratio)) if np.isfinite(ratio) else 1.0


def gm_rw_direction(meas: Measured, K: float) -> np.ndarray:
    """ds/dlambda of a Gauss-Markov term at its random-walk limit, lambda = 1/tau_c -> 0 with
    K^2 = 2 sigma^2 / tau_c held: expanding IEEE 952 C.6 in x = tau/tau_c,
    sigma^2(tau) = K^2 tau/3 - K^2 lambda tau^2/4 + O(lambda^2), so the column is -K^2 tau^2 / 4 (checked
    against :func:`companion.allan.terms.avar_gauss_markov` at lambda = 1e-5..1e-6)."""
    return -(K**2) * meas.tau**2 / 4.0


def pinned(meas: Measured, term) -> bool:
    """A sinusoid at a frequency the record's periodogram measured (``meas.lines``): the frequency is the
    data's, resolved to a bin, and is not moved along the Allan curve's profile (flat near the Nyquist
    frequency, where the octave cluster times see a line at tau0 alone)."""
    return term["effect"] == "sinusoid" and any(abs(term["freq_hz"] - f) <= 1e-9 * f for f, _ in meas.lines)


def refine_shapes(meas: Measured, terms, fixed, indices, steps: int = 3) -> Fit:
    """Refit with the shape parameters (tau_c, freq_hz) of the terms ``indices`` re-optimised one after the
    other by profile likelihood near their current values (``steps`` grid steps of :func:`shape_grid` either
    side, then a bounded refinement), magnitudes free except ``fixed``. Used when a state changes (a term
    recalibrated, an effect added or held back): a shape fitted before is then no longer the maximum of the
    likelihood, and a test that kept it would let it absorb part of what is tested."""
    terms = [dict(t) for t in terms]
    for i in indices:
        t = terms[i]
        q = SHAPE.get(t["effect"])
        if q is None or t[MAGNITUDE[t["effect"]]] <= 0 or pinned(meas, t):
            continue
        per = 8 if t["effect"] == "gauss_markov" else 30
        step = math.log(10.0) / per
        u0 = math.log(t[q])

        def dev(u, i=i, q=q):
            trial = [dict(x) for x in terms]
            trial[i][q] = float(math.exp(u))
            return fit_terms(meas, trial, fixed, intervals=False).dev

        u_lo = math.log(float(shape_grid(t["effect"], meas)[0]))
        us = [max(u0 + k * step, u_lo) for k in range(-steps, steps + 1)]
        ds = [dev(u) for u in us]
        k = int(np.argmin(ds))
        res = minimize_scalar(dev, bounds=(us[max(k - 1, 0)], us[min(k + 1, len(us) - 1)]), method="bounded",
                              options={"xatol": 1e-4})
        terms[i][q] = float(math.exp(res.x if res.fun < ds[k] else us[k]))
        lo_q = float(shape_grid(t["effect"], meas)[0])
        if terms[i][q] < lo_q:  # the candidates' bounds hold after a refinement too (tau_c >= 3 tau0)
            terms[i][q] = lo_q
    return fit_terms(meas, terms, fixed, intervals=False)
