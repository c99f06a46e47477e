"""The fit's least squares: design columns of the AVAR model and the whitened, non-negative GLS problem.

Model (IEEE 952 Annex C; Miao et al. 2014 eq. (3.6)): sigma^2(tau) = sum_j theta_j phi_j(tau) + nonlinear terms,
theta = [Q^2, N^2, B^2, K^2, R^2] with phi = [3/tau^2, 1/tau, 2 ln2/pi, tau/3, tau^2/2]
(:func:`companion.allan.terms.linear_basis`), plus a Gauss-Markov term (sigma^2 linear, tau_c nonlinear) and a
sinusoid (A^2 linear, freq_hz nonlinear). Estimator:

    theta_hat = argmin_{theta >= 0} (v - A theta)^T C^-1 (v - A theta),

solved as NNLS (Lawson & Hanson 1974) after whitening with the Cholesky factor L of C (C = L L^T).
"""

from __future__ import annotations

import math

import numpy as np

from companion.allan.fit.constants import GM_MIN_SAMPLES, NL_LINEAR, NL_SHAPE
from companion.allan.lsq import nnls
from companion.allan.memo import BoundedMemo
from companion.allan.terms import LINEAR_PARAM, avar_term, avar_white_noise, linear_basis

#: the smallest standard deviation of a point taken as non-zero (a term that vanishes at a point)
_SD_FLOOR = 1e-300
#: eigenvalues of the points' correlation below this are clipped: the truncated pair sums of
#: oavar_covariance can leave the matrix slightly indefinite
_EIG_FLOOR = 1e-6
#: the magnitudes a term is reported by (a term with all of them 0 is not reported)
_MAGNITUDES = ("Q", "N", "B", "K", "R", "sigma", "amplitude")


class _Problem:
    """Whitened GLS problem for a fixed covariance C (scaled so the data are O(1)): C = D R D (D the points'
    standard deviations, R their correlation with its eigenvalues clipped at _EIG_FLOOR), L = chol(R) D.
    ``white``: the white-noise column's filter (dict or None); ``tau0``: the sample period."""

    def __init__(self, tau, v, cov, white=None, tau0=None):
        self.tau, self.v = tau, v
        self.white, self.tau0 = white, tau0
        cov = 0.5 * (cov + cov.T)
        d = np.sqrt(np.maximum(np.diag(cov), _SD_FLOOR))
        corr = cov / np.outer(d, d)
        w, U = np.linalg.eigh(0.5 * (corr + corr.T))
        corr = (U * np.maximum(w, _EIG_FLOOR)) @ U.T
        self.L = np.linalg.cholesky(corr) * d[:, None]
        self.vw = self._w(v)
        #: solve's results by design: the model search asks for the same design again (a fifth of the solves)
        self._solved: dict = {}

    def _w(self, x):
        """L^-1 x: the whitened vector or columns."""
        return np.linalg.solve(self.L, x) if np.ndim(x) == 1 else np.linalg.solve(self.L, x)

    def solve(self, A):
        """(theta_hat >= 0, chi^2) for the design ``A`` (columns scaled to unit norm for the NNLS).

        A candidate whose covariance is ~0 at some point (a term that vanishes there) whitens to 1e150 and
        beyond: its chi^2 is inf (the candidate loses), without a RuntimeWarning."""
        key = (A.shape, A.tobytes())
        done = self._solved.get(key)
        if done is not None:
            return done[0].copy(), done[1]
        done = self._solve(A)
        self._solved[key] = done
        return done[0].copy(), done[1]

    def _solve(self, A):
        with np.errstate(over="ignore", invalid="ignore"):
            Aw = self._w(A)
            scale = np.maximum(np.sqrt((Aw**2).sum(axis=0)), _SD_FLOOR)
            theta, _ = nnls(Aw / scale, self.vw, max_iter=50 * A.shape[1] + 50)
            theta = theta / scale
            r = self.vw - Aw @ theta
            c2 = float(r @ r)
        return theta, (c2 if math.isfinite(c2) else math.inf)

    def cov_theta(self, A):
        """Covariance of the coefficients of ``A``'s columns: (A^T C^-1 A)^-1 (pseudo-inverse)."""
        Aw = self._w(A)
        return np.linalg.pinv(Aw.T @ Aw)


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


#: filtered white-noise columns by (tau, filter): the model search asks for the same one hundreds of times per
#: fit (each shape-grid point, each candidate set) and each costs a phase-structure evaluation
_FILTERED_COLUMNS = BoundedMemo(256, read_only=True)


def _filtered_white_column(tau, white):
    """The filtered white-noise column at ``tau`` (:func:`companion.allan.terms.avar_white_noise`, N = 1)."""
    key = (np.asarray(tau, dtype=float).tobytes(), white.get("filter_hz"), white.get("sample_hz"),
           white.get("filter_order"))
    return _FILTERED_COLUMNS.get(key, lambda: avar_white_noise(tau, 1.0, **white))


#: the plain columns phi_j by (tau, effect): the model search builds thousands of designs from the same few
_LINEAR_COLUMNS = BoundedMemo(256, read_only=True)


def _linear_column(tau, effect):
    """The column phi_j of a linear effect at ``tau`` (:func:`companion.allan.terms.linear_basis`)."""
    key = (np.asarray(tau, dtype=float).tobytes(), effect)
    return _LINEAR_COLUMNS.get(key, lambda: np.ascontiguousarray(linear_basis(tau, [effect])[:, 0]))


def _columns(linear, nonlinear, tau, white=None):
    """Design matrix A: the columns phi_j of the ``linear`` effects, then one per (effect, shape) of
    ``nonlinear``; ``white``: {"filter_hz", "sample_hz"[, "filter_order"]} of a low-pass filter seen by the
    white noise (its column is then the filtered shape)."""
    cols = [_filtered_white_column(tau, white) if (e == "white_noise" and white) else _linear_column(tau, e)
            for e in linear]
    cols += [_shape_column(e, s, tau) for e, s in nonlinear]
    return np.column_stack(cols) if cols else np.zeros((len(tau), 0))


def _filter_params(white) -> dict:
    """A white-noise term's filter parameters from the column's filter: numbers, the order an integer."""
    return {k: (int(v) if k == "filter_order" else float(v)) for k, v in white.items() if v}


def _terms_from(linear, nonlinear, theta, scale, white=None):
    """Term dicts (SI) of the coefficients ``theta`` (units of ``scale``): each magnitude sqrt(theta scale);
    terms with no positive magnitude are left out."""
    terms = []
    for e, t in zip(linear, theta[: len(linear)]):
        terms.append({"effect": e, LINEAR_PARAM[e]: math.sqrt(max(t, 0.0) * scale)})
        if e == "white_noise" and white:
            terms[-1].update(_filter_params(white))
    for (e, s), t in zip(nonlinear, theta[len(linear):]):
        terms.append({"effect": e, NL_LINEAR[e]: math.sqrt(max(t, 0.0) * scale), NL_SHAPE[e]: s})
    return [t for t in terms if any(v > 0 for k, v in t.items() if k in _MAGNITUDES)]
