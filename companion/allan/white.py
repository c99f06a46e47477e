"""Where a record carries its white noise, and what it says about N where it does not.

A fitted N is *resolved* only when white noise dominates the fitted model at cluster times above the low-pass
filter's corner (:func:`white_region`): a heavy filter followed by drift (ADEV sqrt(tau) rising from the first
point on) leaves no such region, and N fitted there is a trade between the filter's shape and the drift terms,
with intervals that do not cover. There the honest answer is a bound (:func:`white_bound`): white noise alone
makes AVAR(tau) = N^2 s(tau) / tau (s the filter's shape, :func:`companion.allan.terms.avar_white_noise` with
N = 1, times tau), and every other independent term adds to it, so at every cluster time
N^2 <= AVAR(tau) tau / s(tau); with the estimate's chi-square spread (EDF) the one-sided 95 % upper bound at
each point is AVAR tau / s EDF / chi2_{0.05/k}(EDF), and the least over the k points is the bound (each point's
level Bonferroni-corrected: the least of k bounds at 95 % each falls below N with probability up to k x 5 %).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from companion.allan.special import Z95, chi2_ppf
from companion.allan.terms import avar_term, avar_white_noise, white_filter_of

#: white noise must make at least this share of the fitted AVAR ...
WHITE_SHARE = 0.5
#: ... at cluster times where the filter leaves at least this share of the white level
FILTER_PASS = 0.9
#: ... on at least this many octave points
MIN_POINTS = 2
#: one-sided 95 % normal quantile, rounded: a bound's standard deviation is taken as bound / z
Z95_ONE_SIDED = 1.645
#: correlation of overlapping Allan variance estimates of white noise 0, 1, 2, 3, 4 octaves apart
#: (companion.allan.confidence.oavar_covariance; the same to 0.01 for 600 samples at 10 Hz and 1e5 at 100 Hz)
OCTAVE_CORRELATION = (1.0, 0.53, 0.19, 0.07, 0.02)


def _shape(white_term, tau):
    f = white_filter_of(white_term)
    return avar_white_noise(tau, 1.0, **f) * tau if f else np.ones_like(tau)


def white_region(terms, tau) -> np.ndarray:
    """Boolean mask of the cluster times ``tau`` where the white-noise term of ``terms`` makes at least
    WHITE_SHARE of the model and its filter passes at least FILTER_PASS of the white level."""
    tau = np.asarray(tau, dtype=float)
    plain = [{k: v for k, v in t.items() if k not in ("ci95", "std", "bound")} for t in terms if not t.get("bound")]
    wn = next((t for t in plain if t["effect"] == "white_noise"), None)
    if wn is None:
        return np.zeros(tau.shape, dtype=bool)
    white = avar_term(wn, tau)
    total = sum(avar_term(t, tau) for t in plain)
    return (white >= WHITE_SHARE * np.where(total > 0, total, np.inf)) & (_shape(wn, tau) >= FILTER_PASS)


def white_resolved(terms, tau) -> bool:
    return int(np.count_nonzero(white_region(terms, tau))) >= MIN_POINTS


def white_bound(tau, avar, edf, white_filter=None, level=0.95) -> tuple[float, float]:
    """(one-sided ``level`` upper bound of N, cluster time where it is reached), see the module docstring."""
    tau = np.asarray(tau, dtype=float)
    avar = np.asarray(avar, dtype=float)
    edf = np.maximum(np.asarray(edf, dtype=float), 0.5)
    s = _shape(dict(white_filter or {}), tau)
    r = avar * tau / s  # filter-corrected AVAR x tau: N^2 where white noise alone is there
    ok = np.isfinite(r) & (r > 0)
    if not ok.any():
        return float("nan"), float("nan")
    alpha = (1.0 - level) / int(np.count_nonzero(ok))  # Bonferroni over the points the least is taken from
    q = np.array([chi2_ppf(alpha, float(e)) for e in edf])
    ub = np.where(ok, r * edf / q, np.inf)
    i = int(np.flatnonzero(ok)[np.argmin(ub[ok])])
    return math.sqrt(float(ub[i])), float(tau[i])


#: the white-noise region starts at this many sample periods: clear of a sensor's internal filter, output lines
#: and quantisation at the first few samples
CLEAR_SAMPLES = 10.0
#: a point differs significantly from others when it lies this many of its standard deviations sqrt(2 / EDF)
#: away
SIGNIFICANT_SD = 2.0
#: a leading point is compared with the median of this many following points
CORNER_POINTS = 3
#: a local N within this relative distance of the global one changes nothing
SAME_N = 1e-4
#: relative slack of a cluster-time comparison (tau from m / rate carries rounding)
_TAU_SLACK = 1e-9


class _WhiteModel(NamedTuple):
    """The fitted model around its white-noise term, at the cluster times."""

    wn: dict  # the white-noise term as reported
    white: np.ndarray  # its AVAR
    shape: np.ndarray  # its low-pass filter's shape s = AVAR_white tau / N^2 (1 without a filter)
    total: np.ndarray  # the model's AVAR (terms reported as bounds left out)


def _white_model(wn, terms, tau) -> _WhiteModel:
    plain = [{k: v for k, v in t.items() if k not in ("ci95", "std", "bound")} for t in terms if not t.get("bound")]
    white = avar_term({k: v for k, v in wn.items() if k not in ("ci95", "std", "bound")}, tau)
    total = sum(avar_term(t, tau) for t in plain)
    return _WhiteModel(wn, white, white * tau / wn["N"] ** 2, total)


def _leading_points(r, rel, tau, tau0) -> int:
    """How many leading points to leave to the global fit: points still significantly below the next
    CORNER_POINTS (the data's own corner: a real filter chain rolls off more slowly than the modelled 2-pole
    shape when the model misfits), and, below CLEAR_SAMPLES tau0, points significantly above them (an output
    line at frequency f -- vibration, a sensor's clock -- lifts the octave points near 0.371 / f, and the model
    has no term for a line that close to Nyquist). ``r``: filter-corrected AVAR x tau of the white noise."""
    c = 0
    while c + CORNER_POINTS < r.shape[0]:
        med = float(np.median(r[c + 1:c + 1 + CORNER_POINTS]))
        below = r[c] < med * (1.0 - SIGNIFICANT_SD * rel[c])
        above = r[c] > med * (1.0 + SIGNIFICANT_SD * rel[c]) and tau[c] < CLEAR_SAMPLES * tau0 * (1 - _TAU_SLACK)
        if not (below or above):
            break
        c += 1
    return c


def _before_rise(r, rel, w, first, stop) -> int:
    """The end (exclusive) of the run ``first .. stop`` before a rise of the data that persists: from the first
    point on which this and every later point of the run lie significantly above the EDF-weighted mean of the
    points before it, something the model under misfit does not hold -- an unresolved bias instability, drift,
    temperature -- lifts the curve, and a refit of N through it would read that rise as white noise. A long-tau
    term lifts every longer cluster time; a chance wiggle of a real curve (hours of 100 Hz data make a 1 % one
    significant) does not persist, and leaves the run as it is."""
    for j in range(first + 1, stop + 1):
        mean = float(np.sum(w[first:j] * r[first:j]) / np.sum(w[first:j]))
        if np.all(r[j:stop + 1] > mean * (1.0 + SIGNIFICANT_SD * rel[j:stop + 1])):
            return j
    return stop + 1


def _white_run(wm: _WhiteModel, tau, avar, edf, tau0, share) -> np.ndarray | None:
    """Indices of the white-noise region: the first run of cluster times from CLEAR_SAMPLES tau0 (or, with the
    low-pass filter modelled, from where it passes FILTER_PASS of the white level), past the data's own corner
    (:func:`_leading_points`), on which white noise makes at least ``share`` of the model, cut before a
    persisting rise (:func:`_before_rise`); None with fewer than 2 points."""
    frac = wm.white / np.where(wm.total > 0, wm.total, 1.0)
    start = ((wm.shape >= FILTER_PASS) if wm.wn.get("filter_hz")
             else (tau >= CLEAR_SAMPLES * tau0 * (1 - _TAU_SLACK)))
    r = (np.asarray(avar, dtype=float) - (wm.total - wm.white)) * tau / np.where(wm.shape > 0, wm.shape, 1.0)
    rel = np.sqrt(2.0 / np.maximum(np.asarray(edf, dtype=float), 1.0))
    start &= np.arange(tau.shape[0]) >= _leading_points(r, rel, tau, tau0)
    ok = (frac >= share) & start
    idx = np.flatnonzero(ok)
    if idx.shape[0] < 2:
        return None
    stop = idx[0]
    while stop + 1 < tau.shape[0] and ok[stop + 1]:
        stop += 1
    sel = np.arange(idx[0], _before_rise(r, rel, np.asarray(edf, dtype=float), idx[0], stop))
    return sel if sel.shape[0] >= 2 else None


class _LocalN(NamedTuple):
    """N^2 refitted on the region and its standard deviation."""

    n2: float
    sd_n2: float


def _refit_n2(wm: _WhiteModel, sel, tau, avar, edf) -> _LocalN:
    """Weighted least squares of a - other = N^2 g on the region ``sel`` (module docstring), weights from the
    fitted model: 1 / a^2 would give the points that happen to lie low the most weight and pull N down (5 % low
    on pure white noise with a chance bump). Its standard deviation from the points' variances 2 model^2 / EDF,
    correlated as neighbouring octaves of the overlapping estimator are (OCTAVE_CORRELATION): on a short record
    the region holds a few long cluster times, less precise than the global fit's interval says."""
    a, tt, e = np.asarray(avar)[sel], tau[sel], np.asarray(edf)[sel]
    other = (wm.total - wm.white)[sel]
    mod = np.maximum(wm.total[sel], 1e-300)
    w = e / (2.0 * mod**2)
    g = wm.shape[sel] / tt
    n2 = float(np.sum(w * (a - other) * g) / np.sum(w * g**2))
    k = np.abs(np.subtract.outer(np.arange(sel.shape[0]), np.arange(sel.shape[0])))
    corr = np.asarray(OCTAVE_CORRELATION + (0.0,))[np.minimum(k, len(OCTAVE_CORRELATION))]
    u = g * np.sqrt(e / 2.0) / mod  # w g sd(a), sd(a) = model sqrt(2 / EDF)
    return _LocalN(n2, math.sqrt(float(u @ corr @ u)) / float(np.sum(w * g**2)))


def _with_n(terms, wn, N, ci, ratio) -> list:
    """``terms`` with the white-noise term ``wn`` at ``N`` with the interval ``ci`` (its std scaled by ``ratio``,
    at least the interval's width / 3.92)."""
    new = []
    for t in terms:
        if t is wn:
            t = dict(t)
            t["N"] = N
            t["ci95"] = dict(wn["ci95"], N=ci)
            if "std" in wn:
                t["std"] = dict(wn["std"], N=max(wn["std"]["N"] * ratio, (ci[1] - ci[0]) / 3.92))
        new.append(t)
    return new


def local_white_noise(terms: list, tau, avar, edf, tau0: float, share: float = 0.5, record: dict | None = None):
    """N from a local weighted fit of the white-noise region, for a fit with model misfit (offline: companion
    analyze; online: the estimator's report -- one rule). Terms reported as bounds are not part of the model.

    Under misfit the global fit trades the short-tau points, where the data are most precise, for a bump
    elsewhere. The white-noise region (:func:`_white_run`) is the run of cluster times from 10 tau0 (clear of a
    sensor's internal filter, output lines and quantisation at the first few samples) on which white noise makes
    at least ``share`` of the fitted model. On it N^2 is refitted with the other fitted terms held fixed
    (weighted least squares of a - other = N^2 g, g = s / tau with s the modelled filter's shape (1 without
    one), weights w = EDF / (2 model^2)):

        N^2 = sum w (a - other) g / sum w g^2.

    The weights use the fitted model's AVAR, w = EDF / (2 model^2): the measured points' own would give those
    that happen to lie low the most weight and bias N low. Its interval is the global one scaled by the ratio,
    widened to the refit's own 95 % interval (from the points' variances and correlations) where that is wider.
    Returns (terms, note or None); a refit also fills ``record`` (when given) with the region's cluster times
    ``tau`` [first, last] and N before and after (``N_global``, ``N``, SI), the note's figures as numbers, so that
    a figure can mark the region without reading the note's text.
    """
    wn = next((t for t in terms if t["effect"] == "white_noise"), None)
    if wn is None:
        return terms, None
    tau = np.asarray(tau, dtype=float)
    wm = _white_model(wn, terms, tau)
    sel = _white_run(wm, tau, avar, edf, tau0, share)
    if sel is None:
        return terms, None
    loc = _refit_n2(wm, sel, tau, avar, edf)
    if not loc.n2 > 0:
        return terms, None
    N = math.sqrt(loc.n2)
    ratio = N / wn["N"]
    if abs(ratio - 1) < SAME_N:
        return terms, None
    lo, hi = (c * ratio for c in wn["ci95"]["N"])
    lo = min(lo, math.sqrt(max(loc.n2 - Z95 * loc.sd_n2, 0.0)))
    hi = max(hi, math.sqrt(loc.n2 + Z95 * loc.sd_n2))
    tt = tau[sel]
    if record is not None:
        record.update(tau=[float(tt[0]), float(tt[-1])], N_global=float(wn["N"]), N=N)
    return _with_n(terms, wn, N, [lo, hi], ratio), (
        f"N from a local weighted fit of the white-noise region ({tt[0]:.3g}-{tt[-1]:.3g} s) because "
        f"the model misfits: the global fit gave {100 * (1 / ratio - 1):+.1f} %")


def apply_white_rules(terms: list, tau, avar, edf, tau0: float, model_error: float, white_filter=None,
                      record: dict | None = None):
    """The rules on N shared by the offline analysis and the online report, on report-format terms (resolved
    ones, and bounds with ``"bound": True``): under model misfit N from :func:`local_white_noise`; N resolved
    only where :func:`white_resolved`, else its filter-aware bound (:func:`white_bound`). Returns
    (terms, notes); ``record``, when given, is filled as :func:`local_white_noise` fills it."""
    notes = []
    if model_error:
        terms, note = local_white_noise(terms, tau, avar, edf, tau0, record=record)
        if note:
            notes.append(note)
    wn = next((t for t in terms if t["effect"] == "white_noise" and not t.get("bound")), None)
    # an interval that reaches zero does not resolve N either: the fit could trade all of it into the other
    # terms (90 s at 10 Hz whose AVAR falls like 1 / tau^2 to 2 s reads N 1.43 [0, 2.61] deg/sqrt(h) beside a
    # quantization term)
    lo_zero = wn is not None and not wn.get("ci95", {}).get("N", [1.0])[0] > 0
    if wn is None or (white_resolved(terms, tau) and not lo_zero):
        return terms, notes
    filt = white_filter_of(wn) or dict(white_filter or {})
    ub, at = white_bound(tau, avar, edf, filt)
    if not math.isfinite(ub):
        return terms, notes
    b = {"effect": "white_noise", "N": ub, "std": {"N": ub / Z95_ONE_SIDED}, "ci95": {"N": [0.0, ub]}, "bound": True}
    b.update(filt)
    r = np.asarray(avar, dtype=float) * np.asarray(tau, dtype=float)
    rising = bool(np.all(np.diff(r[: max(3, r.shape[0] // 2)]) > 0))
    why = ("its 95 % interval reaches 0 (the fit does not separate it from the other terms)" if lo_zero
           else "ADEV sqrt(tau) rises from the first cluster time on (a heavy low-pass filter, then drift)" if rising
           else "white noise dominates no octave point above the low-pass corner")
    notes.append(f"N not resolved: {why}; N < {ub:.3g} (SI), the least filter-corrected AVAR x tau, at {at:.3g} s "
                 + (f"(the fitted N, {wn['N']:.3g}, had [0, {wn['ci95']['N'][1]:.3g}])" if lo_zero else
                    f"(a fitted N, {wn['N']:.3g}, would be a trade between the filter and the drift terms)"))
    return [b if t is wn else t for t in terms if not (t["effect"] == "white_noise" and t is not wn)], notes
