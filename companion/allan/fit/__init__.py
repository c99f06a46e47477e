"""Automatic fit of a measured Allan variance with the IEEE Std 952 terms, with calibrated 95 % intervals.

Model (IEEE 952 Annex C; Miao et al. 2014 eq. (3.6)): sigma^2(tau) = sum_j theta_j phi_j(tau) + nonlinear terms,
theta = [Q^2, N^2, B^2, K^2, R^2] with phi = [3/tau^2, 1/tau, 2 ln2/pi, tau/3, tau^2/2], plus optionally one
Gauss-Markov term and one sinusoid. Estimator: generalised least squares with theta >= 0 under the model
covariance C of the overlapping AVAR estimates, recomputed from each new fit. When the caller gives no
``n``/``rate_hz`` (only tau, avar and the EDF), C is diagonal, 2 model^2 / EDF, inflated by 2 x (points per octave)
for the correlation of neighbouring points (an approximation; analyze always uses the full C).

The parts, by role:

- :mod:`~companion.allan.fit.gls`: design columns and the whitened non-negative GLS problem;
- :mod:`~companion.allan.fit.point_cov`: the covariance of the AVAR points under a model;
- :mod:`~companion.allan.fit.term_selection`: which terms the data demand (BIC, Schwarz 1978; extras on
  "very strong" evidence, Kass & Raftery 1995);
- :mod:`~companion.allan.fit.fit_state`: the state the steps share, and the select-and-weigh iteration;
- :mod:`~companion.allan.fit.rolloff`: the low-pass roll-off modelled in the white-noise term;
- :mod:`~companion.allan.fit.intervals`: the terms' intervals (Satterthwaite 1946, test inversion, profile
  likelihood, the selection envelope);
- :mod:`~companion.allan.fit.record_rule`: a long-tau term is reported only on a record that resolves it;
- :mod:`~companion.allan.fit.upper_bound`: 95 % upper bounds of the terms the fit left out;
- :mod:`~companion.allan.fit.steps`: :func:`fit_avar`, the orchestrator of the steps;
- :mod:`~companion.allan.fit.constants`: the numerical rules, each with its reason.

Model misfit (real sensors: an internal low-pass filter bends the ADEV at a few tau0, temperature drifts are no
IEEE 952 term): a relative model error is added so that chi^2 = dof, and the result carries ``model_error`` and a
note. Coverage is measured in benchmarks/bench_fit.py.
"""

from companion.allan.fit.constants import (AUTO_EFFECTS, EXTRA_BIC_MARGIN, FILTER_LOG_LEVEL, FILTER_ORDERS,
                                           FILTER_SHAPE_ERROR, FIRST_ORDER_MAX, FLICKER_SHAPE_ERROR, GM_MIN_SAMPLES,
                                           INVERT_MAX_NU, NONLINEAR_EFFECTS, QUANT_SLOPE, QUANT_SLOPE2,
                                           RESOLVE_EFFECTS, RESOLVE_MIN_RECORD_S, RESOLVE_RECORD_FACTOR)
from companion.allan.fit.gls import _columns, _Problem
from companion.allan.fit.intervals import _scaled_chi2_ci, forced_intervals
from companion.allan.fit.record_rule import dominates_from, record_needed
from companion.allan.fit.fit_result import FitResult
from companion.allan.fit.rolloff import _profile_white_ci
from companion.allan.fit.steps import fit_avar
from companion.allan.fit.term_selection import quantization_slope
from companion.allan.fit.upper_bound import upper_bounds

__all__ = ["AUTO_EFFECTS", "EXTRA_BIC_MARGIN", "FILTER_LOG_LEVEL", "FILTER_ORDERS", "FILTER_SHAPE_ERROR",
           "FIRST_ORDER_MAX", "FLICKER_SHAPE_ERROR", "FitResult", "GM_MIN_SAMPLES", "INVERT_MAX_NU",
           "NONLINEAR_EFFECTS", "QUANT_SLOPE", "QUANT_SLOPE2", "RESOLVE_EFFECTS", "RESOLVE_MIN_RECORD_S",
           "RESOLVE_RECORD_FACTOR", "_Problem", "_columns", "_profile_white_ci", "_scaled_chi2_ci",
           "dominates_from", "fit_avar", "forced_intervals", "quantization_slope", "record_needed", "upper_bounds"]
