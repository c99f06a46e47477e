"""Covariance of the measured AVAR points under a model: the overlapping estimator's own, plus the model's
uncertain parts (a modelled filter's shape, the flicker's shape at the first cluster times, a relative model
error under misfit).

C is computed from the *model* (not from the noisy measured points, whose use biases the fit low) by
:func:`companion.allan.confidence.oavar_covariance`: it holds the variances (the EDF) and the strong correlation
between neighbouring cluster times, so the fit neither over-weights a run of correlated points nor reports
intervals that are too narrow.
"""

from __future__ import annotations

import numpy as np

from companion.allan.confidence import flicker_sampling_excess, oavar_covariance
from companion.allan.fit import constants
from companion.allan.terms import avar_term, avar_white_noise


def _points_cov(terms_si, m, n, rate_hz, segments, scale, max_ratio=256) -> np.ndarray:
    """Model covariance of the AVAR points (in units of ``scale``^2) for noise made of ``terms_si``: the
    overlapping estimator's (:func:`~companion.allan.confidence.oavar_covariance`), pooled over ``segments``
    when there are several (:func:`companion.allan.pooled.pooled_oavar_covariance`)."""
    if segments is not None and len(segments) > 1:
        from companion.allan.pooled import pooled_oavar_covariance

        return pooled_oavar_covariance(terms_si, m, segments, rate_hz, max_ratio=max_ratio) / scale**2
    return oavar_covariance(terms_si, m, n, rate_hz, max_ratio=max_ratio) / scale**2


def _with_shape_errors(c, terms_si, tau, scale, white, floor, v_model) -> np.ndarray:
    """``c`` plus the model's own uncertainty: the modelled filter's shape and the relative model error
    ``floor`` (of the model AVAR ``v_model``, in units of ``scale``):

        C' = C + diag((FILTER_SHAPE_ERROR max(bend, 0) AVAR_N / scale)^2) + diag((floor v_model)^2),
        bend = 1 - AVAR_white(tau; N = 1) tau.

    The filter's shape is uncertain in proportion to how far it bends the point, so the bent points count less
    as the record grows -- the soft form of leaving them out."""
    wt = next((t for t in terms_si if t["effect"] == "white_noise"), None) if white else None
    if wt is not None:
        bend = 1.0 - avar_white_noise(tau, 1.0, **white) * tau
        c = c + np.diag((constants.FILTER_SHAPE_ERROR * np.maximum(bend, 0.0) * avar_term(wt, tau) / scale) ** 2)
    return c + np.diag((floor * v_model) ** 2)


def _flicker_shape_cov(bias_term, m, tau) -> np.ndarray:
    """Covariance (SI) of the fitted AVAR's bias-instability share from the uncertain shape of the flicker at the
    first cluster times: s s^T with s = FLICKER_SHAPE_ERROR x excess(m) x AVAR_B(tau).

    The plateau (2 ln2 / pi) B^2 holds only from a few tau0 on: how a sensor samples its flicker (aliasing folds
    power in, a filter takes it out) moves the first points by up to ~20 %
    (:func:`companion.allan.confidence.flicker_sampling_excess`, +19 % at tau0 for a flicker sampled without
    anti-alias filter). Those points carry most of N's information (EDF ~ 10^5 on hours of data) and the
    departure falls roughly like 1/tau there -- the white-noise shape -- so no fit can tell it from N: where B
    reaches the short taus (white noise meets the flicker floor within a few seconds) it moves N by 1-3 of N's
    standard deviations (without this term N's interval covers the truth in 88 % of random draws). One shape
    error, fully correlated over tau (a rank-one term), widens N's interval by what it can move N, and by
    nothing where B is negligible at tau0."""
    sh = constants.FLICKER_SHAPE_ERROR * flicker_sampling_excess(m) * avar_term(bias_term, tau)
    return np.outer(sh, sh)
