"""Allan analysis of one axis: pooled overlapping AVAR over the still segments, the weighted fit of the
IEEE 952 terms with a low-pass filter modelled in the white-noise term, intervals, bounds and the LSB
contribution.

Steps of :func:`analyze_axis`: the usable pieces (:func:`_usable_pieces`), the octave points the fit sees
(:func:`_fit_points`), the fit (:func:`_fit`), the upper bounds of the terms it left out (:func:`_bounds`), the
Allan curve at the requested cluster times with EDF from the fitted model (:func:`_curve`), the rules on N
shared with the online report (:func:`_white_rules`), N from the curve's flat white region where the fit
misses it (:func:`companion.analysis.flat_white.flat_white_level`), selected terms not told from 0 as bounds
(:func:`_unsure_as_bounds`), and the entry (:func:`_entry`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from companion.allan.adev import cluster_sizes
from companion.allan.confidence import adev_ci, edf_model, edf_simple, forget_rows
from companion.allan.lsb import lsb_report
from companion.allan.pooled import pooled_cluster_sizes, pooled_edf, pooled_oavar
from companion.allan.terms import LINEAR_PARAM
from companion.analysis.flat_white import flat_white_level
from companion.analysis.sufficiency import FIT_MIN_RATE_HZ, fast_enough
from companion.analysis.taus import parse_taus

#: a piece shorter than this many samples has no octave point of its own
MIN_PIECE = 8
#: the fewest octave points a fit with cluster times left out needs (else everything is fitted)
MIN_FIT_POINTS = 3
#: the fewest octave points on which the fit looks for a roll-off in the data (its cut-off is a parameter)
MIN_ROLLOFF_POINTS = 5
#: relative slack of the tau_min comparison (tau from m / rate carries rounding)
_TAU_SLACK = 1e-9
#: the terms a left-out effect gets an upper bound for
BOUNDED_EFFECTS = ("white_noise", "bias_instability", "random_walk")


@dataclass
class _FitPoints:
    """The pooled octave points and which of them the fit sees."""

    pieces: list  # the still pieces (finite samples)
    lengths: list  # their lengths (samples)
    n: int  # samples in all
    tau: np.ndarray
    avar: np.ndarray
    m: np.ndarray
    counts: np.ndarray
    keep: np.ndarray  # the points the fit sees (tau >= tau_min, or all on a short record)
    cut: float  # tau_min
    notes: list = field(default_factory=list)  # what the entry says of the cut

    @property
    def segments(self):
        """The segment lengths for a pooled covariance (None: one piece)."""
        return self.lengths if len(self.pieces) > 1 else None


def _usable_pieces(y, segments, out) -> list | None:
    """Step: the finite pieces of at least MIN_PIECE samples; None when ``out`` got a status instead (absent
    sensor, too short, constant)."""
    pieces = [np.asarray(y, dtype=float)] if segments is None else [np.asarray(p, dtype=float) for p in segments]
    if pieces and all(p.shape[0] and np.all(np.isnan(p)) for p in pieces):
        out["status"] = "absent"
        out["note"] = "this source does not carry this sensor"
        return None
    pieces = [p[np.isfinite(p)] for p in pieces]
    pieces = [p for p in pieces if p.shape[0] >= MIN_PIECE]
    n = int(sum(p.shape[0] for p in pieces))
    if n < MIN_PIECE:
        out["status"] = "too_short"
        out["note"] = f"only {n} samples"
        return None
    first = pieces[0][0]
    if all(np.all(p == first) for p in pieces):
        out["status"] = "constant"
        out["note"] = ("all samples equal (" + ("all zero" if first == 0 else f"{first:g}") + "): no noise to "
                       "analyse; a sensor at rest reads noise, so this one is frozen, dead or below its resolution")
        return None
    return pieces


def _fit_points(pieces, rate_hz, tau_min) -> _FitPoints:
    """Step: the pooled AVAR at octave cluster sizes (:func:`companion.allan.pooled.pooled_oavar`), the points
    below ``tau_min`` left out (by hand) unless fewer than MIN_FIT_POINTS would remain: a record too short to
    leave the roll-off out is fitted whole, and the entry says so."""
    lengths = [int(p.shape[0]) for p in pieces]
    m_fit = pooled_cluster_sizes(lengths, "octave")
    tau_f, avar_f, m_fit, counts = pooled_oavar(pieces, rate_hz, m=m_fit)
    cut = float(tau_min or 0.0)
    keep = tau_f >= cut * (1 - _TAU_SLACK)
    notes = []
    if keep.sum() < MIN_FIT_POINTS:
        if cut > 0 and tau_f.shape[0]:
            notes.append(f"the record is too short to leave the low-pass roll-off (below {cut:.3g} s) out of the "
                         "fit: N may read low")
        keep = np.ones_like(keep)
    return _FitPoints(pieces, lengths, int(sum(lengths)), tau_f, avar_f, m_fit, counts, keep, cut, notes)


def _fit(fp: _FitPoints, rate_hz, effects, level, white_filter, sampling):
    """Step: the weighted fit (:func:`companion.allan.fit.fit_avar`) on the kept points, first weights from the
    simple EDF; a roll-off is looked for in the data where the rate and the points allow. Returns (fit, EDF)."""
    from companion.allan.fit import fit_avar  # scipy.optimize/stats: only where a fit runs (start-up time)

    k = fp.keep
    edf0 = np.array([edf_simple(int(c) + 2 * int(mm), mm, 0) for c, mm in zip(fp.counts[k], fp.m[k])])
    rolloff = fast_enough(rate_hz, FIT_MIN_RATE_HZ) and k.sum() >= MIN_ROLLOFF_POINTS
    fit = fit_avar(fp.tau[k], fp.avar[k], edf0, effects=effects, n=fp.n, rate_hz=rate_hz, m=fp.m[k],
                   level=level, segments=fp.segments, white_filter=white_filter,
                   detect_filter=sampling if rolloff else None)
    return fit, edf0


def _bounds(fit, fp: _FitPoints, rate_hz, edf0) -> list:
    """Step: the 95 % upper bounds of the effects the fit left out (N, B, K), by test inversion with the points'
    covariance evaluated at the bound (:func:`companion.allan.fit.upper_bounds`): the online report's cheaper
    rule (covariance at the fitted model, where the left-out term is 0) bounds a rate random walk left out of
    2-h records below its truth far more often (benchmarks/bench_fit.py draws). The report's rule only where
    the inversion gives none."""
    from companion.allan.fit import upper_bounds
    from companion.estimators.online_report import bounds_for_fit

    k = fp.keep
    bounds = upper_bounds(fit, fp.tau[k], fp.avar[k], n=fp.n, rate_hz=rate_hz, m=fp.m[k], segments=fp.segments)
    have = {b["effect"] for b in bounds} | {t["effect"] for t in fit.terms}
    rest = tuple(e for e in BOUNDED_EFFECTS if e not in have)
    if rest:
        bounds += bounds_for_fit(fit, fp.tau[k], fp.avar[k], np.maximum(edf0, 0.5), rate_hz, fp.n, effects=rest)
    return bounds


def _points_at(fp: _FitPoints, m, rate_hz):
    """(tau, avar, m) of the pooled AVAR at cluster sizes ``m``: the fit's octave points where ``m`` is the same
    set (the default --taus; each point costs passes over the whole record), else computed."""
    m = np.asarray(m, dtype=np.int64)
    if np.array_equal(m[(m >= 1) & (m <= max(fp.lengths) // 2)], fp.m):
        return fp.tau, fp.avar, fp.m
    tau, avar, m, _ = pooled_oavar(fp.pieces, rate_hz, m=m)
    return tau, avar, m


def _curve(fit, fp: _FitPoints, taus, rate_hz, level) -> dict:
    """Step: the Allan deviation at the requested cluster times with its ``level`` interval, the EDF from the
    fitted model (:func:`companion.allan.confidence.edf_model`, pooled where there are pieces) where it is
    finite, else the simple one."""
    longest = max(fp.lengths)
    m = parse_taus(taus, longest, rate_hz) if isinstance(taus, str) else cluster_sizes(longest, taus)
    tau, avar, m = _points_at(fp, m, rate_hz)
    plain = [{k: v for k, v in t.items() if k != "ci95"} for t in fit.terms]
    simple = np.array([edf_simple(longest + 1, mm, 0) for mm in m])
    if plain:
        edf = pooled_edf(plain, m, fp.lengths, rate_hz) if fp.segments else edf_model(plain, m, fp.n, rate_hz)
    else:
        edf = simple
    edf = np.where(np.isfinite(edf) & (edf > 0), edf, simple)
    adev = np.sqrt(avar)
    lo, hi = adev_ci(adev, edf, level)
    return {"tau": tau.tolist(), "adev": adev.tolist(), "adev_lo": lo.tolist(), "adev_hi": hi.tolist(),
            "edf": edf.tolist()}


def _white_rules(fit, fp: _FitPoints, rate_hz, edf0, bounds, notes, refit):
    """Step: the rules on N shared with the online report (:func:`companion.allan.white.apply_white_rules`:
    local refit under misfit, resolved or a filter-aware bound); a bound replaces the white-noise bound of
    ``bounds``. Returns (terms, bounds)."""
    from companion.allan.terms import white_filter_of
    from companion.allan.white import apply_white_rules

    terms, more = apply_white_rules(fit.terms, fp.tau[fp.keep], fp.avar[fp.keep], edf0, 1.0 / rate_hz,
                                    fit.model_error, white_filter_of(fit.filter), record=refit)
    notes += more
    if any(t.get("bound") for t in terms):
        bounds = [x for x in bounds if x["effect"] != "white_noise"] + [t for t in terms if t.get("bound")]
        terms = [t for t in terms if not t.get("bound")]
    return terms, bounds


def _unsure_as_bounds(terms, bounds, notes):
    """Step: a selected term whose interval (the selection envelope included) reaches 0 is not told from the
    others: its bound (the interval's upper end), as the online report gives it; the model keeps it (drawn).
    Returns (terms, bounds, the unsure terms)."""
    unsure = [t for t in terms if t["effect"] in LINEAR_PARAM and t["effect"] != "white_noise"
              and not t.get("ci95", {}).get(LINEAR_PARAM[t["effect"]], [1.0])[0] > 0]
    for t in unsure:
        par = LINEAR_PARAM[t["effect"]]
        top = float(t["ci95"][par][1])
        bounds = [x for x in bounds if x["effect"] != t["effect"]]
        bounds.append({"effect": t["effect"], par: top, "std": dict(t.get("std", {})), "ci95": {par: [0.0, top]},
                       "bound": True, "selected": True})
        notes.append(f"{par} ({t['effect']}) is in the fitted model but its 95 % interval reaches 0: reported as "
                     "its upper bound")
    return [t for t in terms if t not in unsure], bounds, unsure


def _fit_entry(fit, fp: _FitPoints, notes, refit) -> dict:
    """The entry's ``fit``: the fit's figures, the points it saw and every note (the cut, the log's filter)."""
    k = fp.keep
    entry = {"chi2": fit.chi2, "dof": fit.dof, "criterion": fit.criterion, "score": fit.score,
             "model_error": fit.model_error, "tau_min": float(fp.tau[k][0]) if k.any() else None,
             "filter": fit.filter,
             # the region N was taken from instead of the global fit and N before/after (None: N from the
             # global fit); rule "flat": the curve's flat white region, else the local white-noise refit
             "white_refit": refit or None,
             "points": int(k.sum()), "notes": notes, "segments": len(fp.pieces)}
    entry["notes"] += fp.notes
    if fp.cut > 0 and (~k).any():
        entry["notes"].append(f"cluster times below {fp.tau[k][0]:.3g} s left out of the fit (by hand)")
    if fit.filter and fit.filter.get("source") == "log":
        entry["notes"].append(f"low-pass {fit.filter['filter_hz']:.3g} Hz (the log's, 2-pole, "
                              f"{'point-sampled' if fit.filter.get('sample_hz') else 'averaged'}) modelled "
                              "in the white-noise term, no cluster time left out")
    return entry


def analyze_axis(y, rate_hz: float, taus="octave", lsb: float | None = None, effects=None, level: float = 0.95,
                 segments=None, tau_min: float = 0.0, white_filter=None, sampling: str = "point") -> dict:
    """Allan analysis of one axis (SI rate samples): the JSON ``axes`` entry.

    Keys: ``tau``, ``adev``, ``adev_lo``, ``adev_hi`` (``level`` interval, EDF from the fitted model),
    ``terms`` (fitted, each with ``ci95``), ``status`` ("ok", "constant", "too_short", "absent"), ``fit``
    (chi2, dof, criterion, ``tau_min``), ``quantization`` (LSB contribution, or None when the format has none).
    ``taus``: a --taus string or an array of cluster sizes m. ``segments``: a list of contiguous pieces
    (still segments) analysed with the pooled AVAR (:mod:`companion.allan.pooled`) instead of ``y``.
    ``tau_min``: cluster times below it are left out of the fit (by hand; a low-pass filter is modelled, not
    cut). ``white_filter``: {"filter_hz", "sample_hz"} of the log's low-pass filter (the log's parameter), and
    ``sampling`` ("point" or "average") how the samples were taken from the filtered signal: the fit models
    the filter in the white-noise term and also looks for a roll-off in the data
    (:func:`companion.allan.fit.fit_avar`). N is resolved only where white noise dominates an octave above the
    filter's corner (:mod:`companion.allan.white`); otherwise it is reported as a filter-aware bound.
    """
    out = {"tau": [], "adev": [], "adev_lo": [], "adev_hi": [], "terms": [], "status": "ok",
           "fit": None, "quantization": None}
    pieces = _usable_pieces(y, segments, out)
    if pieces is None:
        return out
    fp = _fit_points(pieces, rate_hz, tau_min)
    fit, edf0 = _fit(fp, rate_hz, effects, level, white_filter, sampling)
    bounds = _bounds(fit, fp, rate_hz, edf0)
    curve = _curve(fit, fp, taus, rate_hz, level)
    forget_rows()
    notes = list(fit.notes)
    refit: dict = {}
    terms, bounds = _white_rules(fit, fp, rate_hz, edf0, bounds, notes, refit)
    terms, bounds = flat_white_level(terms, bounds, curve["tau"], np.square(curve["adev"]), curve["edf"], notes, refit,
                                     filter_ci=(fit.filter or {}).get("ci95"))
    terms, bounds, unsure = _unsure_as_bounds(terms, bounds, notes)
    out.update(tau=curve["tau"], adev=curve["adev"], adev_lo=curve["adev_lo"], adev_hi=curve["adev_hi"],
               terms=terms, bounds=bounds, edf=curve["edf"],
               # terms the record is too short to resolve but the fit kept in its model (reported as bounds):
               # the plot draws them, so that the sum it shows is the model N was fitted with
               unresolved=[{k: v for k, v in t.items() if k != "ci95"} for t in list(fit.nuisance) + unsure],
               fit=_fit_entry(fit, fp, notes, refit))
    N = next((t["N"] for t in terms if t["effect"] == "white_noise"), None)
    out["quantization"] = lsb_report(pieces[int(np.argmax(fp.lengths))], rate_hz, lsb, N)
    return out
