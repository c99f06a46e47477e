"""The Allan coefficients theta = [Q^2, N^2, B^2, K^2, R^2] from a bank's Allan variances: sigma_j^2 = A_j theta
(Miao 2014 eq. (3.6); :func:`companion.allan.terms.linear_basis`) solved with theta >= 0.

- :func:`fit_theta`: weighted NNLS with var(sigma_j^2) = 2 (A_j theta)^2 / edf_j (chi-square), the weights
  iterated from the model, plus a model-error floor when the model does not fit (Birge ratio);
- :func:`fit_theta_gls`: generalised NNLS with the model covariance of the overlapping Allan estimates
  (:func:`companion.allan.confidence.oavar_covariance`), cached on a sqrt(2) grid.

numpy only (the live pipeline loads no scipy: seconds of start-up, tens of MB on a small board).
"""

from __future__ import annotations

import math

import numpy as np

from companion.allan.confidence import oavar_covariance
from companion.allan.lsq import nnls
from companion.allan.terms import LINEAR_PARAM, linear_basis

GLS_CACHE_SIZE = 16  #: covariance factors kept per estimator (a stable model reuses one; ~0.1 s each to build)
GLS_MIN_SHARE = 0.05  #: a term under this share of the model at every level is left out of the covariance


def _wnnls(A, avar, edf, floor, iterations, model=None):
    """Weighted NNLS of avar = A theta with var_j = 2 model_j^2 / edf_j + (floor model_j)^2, the weights
    iterated from the model. Returns (theta, model, sw) with sw the final 1/sd per point."""
    tiny = 1e-300
    model = avar.copy() if model is None else model
    theta = np.zeros(A.shape[1])

    def weights(mod):
        mod = np.maximum(mod, avar * 1e-3 + tiny)
        return 1.0 / (mod * np.sqrt(2.0 / edf + floor**2))

    for _ in range(iterations):
        sw = weights(model)
        Aw = A * sw[:, None]
        scale = np.linalg.norm(Aw, axis=0)
        scale[scale == 0] = 1.0
        sol, _ = nnls(Aw / scale, avar * sw)
        theta = sol / scale
        new_model = A @ theta
        if np.allclose(new_model, model, rtol=1e-9, atol=0):
            model = new_model
            break
        model = new_model
    return theta, model, weights(model)


def fit_theta(tau, avar, edf, effects, iterations=6, return_floor=False):
    """Weighted NNLS of AVAR = A theta, theta = squared coefficients; var(avar_j) = 2 model_j^2 / edf_j.

    Model misfit (real sensors: the internal low-pass filter bends the ADEV at a few tau0, a short-tau
    Gauss-Markov shape, lines): when chi^2 exceeds dof + 3 sqrt(2 dof), a relative model error e, the same
    for every level, is added, var_j = 2 model_j^2 / edf_j + (e model_j)^2, with e chosen so that
    chi^2 = dof (Birge ratio; bisection on ln e, the fit redone at each step) -- as the offline fit
    :func:`companion.allan.fit.fit_avar` does. Without it the thousands of degrees of freedom of the
    shortest cluster times let a small misfit there set N and push B several times too high (on a real
    ADIS16405 record, B 2.3-3.5x the offline fit's). Simulated data consistent with the model never get here.

    Returns ``(theta, std_theta)`` (arrays over ``effects``; std is inf where nothing constrains it), and
    the model error e as a third item with ``return_floor``.
    """
    n_par = len(effects)
    tau = np.asarray(tau, float)
    avar = np.asarray(avar, float)
    edf = np.asarray(edf, float)
    if tau.size == 0:
        out = (np.zeros(n_par), np.full(n_par, np.inf))
        return out + (0.0,) if return_floor else out
    A = linear_basis(tau, effects)
    floor = 0.0
    theta, model, sw = _wnnls(A, avar, edf, 0.0, iterations)
    dof = tau.size - int(np.count_nonzero(theta))
    chi2 = float(np.sum(((avar - model) * sw) ** 2))
    if dof >= 2 and chi2 > dof + 3.0 * math.sqrt(2.0 * dof):
        def excess(lf):  # warm-started from the unfloored model: a few reweightings suffice
            th, mod, w = _wnnls(A, avar, edf, math.exp(lf), 3, model)
            return float(np.sum(((avar - mod) * w) ** 2)) - dof

        lo, hi = math.log(1e-4), math.log(3.0)
        if excess(hi) < 0:
            for _ in range(14):  # ln e to 10.3 / 2^14 = 6e-4
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if excess(mid) > 0 else (lo, mid)
        floor = math.exp(hi)
        theta, model, sw = _wnnls(A, avar, edf, floor, iterations, model)
    Aw = A * sw[:, None]
    F = Aw.T @ Aw  # Fisher information of theta
    std = np.full(n_par, np.inf)
    free = theta > 0
    if free.any():
        try:
            cov = np.linalg.inv(F[np.ix_(free, free)])
            std[free] = np.sqrt(np.maximum(np.diag(cov), 0.0))
        except np.linalg.LinAlgError:
            pass
    for i in np.flatnonzero(~free):
        idx = np.flatnonzero(free | (np.arange(n_par) == i))
        sub = F[np.ix_(idx, idx)]
        try:
            cov = np.linalg.pinv(sub)
            v = cov[list(idx).index(i), list(idx).index(i)]
            std[i] = math.sqrt(v) if v > 0 else np.inf
        except np.linalg.LinAlgError:
            pass
    return (theta, std, floor) if return_floor else (theta, std)


def _quantise(x: float) -> float:
    """Round a positive number to the nearest power of sqrt(2) (41 % steps; C only weights the fit)."""
    return float(2.0 ** (round(2.0 * math.log2(x)) / 2.0))


def fit_theta_gls(tau, avar, theta0, effects, n, rate_hz, max_ratio=16, iterations=2, cache=None, floor=0.0):
    """Generalised NNLS with the model covariance of the Allan estimates at the levels (including the strong
    correlation of neighbouring cluster times), as the offline fit :func:`companion.allan.fit.fit_avar`:
    C = oavar_covariance(model, m, n) (overlapping estimator; the staggered phases are close to it; model
    and n rounded to sqrt(2) steps, which changes the weights only, and cached),
    theta = argmin_{theta >= 0} (v - A theta)^T C^-1 (v - A theta), C recomputed from the new model.
    ``floor``: the model error of :func:`fit_theta` (misfit), added as (floor model)^2 to the diagonal of C.
    Starts from ``theta0`` (the diagonal fit). Returns ``(theta, std_theta)``."""
    tau = np.asarray(tau, float)
    avar = np.asarray(avar, float)
    m = np.round(tau * rate_hz).astype(np.int64)
    A = linear_basis(tau, effects)
    scale = float(np.median(avar)) if np.any(avar > 0) else 1.0
    v = avar / scale
    theta = np.asarray(theta0, float) / scale
    n_par = len(effects)
    n = _quantise(max(float(n), float(2 * m.max() + 2)))
    floor = _quantise(floor) if floor > 0 else 0.0
    F = None
    for _ in range(iterations):
        # C is computed from the model and n rounded to sqrt(2) steps: a deterministic function of the
        # state (so results never depend on when terms() was called before), cached because it costs ~0.1 s
        # terms contributing less than 5 % of the model at every level are left out of C
        frac = (A * theta) / np.maximum((A @ theta)[:, None], 1e-300)
        th_q = tuple(_quantise(t * scale) if t > 0 and frac[:, i].max() >= GLS_MIN_SHARE else 0.0
                     for i, t in enumerate(theta))
        key = (tuple(m.tolist()), th_q, n, float(rate_hz), int(max_ratio), tuple(effects), floor)
        L = cache.get(key) if cache is not None else None
        if L is None:
            model = [{"effect": e, LINEAR_PARAM[e]: math.sqrt(t)} for e, t in zip(effects, th_q)]
            C = oavar_covariance(model, m, int(n), rate_hz, max_ratio=max_ratio)
            C = C + np.diag((floor * (A @ np.asarray(th_q))) ** 2)
            C = C + np.diag(np.maximum(np.diag(C), 1e-300) * 1e-9)
            try:
                L = np.linalg.cholesky(C)
            except np.linalg.LinAlgError:
                return np.asarray(theta0, float), np.full(n_par, np.inf)
            if cache is not None:
                if len(cache) >= GLS_CACHE_SIZE:
                    cache.pop(next(iter(cache)))
                cache[key] = L
        L = L / scale
        Aw = np.linalg.solve(L, A)
        vw = np.linalg.solve(L, v)
        cs = np.linalg.norm(Aw, axis=0)
        cs[cs == 0] = 1.0
        sol, _ = nnls(Aw / cs, vw)
        theta = sol / cs
        F = Aw.T @ Aw
    std = np.full(n_par, np.inf)
    free = theta > 0
    for i in range(n_par):
        idx = np.flatnonzero(free | (np.arange(n_par) == i))
        try:
            cov = np.linalg.pinv(F[np.ix_(idx, idx)])
            vv = cov[list(idx).index(i), list(idx).index(i)]
            std[i] = math.sqrt(vv) if vv > 0 else np.inf
        except np.linalg.LinAlgError:
            pass
    return theta * scale, std * scale
