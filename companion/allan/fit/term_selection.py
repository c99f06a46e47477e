"""Which terms the data demand, for a fixed covariance of the AVAR points.

Every subset of the usual gyro model {white_noise, bias_instability, random_walk} is fitted and the one with the
least Bayesian information criterion BIC = chi^2 + k ln(n_points) is kept (k = non-zero coefficients; Schwarz
1978). Then quantization (only where :func:`quantization_slope` sees its slope), ramp and one Gauss-Markov term
(tau_c by :func:`_best_shape`, kept only at an interior optimum) are tried in turn (a sinusoid the same way,
only when asked for) and kept only if they lower the BIC by more than EXTRA_BIC_MARGIN. A forward pass then
brings back any base term whose return lowers the BIC (an extra term may have displaced it), and a backward pass
drops any term whose removal costs less than its penalty (a term picked early may have stood in for one picked
later). A slope region absent from the data simply leaves its coefficient at 0: never NaN.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from companion.allan.fit.constants import (EXTRA_BIC_MARGIN, NONLINEAR_EFFECTS, QUANT_SLOPE, QUANT_SLOPE2,
                                           SHAPE_EDGE, SHAPE_GRID)
from companion.allan.fit.gls import _columns, _shape_range
from companion.allan.special import minimize_scalar_bounded
from companion.allan.terms import BASE_EFFECTS, LINEAR_EFFECTS

#: subsets whose BIC differ by less than this are equal: the first (fewest terms) is kept
_BIC_TIE = 1e-9
#: the bounded refinement of a log shape parameter stops at this width (0.1 % of the shape)
_SHAPE_XTOL = 1e-3


class ShapeFit(NamedTuple):
    """The best shape parameter of a nonlinear term (:func:`_best_shape`)."""

    shape: float  # tau_c or freq_hz at the least chi^2
    chi2: float
    grid: np.ndarray  # the log shape grid searched
    chi2_grid: np.ndarray  # chi^2 at each grid point
    interior: bool  # the optimum is not pinned to an end of the range: the term is identified


@dataclass
class Selection:
    """A selected model for a fixed covariance: ``linear`` effects, ``nonlin`` (effect, shape) pairs, its chi^2,
    and ``bic``, the score an extra term must beat by EXTRA_BIC_MARGIN (the forward and backward passes after
    that step compare chi^2 changes with the penalties directly)."""

    linear: list
    nonlin: list
    c2: float
    bic: float = math.inf


class _Move(NamedTuple):
    """A candidate change of the model in the forward/backward passes, and what it gains (> 0: better)."""

    gain: float
    linear: list
    nonlin: list
    c2: float


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


def _best_shape(prob, effect, linear, others, tau) -> ShapeFit | None:
    """Grid (SHAPE_GRID points over :func:`~companion.allan.fit.gls._shape_range`, in log) + bounded refinement
    (Brent) of the shape parameter of ``effect`` beside the ``linear`` effects and the ``others`` nonlinear
    ones; None where the range is empty (the record is too short for the term)."""
    lo, hi = _shape_range(effect, tau, prob.tau0)
    if not hi > lo > 0:
        return None

    def chi(log_s):
        A = _columns(linear, others + [(effect, math.exp(log_s))], tau, prob.white)
        return prob.solve(A)[1]

    grid = np.linspace(math.log(lo), math.log(hi), SHAPE_GRID[effect])
    vals = np.array([chi(g) for g in grid])
    i = int(np.argmin(vals))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    res_x, res_fun = minimize_scalar_bounded(chi, a, b, xatol=_SHAPE_XTOL)
    best = float(res_x) if res_fun < vals[i] else float(grid[i])
    span = grid[-1] - grid[0]
    interior = grid[0] + SHAPE_EDGE * span < best < grid[-1] - SHAPE_EDGE * span
    return ShapeFit(math.exp(best), min(float(res_fun), float(vals[i])), grid, vals, interior)


def _fit_given(prob, tau, lin_cand, nl_cand) -> Selection:
    """No selection: every candidate in, each nonlinear one at its best shape."""
    nonlin = []
    for e in nl_cand:
        r = _best_shape(prob, e, lin_cand, nonlin, tau)
        if r:
            nonlin.append((e, r.shape))
    _, c2 = prob.solve(_columns(lin_cand, nonlin, tau, prob.white))
    return Selection(lin_cand, nonlin, c2)


def _best_base_subset(prob, tau, base, n_pts) -> Selection:
    """The subset of the base effects with the least BIC = chi^2 + k ln(n_points), k its non-zero
    coefficients (ties: the first, smallest subset); only its non-zero effects are kept."""
    best = None
    for k in range(1, len(base) + 1):
        for subset in itertools.combinations(base, k):
            theta, c2 = prob.solve(_columns(list(subset), [], tau, prob.white))
            kk = int(np.count_nonzero(theta > 0))
            bic = c2 + kk * math.log(n_pts)
            if best is None or bic < best.bic - _BIC_TIE:
                best = Selection([e for e, t in zip(subset, theta) if t > 0], [], c2, bic)
    return best if best is not None else Selection([], [], 0.0, math.inf)


def _add_extras(prob, tau, sel: Selection, extras, n_pts) -> Selection:
    """Each extra effect in turn, kept only where it lowers the BIC by more than EXTRA_BIC_MARGIN (a nonlinear
    one at its best shape, and only at an interior optimum); the base terms it makes redundant (coefficient 0)
    leave the model."""
    linear, nonlin, bic, c2 = sel.linear, sel.nonlin, sel.bic, sel.c2
    for e in extras:
        if e in LINEAR_EFFECTS:
            cand_lin, cand_nl = linear + [e], nonlin
        else:
            r = _best_shape(prob, e, linear, nonlin, tau)
            if r is None or not r.interior:
                continue  # no interior optimum of the shape parameter: the term is not identified
            cand_lin, cand_nl = linear, nonlin + [(e, r.shape)]
        theta, c2n = prob.solve(_columns(cand_lin, cand_nl, tau, prob.white))
        if theta[len(cand_lin) - 1 if e in LINEAR_EFFECTS else -1] <= 0:
            continue
        kk = int(np.count_nonzero(theta > 0)) + len(cand_nl)
        bic_n = c2n + kk * math.log(n_pts)
        if bic_n < bic - EXTRA_BIC_MARGIN:
            keep = theta[: len(cand_lin)] > 0
            linear = [x for x, kp in zip(cand_lin, keep) if kp]
            nonlin = cand_nl
            bic, c2 = bic_n, c2n
    return Selection(linear, nonlin, c2, bic)


def _forward_base(prob, tau, sel: Selection, base, n_pts) -> Selection:
    """Bring back, one at a time, the base effect whose return lowers the BIC most (chi^2 falls by more than
    ln n_points): an extra term may have taken the place of a base one the data still need beside it (a ramp
    that displaced the random walk standing in for it, and white noise with it)."""
    linear, c2 = sel.linear, sel.c2
    while True:
        best = None
        for e in base:
            if e in linear:
                continue
            lin2 = [x for x in LINEAR_EFFECTS if x in linear or x == e]
            th2, c2a = prob.solve(_columns(lin2, sel.nonlin, tau, prob.white))
            if th2[lin2.index(e)] <= 0:
                continue
            gain = (c2 - c2a) - math.log(n_pts)
            if gain > 0 and (best is None or gain > best.gain):
                best = _Move(gain, [x for x, t in zip(lin2, th2[:len(lin2)]) if t > 0], sel.nonlin, c2a)
        if best is None:
            break
        linear, c2 = best.linear, best.c2
    return replace(sel, linear=linear, c2=c2)


def _backward(prob, tau, sel: Selection, n_pts) -> Selection:
    """Drop, one at a time, the term whose removal gains most: chi^2 rises by less than its penalty (k ln
    n_points, k = 1 for a linear term and 2 for a nonlinear one, + EXTRA_BIC_MARGIN for an extra term). A term
    added early may have stood in for one added later (a quantization or bias-instability term for a
    Gauss-Markov bump)."""
    linear, nonlin, c2 = sel.linear, sel.nonlin, sel.c2
    while len(linear) + len(nonlin) > 1:
        best = None
        for i in range(len(linear) + len(nonlin)):
            lin2 = [e for j, e in enumerate(linear) if j != i]
            nl2 = [x for j, x in enumerate(nonlin) if j + len(linear) != i]
            name = linear[i] if i < len(linear) else nonlin[i - len(linear)][0]
            _, c2d = prob.solve(_columns(lin2, nl2, tau, prob.white))
            k_params = (1 if name in LINEAR_EFFECTS else 2)
            margin = 0.0 if name in BASE_EFFECTS else EXTRA_BIC_MARGIN
            gain = (c2 - c2d) + k_params * math.log(n_pts) + margin
            if gain > 0 and (best is None or gain > best.gain):
                best = _Move(gain, lin2, nl2, c2d)
        if best is None:
            break
        linear, nonlin, c2 = best.linear, best.nonlin, best.c2
    return replace(sel, linear=linear, nonlin=nonlin, c2=c2)


def _select(prob, tau, effects, n_pts, auto) -> Selection:
    """Model selection for fixed C (module docstring); ``auto`` False fits every candidate of ``effects``."""
    lin_cand = [e for e in effects if e in LINEAR_EFFECTS]
    nl_cand = [e for e in effects if e in NONLINEAR_EFFECTS]
    if not auto:
        return _fit_given(prob, tau, lin_cand, nl_cand)
    base = [e for e in lin_cand if e in BASE_EFFECTS]
    extra_lin = [e for e in lin_cand if e not in BASE_EFFECTS]
    sel = _best_base_subset(prob, tau, base, n_pts)
    sel = _add_extras(prob, tau, sel, extra_lin + nl_cand, n_pts)
    sel = _forward_base(prob, tau, sel, base, n_pts)
    return _backward(prob, tau, sel, n_pts)
