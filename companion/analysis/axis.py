"""Allan analysis of one axis: pooled overlapping AVAR over the still segments, the weighted fit of the
IEEE 952 terms with a low-pass filter modelled in the white-noise term, intervals, bounds and the LSB
contribution."""

from __future__ import annotations


import numpy as np

from companion.allan.adev import cluster_sizes
from companion.allan.confidence import adev_ci, edf_model, edf_simple
from companion.allan.lsb import lsb_report
from companion.allan.pooled import pooled_cluster_sizes, pooled_edf, pooled_oavar
from companion.allan.terms import LINEAR_PARAM
from companion.analysis.limits import FIT_MIN_RATE_HZ, fast_enough
from companion.analysis.taus import parse_taus


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
    pieces = [np.asarray(y, dtype=float)] if segments is None else [np.asarray(p, dtype=float) for p in segments]
    out = {"tau": [], "adev": [], "adev_lo": [], "adev_hi": [], "terms": [], "status": "ok",
           "fit": None, "quantization": None}
    if pieces and all(p.shape[0] and np.all(np.isnan(p)) for p in pieces):
        out["status"] = "absent"
        out["note"] = "this source does not carry this sensor"
        return out
    pieces = [p[np.isfinite(p)] for p in pieces]
    pieces = [p for p in pieces if p.shape[0] >= 8]
    n = int(sum(p.shape[0] for p in pieces))
    if n < 8:
        out["status"] = "too_short"
        out["note"] = f"only {n} samples"
        return out
    allv = np.concatenate(pieces)
    if np.all(allv == allv[0]):
        out["status"] = "constant"
        out["note"] = ("all samples equal (" + ("all zero" if allv[0] == 0 else f"{allv[0]:g}") + "): no noise to "
                       "analyse; a sensor at rest reads noise, so this one is frozen, dead or below its resolution")
        return out
    from companion.allan.fit import fit_avar  # scipy.optimize/stats: only where a fit runs (start-up time)

    lengths = [int(p.shape[0]) for p in pieces]
    pooled = len(pieces) > 1
    m_fit = pooled_cluster_sizes(lengths, "octave")
    tau_f, avar_f, m_fit, counts = pooled_oavar(pieces, rate_hz, m=m_fit)
    cut = float(tau_min or 0.0)
    why = "by hand"
    keep = tau_f >= cut * (1 - 1e-9)
    short_note = None
    if keep.sum() < 3:  # too short a record to leave the roll-off out: fit everything, and say so
        if cut > 0 and tau_f.shape[0]:
            short_note = (f"the record is too short to leave the low-pass roll-off (below {cut:.3g} s) out of the "
                          "fit: N may read low")
        keep = np.ones_like(keep)
    edf0 = np.array([edf_simple(int(c) + 2 * int(mm), mm, 0) for c, mm in zip(counts[keep], m_fit[keep])])
    fit = fit_avar(tau_f[keep], avar_f[keep], edf0, effects=effects, n=n, rate_hz=rate_hz, m=m_fit[keep],
                   level=level, segments=lengths if pooled else None, white_filter=white_filter,
                   detect_filter=sampling if fast_enough(rate_hz, FIT_MIN_RATE_HZ) and keep.sum() >= 5 else None)
    from companion.allan.fit import upper_bounds
    from companion.estimators.report import bounds_for_fit

    # effects the fit left out (N, B, K): their 95 % upper bound by test inversion, the points' covariance
    # evaluated at the bound (:func:`companion.allan.fit.upper_bounds`); the online report's cheaper rule
    # (covariance at the fitted model, where the left-out term is 0) fell below the truth of a rate random walk
    # left out of 2-h records in 9 of 17 draws against 1 of 17 (benchmarks/bench_fit.py draws)
    bounds = upper_bounds(fit, tau_f[keep], avar_f[keep], n=n, rate_hz=rate_hz, m=m_fit[keep],
                          segments=lengths if pooled else None)
    # the report's rule only where the inversion gave none (it is not computed for the others)
    have = {b["effect"] for b in bounds} | {t["effect"] for t in fit.terms}
    rest = tuple(e for e in ("white_noise", "bias_instability", "random_walk") if e not in have)
    if rest:
        bounds += bounds_for_fit(fit, tau_f[keep], avar_f[keep], np.maximum(edf0, 0.5), rate_hz, n, effects=rest)
    m = parse_taus(taus, max(lengths), rate_hz) if isinstance(taus, str) else cluster_sizes(max(lengths), taus)
    tau, avar, m, _ = pooled_oavar(pieces, rate_hz, m=m)
    plain = [{k: v for k, v in t.items() if k != "ci95"} for t in fit.terms]
    simple = np.array([edf_simple(max(lengths) + 1, mm, 0) for mm in m])
    if plain:
        edf = pooled_edf(plain, m, lengths, rate_hz) if pooled else edf_model(plain, m, n, rate_hz)
    else:
        edf = simple
    edf = np.where(np.isfinite(edf) & (edf > 0), edf, simple)
    adev = np.sqrt(avar)
    lo, hi = adev_ci(adev, edf, level)
    notes = list(fit.notes)
    terms = fit.terms
    from companion.allan.terms import white_filter_of
    from companion.allan.white import apply_white_rules

    # the rules on N shared with the online report: local refit under misfit, resolved or a filter-aware bound
    refit: dict = {}
    terms, more = apply_white_rules(terms, tau_f[keep], avar_f[keep], edf0, 1.0 / rate_hz, fit.model_error,
                                    white_filter_of(fit.filter), record=refit)
    notes += more
    if any(t.get("bound") for t in terms):
        bounds = [x for x in bounds if x["effect"] != "white_noise"] + [t for t in terms if t.get("bound")]
        terms = [t for t in terms if not t.get("bound")]
    # a selected term whose interval (the selection envelope included) reaches 0 is not told from the others:
    # its bound (the interval's upper end), as the online report gives it; the model keeps it (drawn)
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
    terms = [t for t in terms if t not in unsure]
    out.update(tau=tau.tolist(), adev=adev.tolist(), adev_lo=lo.tolist(), adev_hi=hi.tolist(),
               terms=terms, bounds=bounds, edf=edf.tolist(),
               # terms the record is too short to resolve but the fit kept in its model (reported as bounds):
               # the plot draws them, so that the sum it shows is the model N was fitted with
               unresolved=[{k: v for k, v in t.items() if k != "ci95"} for t in list(fit.nuisance) + unsure],
               fit={"chi2": fit.chi2, "dof": fit.dof, "criterion": fit.criterion, "score": fit.score,
                    "model_error": fit.model_error, "tau_min": float(tau_f[keep][0]) if keep.any() else None,
                    "filter": fit.filter,
                    # the local white-noise refit's region and N before/after (None: N from the global fit)
                    "white_refit": refit or None,
                    "points": int(keep.sum()), "notes": notes, "segments": len(pieces)})
    if short_note:
        out["fit"]["notes"].append(short_note)
    if cut > 0 and (~keep).any():
        out["fit"]["notes"].append(f"cluster times below {tau_f[keep][0]:.3g} s left out of the fit ({why})")
    if fit.filter and fit.filter.get("source") == "log":
        out["fit"]["notes"].append(f"low-pass {fit.filter['filter_hz']:.3g} Hz (the log's, 2-pole, "
                                   f"{'point-sampled' if fit.filter.get('sample_hz') else 'averaged'}) modelled "
                                   "in the white-noise term, no cluster time left out")
    N = next((t["N"] for t in terms if t["effect"] == "white_noise"), None)
    out["quantization"] = lsb_report(pieces[int(np.argmax(lengths))], rate_hz, lsb, N)
    return out
