"""The model after, fitted to the measurement's band: magnitudes that put the model inside the 95 % band of
as many cluster times as they can.

The workflow's fits are maximum likelihood with a 5 % model floor in AVAR (:data:`companion.gap.likelihood.
MODEL_FLOOR`): right for weighing explanations, whose shapes no model follows to better than that. On a long
record the shortest cluster times' band is far narrower (2 h at 50 Hz: +-0.3 % at tau0), and a model fitted
with the floor misses it there by a fraction of a per cent. The band's own weights, EDF/2 per point on the log
scale, make the fit linear in the squared magnitudes: non-negative least squares on rows scaled by
sqrt(EDF/2)/model, iterated with the model in the scale (weights from the measured AVAR favour the points that
lie low).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar, nnls

from companion.gap.candidates import MAGNITUDE, SHAPE, _assemble
from companion.gap.compare import gap_metric
from companion.gap.likelihood import Measured

#: reweighting passes of the band fit
PASSES = 3
#: a shape (Gauss-Markov tau_c) is re-profiled on the band's weights within this factor of the steps' value:
#: the analytic Gauss-Markov AVAR and a discrete record of a few samples' tau_c differ by about a per cent at
#: the shortest cluster times, where a long record's band is narrower
SHAPE_RANGE = 1.3


def in_band(meas: Measured, s) -> float:
    """The share of cluster times where the model AVAR ``s`` lies inside the measurement's 95 % band."""
    s = np.asarray(s, dtype=float)
    return float(np.mean((s >= meas.lo) & (s <= meas.hi)))


def band_fit(meas: Measured, terms, fixed) -> tuple[list, np.ndarray]:
    """Magnitudes of the terms not in ``fixed`` (shapes as given) by the band's weights (module docstring).
    Returns (terms, model AVAR)."""
    terms = [dict(t) for t in terms]
    A, s_fixed, free = _assemble(meas, terms, sorted(set(fixed)))
    if not free:
        return terms, s_fixed
    nu = np.maximum(np.asarray(meas.nu_raw, dtype=float), 1.0)  # the band's own EDF (lo, hi), not the floored
    scale = np.asarray(meas.avar, dtype=float)
    for _ in range(PASSES):
        w = np.sqrt(nu / 2.0) / np.maximum(scale, 1e-300)
        norms = np.linalg.norm(A * w[:, None], axis=0)
        norms = np.where(norms > 0, norms, 1.0)
        c, _ = nnls((A * w[:, None]) / norms, (meas.avar - s_fixed) * w, maxiter=50 * A.shape[1] + 100)
        c = c / norms
        s = s_fixed + A @ c
        scale = np.maximum(s, 1e-300)
    for j, i in enumerate(free):
        terms[i][MAGNITUDE[terms[i]["effect"]]] = float(math.sqrt(max(c[j], 0.0)))
    return terms, s


def _band_chi2(meas: Measured, s) -> float:
    nu = np.maximum(np.asarray(meas.nu_raw, dtype=float), 1.0)
    return float(np.sum(nu / 2.0 * np.log(np.asarray(meas.avar) / np.maximum(s, 1e-300)) ** 2))


def band_fit_shapes(meas: Measured, terms, fixed) -> tuple[list, np.ndarray]:
    """:func:`band_fit` with each free Gauss-Markov tau_c re-profiled (one at a time, on a log scale, within
    SHAPE_RANGE of its value) on the band's chi-square."""
    terms = [dict(t) for t in terms]
    for i, t in enumerate(terms):
        if i in fixed or t["effect"] != "gauss_markov" or not t.get(SHAPE[t["effect"]]):
            continue
        q, v0 = SHAPE[t["effect"]], float(t[SHAPE[t["effect"]]])

        def cost(u, i=i, q=q):
            trial = [dict(x) for x in terms]
            trial[i][q] = v0 * math.exp(u)
            return _band_chi2(meas, band_fit(meas, trial, fixed)[1])

        r = minimize_scalar(cost, bounds=(-math.log(SHAPE_RANGE), math.log(SHAPE_RANGE)), method="bounded",
                            options={"xatol": 1e-3})
        if r.fun < cost(0.0):
            terms[i][q] = v0 * math.exp(float(r.x))
    return band_fit(meas, terms, fixed)


def better_in_band(meas: Measured, terms, fixed, s_ml) -> tuple[list, np.ndarray] | None:
    """The band fit (shapes re-profiled) where it puts the model inside the band at more cluster times than
    the maximum-likelihood fit ``s_ml`` (of equals, where its gap G is smaller); else None."""
    t_band, s_band = band_fit_shapes(meas, terms, fixed)
    key_ml = (in_band(meas, s_ml), -gap_metric(meas, s_ml))
    key_band = (in_band(meas, s_band), -gap_metric(meas, s_band))
    return (t_band, s_band) if key_band > key_ml else None
