"""The low-pass roll-off of the white noise: its profile over the cut-off, and which filter the fit models.

A low-pass filter before logging bends the white-noise AVAR at the first cluster times; modelled in the
white-noise column (:func:`companion.allan.terms.avar_white_noise`) N comes from every cluster time, the roll-off
included. The profile chi^2(f_c) of the cut-off (:func:`_profile_filter`, per order of FILTER_ORDERS) decides:
without a log's cut-off a roll-off is claimed only where it lowers chi^2 by more than ln(points) +
EXTRA_BIC_MARGIN; a log's cut-off stands unless it lies outside the data's FILTER_LOG_LEVEL profile interval
(chi^2 scaled by the Birge ratio of the best fit). A first-order shape (below FIRST_ORDER_MAX of the sample rate)
replaces the 2-pole only where it fits better than the best 2-pole by the FILTER_LOG_LEVEL margin, judged under
the covariance of the model fitted with the log's cut-off (or none) and, where it fits better but not by the
rule's margin, again under its own model's selection and covariance (:func:`model_rolloff`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from companion.allan.fit.constants import (CUTOFF_GRID, EXTRA_BIC_MARGIN, FILTER_LOG_LEVEL, FILTER_ORDERS,
                                           FIRST_ORDER_MAX, PROFILE_POINTS, TWO_POLE_MAX)
from companion.allan.fit.fit_state import FitData, FitState, ModelFit, iterate
from companion.allan.fit.gls import _columns, _Problem
from companion.allan.fit.intervals import _profile_union
from companion.allan.special import brentq, chi2_ppf, minimize_scalar_bounded
from companion.allan.terms import white_filter_of

#: the cut-off's bounded refinement and its interval ends stop at this width of log f_c (0.1 %)
_CUTOFF_XTOL = 1e-3
#: an optimum among the last this many grid points of a roll-off is pressed against the range's top: no roll-off
_TOP_POINTS = 3
#: N's interval with the first-order shape in its profile is noted only where it widens the 2-pole's by more
#: than this fraction at either end
_SPAN_NOTE = 0.02
#: the fewest points on which a roll-off is looked for (its cut-off is a parameter of its own)
MIN_POINTS = 5


@dataclass
class RollOffProfile:
    """The profile of the white-noise term's cut-off at one filter order (:func:`_profile_filter_order`)."""

    filter_order: int
    chi2_plain: float  # chi^2 without a filter
    chi2_given: float | None  # chi^2 with the log's cut-off (None: the log has none)
    filter_hz: float | None = None  # the best cut-off (None: the record is too short for the order's range)
    chi2: float = math.inf  # chi^2 at the best cut-off
    interior: bool = False  # the optimum is not at the grid's upper end (there the data look unfiltered)
    ci95: list | None = None  # the cut-off's profile interval
    source: str | None = None  # "data" where the fit models it, "log" where the log's cut-off stands


class RollOffDecision(NamedTuple):
    """What the data say of the roll-off under one model's covariance (:func:`_decide`)."""

    profile: RollOffProfile  # the best 2-pole, or the first-order shape where the data exclude that
    aside: bool  # the data set the log's cut-off (or no filter) aside for the profile's
    better: RollOffProfile | None  # a first-order shape fitting better than the log's cut-off (or no filter)
    over_two: RollOffProfile | None  # a first-order shape fitting better than the best 2-pole


class _OwnModel(NamedTuple):
    """A roll-off judged again under the model fitted with it (:func:`_judge_under_own_model`)."""

    decision: RollOffDecision
    model: ModelFit


def _cutoff_grid(order, tau, tau0) -> np.ndarray:
    """The log cut-offs profiled for a roll-off of ``order``: from FILTER_ORDERS[order] / tau_max to
    TWO_POLE_MAX / tau0 (2-pole) or FIRST_ORDER_MAX / tau0 (first-order); empty where the record is too short
    for that range."""
    lo, hi = FILTER_ORDERS[order] / tau[-1], (TWO_POLE_MAX if order == 2 else FIRST_ORDER_MAX) / tau0
    return np.linspace(math.log(lo), math.log(hi), CUTOFF_GRID[order]) if hi > lo else np.empty(0)


def _profile_filter(prob, linear, nonlin, tau0, sampling, given=None, level=0.95) -> dict:
    """Profile chi^2 of the white-noise term's low-pass cut-off f_c, for each order of FILTER_ORDERS (a dict
    order -> :class:`RollOffProfile`), over a log grid from its lowest cut-off to TWO_POLE_MAX / tau0 (a filter
    above that bends no cluster time; a first-order one to FIRST_ORDER_MAX / tau0), refined by a bounded 1-D
    minimisation; ``ci95`` the cut-off's ``level`` profile interval at that order, chi^2 <= chi^2_min +
    chi2_level(1). ``sampling``: "point" or "average", how the samples were taken from the filtered signal;
    ``given``: the log's filter."""
    sample_hz = 1.0 / tau0 if sampling == "point" else None
    plain = prob.solve(_columns(linear, nonlin, prob.tau, None))[1]
    given_c2 = (prob.solve(_columns(linear, nonlin, prob.tau, white_filter_of(dict(given, sample_hz=sample_hz))))[1]
                if given else None)
    return {order: _profile_filter_order(prob, linear, nonlin, tau0, sample_hz, level,
                                         RollOffProfile(order, plain, given_c2, chi2=plain))
            for order in FILTER_ORDERS}


def _profile_filter_order(prob, linear, nonlin, tau0, sample_hz, level, out: RollOffProfile) -> RollOffProfile:
    """Fill ``out`` (its order, no cut-off yet) with the profile of the cut-off at its order."""
    tau = prob.tau
    extra = {} if out.filter_order == 2 else {"filter_order": out.filter_order}

    def chi(lf):
        w = {"filter_hz": math.exp(lf), "sample_hz": sample_hz, **extra}
        return prob.solve(_columns(linear, nonlin, tau, w))[1]

    out.ci95 = [None, None]
    grid = _cutoff_grid(out.filter_order, tau, tau0)
    if grid.size == 0:
        return out
    vals = np.array([chi(g) for g in grid])
    i = int(np.argmin(vals))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    x, fx = minimize_scalar_bounded(chi, a, b, xatol=_CUTOFF_XTOL)
    best, c2 = (x, fx) if fx < vals[i] else (grid[i], float(vals[i]))
    thr = c2 + chi2_ppf(level, 1)
    inside = np.flatnonzero(vals <= thr)
    if inside.size == 0:
        inside = np.array([i])
    i0, i1 = int(inside.min()), int(inside.max())

    def g(lf):
        return chi(lf) - thr

    lo_ok = i0 > 0 and g(grid[i0 - 1]) > 0 > g(min(grid[i0], best))
    hi_ok = i1 < len(grid) - 1 and g(grid[i1 + 1]) > 0 > g(max(grid[i1], best))
    ci = [math.exp(brentq(g, grid[i0 - 1], min(grid[i0], best), xtol=_CUTOFF_XTOL)) if lo_ok
          else math.exp(grid[max(i0 - 1, 0)]),
          math.exp(brentq(g, max(grid[i1], best), grid[i1 + 1], xtol=_CUTOFF_XTOL)) if hi_ok
          else math.exp(grid[min(i1 + 1, len(grid) - 1)])]
    out.filter_hz, out.chi2, out.interior = math.exp(best), float(c2), bool(best < grid[-_TOP_POINTS])
    out.ci95 = [min(ci[0], math.exp(best)), max(ci[1], math.exp(best))]
    return out


def _decide(d: FitData, model: ModelFit, given, sampling) -> RollOffDecision:
    """The roll-off the data show under ``model``'s covariance (its selection, white noise added where it
    lacks it). The 2-pole Butterworth is the autopilots' filter; a first-order shape only where the data exclude
    the 2-pole's best at the FILTER_LOG_LEVEL level (a short correlated process, a sensor's own roll-off). The
    log's cut-off ``given`` is a prior, not a claim to test: it is set aside when the data put it outside their
    FILTER_LOG_LEVEL profile interval (chi^2 scaled by the Birge ratio where the model misfits) -- a nominal
    cut-off need not be the 2-pole equivalent of the real filter, and N follows the shape it is given. Without
    one a roll-off must lower chi^2 by ln(points) + EXTRA_BIC_MARGIN."""
    lin_f = model.linear if "white_noise" in model.linear else ["white_noise"] + list(model.linear)
    infos = _profile_filter(_Problem(d.tau, d.v, model.cov, None, d.tau0), lin_f, model.nonlin, d.tau0, sampling,
                            given)
    dof_f = max(d.n_pts - len(lin_f) - 2 * len(model.nonlin) - 1, 1)
    info, one = infos[2], infos[1]
    margin = chi2_ppf(FILTER_LOG_LEVEL, 1) * max(1.0, one.chi2 / dof_f)
    if one.interior and one.chi2 < info.chi2 - margin:
        info = one
    if given:
        thr = chi2_ppf(FILTER_LOG_LEVEL, 1) * max(1.0, info.chi2 / dof_f)
        base_c2 = info.chi2_given
    else:
        thr = math.log(d.n_pts) + EXTRA_BIC_MARGIN
        base_c2 = info.chi2_plain
    return RollOffDecision(info, bool(info.interior and info.chi2 < base_c2 - thr),
                           one if one.interior and one.chi2 < base_c2 else None,
                           one if one.interior and one.chi2 < infos[2].chi2 else None)


def _data_filter(profile: RollOffProfile, sampling, rate_hz) -> dict:
    """The white-noise column's filter of a roll-off found in the data."""
    return white_filter_of({"filter_hz": profile.filter_hz, "sample_hz": rate_hz if sampling == "point" else None,
                            "filter_order": profile.filter_order})


def _judge_under_own_model(st: FitState, shape: RollOffProfile, given, sampling) -> _OwnModel:
    """The decision under the model fitted with the data's ``shape`` (its own selection and covariance), and
    that model; ``st.white`` is left at ``shape``."""
    st.white = _data_filter(shape, sampling, st.data.rate_hz)
    model = iterate(st.data, st.white, 0.0)
    return _OwnModel(_decide(st.data, model, given, sampling), model)


def _rolloff_note(profile: RollOffProfile, given) -> str:
    order, fc = profile.filter_order, profile.filter_hz
    given_hz = given["filter_hz"] if given else None
    return (f"low-pass roll-off seen in the data: {order}-pole {fc:.3g} Hz "
            f"[{profile.ci95[0]:.3g}, {profile.ci95[1]:.3g}] modelled in the white-noise term"
            + (f" (the log's {given_hz:.3g} Hz set aside: outside the data's "
               f"{100 * FILTER_LOG_LEVEL:.0f} % interval)" if given_hz else "")
            + (f"; a first-order roll-off is also the shape of a Gauss-Markov process of tau_c "
               f"{1.0 / (2.0 * math.pi * fc):.2g} s (the two look alike): N is the white level above it"
               if order == 1 else ""))


def model_rolloff(st: FitState, detect_filter) -> None:
    """Step: look for a roll-off in the data (``detect_filter``: "point" or "average" sampling) and settle the
    white-noise column's filter ``st.white``, its profile ``st.filter_info`` and, where the filter changed, the
    model ``st.model`` (module docstring).

    Where the data set the log's cut-off (or no filter) aside for a 2-pole of their own and a first-order shape
    fits better than that 2-pole, the 2-pole's model may have kept a drift term for the difference (a bias
    instability the record cannot resolve): the first-order shape replaces the 2-pole only if, judged again under
    its own model, the data there put the 2-pole's best outside the margin too. Where the log's 2-pole (or no
    filter) stands but a first-order shape fits better, the drift terms of that model take up the difference and
    overshoot the long cluster times, whose variance then looks larger than it is, so that model is judged
    leniently there: the first-order shape is judged again under its own model's covariance, by the same rules."""
    d = st.data
    if not (detect_filter and "white_noise" in d.effects and d.tau0 and d.n_pts >= MIN_POINTS):
        return
    sampling = "point" if detect_filter != "average" else "average"
    given = st.white
    dec = _decide(d, st.model, given, sampling)
    profile, aside = dec.profile, dec.aside
    if aside and profile.filter_order == 2 and dec.over_two is not None:
        own = _judge_under_own_model(st, dec.over_two, given, sampling)
        if own.decision.aside and own.decision.profile.filter_order == 1:
            profile, st.model = own.decision.profile, own.model
        else:
            st.white = given
    if not aside and dec.better is not None:
        own = _judge_under_own_model(st, dec.better, given, sampling)
        aside = own.decision.aside
        if aside:
            profile, st.model = own.decision.profile, own.model
        else:
            st.white = given
    if aside:
        new_white = _data_filter(profile, sampling, d.rate_hz)
        if new_white != st.white:
            st.white = new_white
            st.model = iterate(d, st.white, 0.0)
        profile.source = "data"
        st.notes.append(_rolloff_note(profile, given))
    else:
        profile.source = "log" if given else None
    st.filter_info = profile


def _profile_white_ci(ci, prob, prob_ci, linear, nonlin, tau, white, fc_ci, c2, scale, level, tau0=None,
                      notes=None, first_order=None):
    """N's interval ``ci`` (at the fitted cut-off) widened to its profile-likelihood interval over the roll-off's
    shape (:func:`~companion.allan.fit.intervals._profile_union`): f_c on a log grid over its interval ``fc_ci``
    widened by half its log-width each side (the final covariance, with any model error, may allow more than the
    first profile did; None: the log's cut-off, which is not profiled) and, for a 2-pole, the first-order shape
    over its whole range (FILTER_ORDERS, FIRST_ORDER_MAX; sample period ``tau0``): where the record cannot tell
    the two orders apart, N's interval spans both readings (on 20 s of a first-order roll-off the 2-pole + an
    unresolved drift term read N at half the level the 1-pole reads); a note then goes to ``notes`` (a list)
    when given. ``first_order``: whether the first-order shape is in the profile, as decided before (the online
    report takes its selection's, between re-selections); None: decided here. Returns (interval, first_order)."""
    designs = []
    if fc_ci is not None:
        lo_l, hi_l = math.log(fc_ci[0]), math.log(fc_ci[1])
        pad = 0.5 * (hi_l - lo_l)
        designs = [_columns(linear, nonlin, tau, dict(white, filter_hz=float(fc)))
                   for fc in np.exp(np.linspace(lo_l - pad, hi_l + pad, PROFILE_POINTS))]
    grid1 = _cutoff_grid(1, tau, tau0) if tau0 else np.empty(0)
    if int(white.get("filter_order") or 2) == 2 and grid1.size and first_order is not False:
        ones = [_columns(linear, nonlin, tau, dict(white, filter_hz=float(fc), filter_order=1))
                for fc in np.exp(grid1)]
        # only a first-order roll-off the data show (its best cut-off inside the range, as the order's choice
        # asks, the profile's `interior`): one pressed against the range's top is no roll-off below a tenth of
        # the sample rate
        if first_order is None:
            first_order = int(np.argmin([prob.solve(A1)[1] for A1 in ones])) < len(ones) - _TOP_POINTS
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
    if notes is not None and (lo < (1.0 - _SPAN_NOTE) * two[0] or hi > (1.0 + _SPAN_NOTE) * two[1]):
        notes.append(f"N's interval spans a first-order roll-off's reading too: the record does not tell it from the "
                     f"2-pole (within the {100 * FILTER_LOG_LEVEL:.0f} % margin)")
    return out, bool(first_order)


def _filter_summary(white, info: RollOffProfile | None, first_order=False):
    """The result's ``filter``: the white-noise column's filter, where it came from ("log" or "data"), the
    data's interval of the cut-off, and whether N's interval holds the first-order reading."""
    if not white:
        return None
    out = {"filter_hz": float(white["filter_hz"]), "sample_hz": white.get("sample_hz"),
           "source": (info.source if info else None) or "log"}
    if white.get("filter_order"):
        out["filter_order"] = int(white["filter_order"])
    if info and info.source == "data":
        out["ci95"] = list(info.ci95)
    if first_order:
        out["first_order_in_ci"] = True  # the data's first-order reading is in N's profile interval
    return out
