"""Allan analysis of one axis: pooled overlapping AVAR over the still segments, the weighted fit of the
IEEE 952 terms with a low-pass roll-off kept out, intervals, bounds and the LSB contribution."""

from __future__ import annotations

import math

import numpy as np

from companion.allan.adev import cluster_sizes
from companion.allan.confidence import adev_ci, edf_model, edf_simple
from companion.allan.lsb import lsb_report
from companion.allan.pooled import pooled_cluster_sizes, pooled_edf, pooled_oavar
from companion.analysis.limits import FIT_MIN_RATE_HZ
from companion.analysis.taus import parse_taus


def analyze_axis(y, rate_hz: float, taus="octave", lsb: float | None = None, effects=None, level: float = 0.95,
                 segments=None, tau_min: float = 0.0) -> dict:
    """Allan analysis of one axis (SI rate samples): the JSON ``axes`` entry.

    Keys: ``tau``, ``adev``, ``adev_lo``, ``adev_hi`` (``level`` interval, EDF from the fitted model),
    ``terms`` (fitted, each with ``ci95``), ``status`` ("ok", "constant", "too_short", "absent"), ``fit``
    (chi2, dof, criterion, ``tau_min``), ``quantization`` (LSB contribution, or None when the format has none).
    ``taus``: a --taus string or an array of cluster sizes m. ``segments``: a list of contiguous pieces
    (still segments) analysed with the pooled AVAR (:mod:`companion.allan.pooled`) instead of ``y``.
    ``tau_min``: cluster times below it are left out of the fit (a known low-pass filter's roll-off;
    a roll-off is also detected from the data, :func:`rolloff_tau`).
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
        out["note"] = "all samples equal (" + ("all zero" if allv[0] == 0 else f"{allv[0]:g}") + "): no noise to analyse"
        return out
    from companion.allan.fit import fit_avar  # scipy.optimize/stats: only where a fit runs (issue 14)

    lengths = [int(p.shape[0]) for p in pieces]
    pooled = len(pieces) > 1
    m_fit = pooled_cluster_sizes(lengths, "octave")
    tau_f, avar_f, m_fit, counts = pooled_oavar(pieces, rate_hz, m=m_fit)
    detected = rolloff_tau(tau_f, avar_f) if rate_hz >= FIT_MIN_RATE_HZ else 0.0
    cut = max(float(tau_min or 0.0), detected)
    why = "from the log's filter parameter" if (tau_min or 0.0) >= detected else "detected in the data"
    keep = tau_f >= cut * (1 - 1e-9)
    short_note = None
    if keep.sum() < 3:  # too short a record to leave the roll-off out: fit everything, and say so
        if cut > 0 and tau_f.shape[0]:
            short_note = (f"the record is too short to leave the low-pass roll-off (below {cut:.3g} s) out of the "
                          "fit: N may read low")
        keep = np.ones_like(keep)
    edf0 = np.array([edf_simple(int(c) + 2 * int(mm), mm, 0) for c, mm in zip(counts[keep], m_fit[keep])])
    fit = fit_avar(tau_f[keep], avar_f[keep], edf0, effects=effects, n=n, rate_hz=rate_hz, m=m_fit[keep],
                   level=level, segments=lengths if pooled else None)
    from companion.estimators.report import bounds_for_fit

    # effects the fit left out (N, B, K): their 95 % upper bound, as the online report gives it (issue 13)
    bounds = bounds_for_fit(fit, tau_f[keep], avar_f[keep], np.maximum(edf0, 0.5), rate_hz, n)
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
    if fit.model_error:
        terms, note = local_white_noise(terms, tau_f[keep], avar_f[keep], edf0, 1.0 / rate_hz)
        if note:
            notes.append(note)
    out.update(tau=tau.tolist(), adev=adev.tolist(), adev_lo=lo.tolist(), adev_hi=hi.tolist(),
               terms=terms, bounds=bounds, edf=edf.tolist(),
               fit={"chi2": fit.chi2, "dof": fit.dof, "criterion": fit.criterion, "score": fit.score,
                    "model_error": fit.model_error, "tau_min": float(tau_f[keep][0]) if keep.any() else None,
                    "points": int(keep.sum()), "notes": notes, "segments": len(pieces)})
    if short_note:
        out["fit"]["notes"].append(short_note)
    if cut > 0 and (~keep).any():
        out["fit"]["notes"].append(f"cluster times below {tau_f[keep][0]:.3g} s left out of the fit (low-pass "
                                   f"roll-off, {why})")
    N = next((t["N"] for t in terms if t["effect"] == "white_noise"), None)
    out["quantization"] = lsb_report(pieces[int(np.argmax(lengths))], rate_hz, lsb, N)
    return out


def rolloff_tau(tau, avar, drop: float = 0.95) -> float:
    """Shortest cluster time not bent down by a low-pass filter, detected from the data: AVAR x tau of a
    white-noise region is flat; a filter makes it smaller at the shortest taus. The reference is the median
    of AVAR x tau over the 3rd-6th octave points; leading points below ``drop`` x that are left out.
    Returns 0 when nothing is bent (or too few points to tell)."""
    tau = np.asarray(tau, dtype=float)
    avar = np.asarray(avar, dtype=float)
    if tau.shape[0] < 7:
        return 0.0
    r = avar * tau
    ref = float(np.median(r[3:7]))
    if not (ref > 0):
        return 0.0
    k = 0
    while k < 3 and r[k] < drop * ref:
        k += 1
    return float(tau[k]) if k else 0.0


def filter_tau(cutoff_hz: float | None, rate_hz: float) -> float:
    """Cluster time from which a 2-pole low-pass filter at ``cutoff_hz`` bends AVAR by < 2 %.

    Simulated (white noise at 1 kHz through a 2-pole Butterworth, logged at the stream's rate): AVAR x tau
    is 1 - 0.14 / (f_c tau), so tau >= 7 / f_c. When the log samples slower than 2.5 f_c the decimation
    leaves the samples nearly white (50 Hz logging of a 20 Hz filter: -3 % at 2 samples, -1 % at 3): 3 samples.
    """
    if not cutoff_hz or cutoff_hz <= 0 or not rate_hz or rate_hz <= 0:
        return 0.0
    if rate_hz <= 2.5 * cutoff_hz:
        return 3.0 / rate_hz
    return 7.0 / cutoff_hz


def local_white_noise(terms: list, tau, avar, edf, tau0: float, share: float = 0.5):
    """N from a local weighted fit of the white-noise region, for a fit with model misfit.

    Under misfit the global fit trades the short-tau points, where the data are most precise, for a bump
    elsewhere. The white-noise region is the run of cluster times from 10 tau0 (clear of a sensor's internal
    filter, output lines and quantisation at the first few samples) on which white noise makes at least
    ``share`` of the fitted model. On it N^2 is refitted with the other fitted terms held fixed (weighted
    least squares of a - other = N^2 / tau, weights w = EDF / (2 a^2)):

        N^2 = sum w (a - other) / tau / sum w / tau^2.

    Its interval is the global one scaled by the ratio. Returns (terms, note or None).
    """
    from companion.allan.terms import avar_term

    wn = next((t for t in terms if t["effect"] == "white_noise"), None)
    if wn is None:
        return terms, None
    plain = [{k: v for k, v in t.items() if k != "ci95"} for t in terms]
    tau = np.asarray(tau, dtype=float)
    white = avar_term({"effect": "white_noise", "N": wn["N"]}, tau)
    total = sum(avar_term(t, tau) for t in plain)
    frac = white / np.where(total > 0, total, 1.0)
    ok = (frac >= share) & (tau >= 10.0 * tau0 * (1 - 1e-9))
    idx = np.flatnonzero(ok)
    if idx.shape[0] < 2:
        return terms, None
    stop = idx[0]
    while stop + 1 < tau.shape[0] and ok[stop + 1]:
        stop += 1
    sel = np.arange(idx[0], stop + 1)
    if sel.shape[0] < 2:
        return terms, None
    a, tt, e = np.asarray(avar)[sel], tau[sel], np.asarray(edf)[sel]
    other = (total - white)[sel]
    w = e / (2.0 * a**2)
    n2 = float(np.sum(w * (a - other) / tt) / np.sum(w / tt**2))
    if not n2 > 0:
        return terms, None
    N = math.sqrt(n2)
    ratio = N / wn["N"]
    if abs(ratio - 1) < 1e-4:
        return terms, None
    new = []
    for t in terms:
        if t is wn:
            t = dict(t)
            t["N"] = N
            t["ci95"] = {"N": [c * ratio for c in wn["ci95"]["N"]]}
        new.append(t)
    return new, (f"N from a local weighted fit of the white-noise region ({tt[0]:.3g}-{tt[-1]:.3g} s) because "
                 f"the model misfits: the global fit gave {100 * (1 / ratio - 1):+.1f} %")
