"""An ``axes`` entry in ``companion analyze``'s form (``terms``, ``bounds``, each term's ``ci95``, the Allan
curve with its interval) from Allan points that are no plain record: a pair's calibrated difference or one
IMU's share of the three-cornered hat (numpy and scipy only).

The fit is :func:`companion.allan.fit.fit_avar` with its automatic selection of the IEEE 952 terms on the
points at and above ``tau_min``, with a diagonal covariance 2 AVAR^2 / EDF (inflated for neighbouring points:
the hat's points are sums of three correlated curves, whose joint covariance the single-record model does not
describe), then the record rule (a bias instability or random walk the span cannot resolve is a bound).
N is a value where the fit resolves it (its 95 % interval above 0), else a 95 % upper bound
(:func:`companion.allan.white.white_bound`), never above ``n_ceiling`` when one is given (a pair's figure
bounds each of its IMUs).
"""

from __future__ import annotations

import math

import numpy as np

from companion.allan.confidence import adev_ci

#: cluster times below this many grid periods are left out of the fit: interpolation, the low-pass filters,
#: the derivative terms of the calibration and aliased vibration lines bend the curve there
ROLLOFF_TAU0 = 8.0
#: and below this many periods of the lowest low-pass cut-off (a 2-pole filter lowers AVAR x tau by a few %
#: up to about 3 / f_c)
ROLLOFF_CUTOFF = 5.0
#: fewest points above tau_min for any fit
MIN_POINTS = 3


def tau_min_for(rate_hz: float, filter_hz=None) -> float:
    """The shortest cluster time the fit sees (s)."""
    out = ROLLOFF_TAU0 / rate_hz
    fc = filter_hz if filter_hz else rate_hz / 4.0
    return max(out, ROLLOFF_CUTOFF / fc)


def _curve(tau, avar, edf, level) -> dict:
    ok = np.isfinite(avar) & (avar > 0)
    adev = np.sqrt(avar[ok])
    lo, hi = adev_ci(adev, edf[ok], level)
    return {"tau": tau[ok].tolist(), "adev": adev.tolist(), "adev_lo": lo.tolist(), "adev_hi": hi.tolist(),
            "edf": edf[ok].tolist()}


def _white_bound_term(tau, avar, edf, level, ceiling, why) -> dict | None:
    from companion.allan.white import white_bound

    ub, at = white_bound(tau, np.maximum(avar, 0.0), edf, None, level)
    if ceiling is not None and (not math.isfinite(ub) or ceiling < ub):
        ub, why = float(ceiling), why + "; the pair figure bounds it"
    if not math.isfinite(ub):
        return None
    return {"effect": "white_noise", "N": ub, "std": {}, "ci95": {"N": [0.0, ub]}, "bound": True, "reason": why}


def _neg_bounds(tau, avar, sd) -> list:
    """The cluster times whose estimate is <= 0: an upper bound of the AVAR there (estimate + 1.645 sd)."""
    out = []
    for t, a, s in zip(tau, avar, sd):
        if np.isfinite(a) and a <= 0:
            out.append({"tau": float(t), "adev_upper": math.sqrt(max(a, 0.0) + 1.6448536269514722 * s),
                        "reason": "the three-cornered hat estimate is negative here (the other IMUs' noise or "
                                  "a vibration they do not share dominates): an upper bound only"})
    return out


def axis_entry(tau, avar, edf, *, rate_hz: float, n: int, tau_min: float, level: float = 0.95,
               n_ceiling: float | None = None, notes=(), sd=None) -> dict:
    """The ``axes`` entry of one axis from Allan points (``tau`` s, ``avar`` (rad/s)^2, may be <= 0 for a hat
    share; ``edf`` per point; ``sd`` the standard deviation of each point, for the bounds of negative ones)."""
    from companion.allan.fit import fit_avar
    from companion.allan.fit.record_rule import apply_record_rule

    tau, avar, edf = (np.asarray(x, dtype=float) for x in (tau, avar, edf))
    sd = np.sqrt(2.0 / np.maximum(edf, 0.5)) * np.abs(avar) if sd is None else np.asarray(sd, dtype=float)
    out = {"status": "ok", "terms": [], "bounds": [], "fit": None, "quantization": None,
           "negative": _neg_bounds(tau, avar, sd), "notes": list(notes)}
    out.update(_curve(tau, avar, edf, level))
    keep = (tau >= tau_min * (1 - 1e-9)) & np.isfinite(avar) & (avar > 0) & (edf > 0)
    if keep.sum() < MIN_POINTS:
        out["status"] = "too_short" if tau.size < MIN_POINTS else "bound"
        b = _white_bound_term(tau, avar, edf, level, n_ceiling, "too few positive cluster times to fit")
        out["bounds"] = [b] if b else []
        if not b:  # said, not left as a "bound" without one
            out["status"] = "no_figure"
            out["notes"].append("too few cluster times with a positive Allan variance of the differences for a "
                                "value or a bound")
        return out
    m = np.round(tau[keep] * rate_hz)
    fit = fit_avar(tau[keep], avar[keep], edf[keep], n=None, rate_hz=None, m=m, level=level)
    fit = apply_record_rule(fit, n, rate_hz, None)
    terms = [t for t in fit.terms]
    out["fit"] = {"chi2": fit.chi2, "dof": fit.dof, "model_error": fit.model_error, "tau_min": float(tau[keep][0]),
                  "points": int(keep.sum()), "notes": list(fit.notes)}
    wn = next((t for t in terms if t["effect"] == "white_noise"), None)
    if wn is None or not wn.get("ci95", {}).get("N", [0.0])[0] > 0:
        terms = [t for t in terms if t["effect"] != "white_noise"]
        b = _white_bound_term(tau[keep], avar[keep], edf[keep], level, n_ceiling,
                              "white noise not resolved in the fit")
        out["bounds"].append(b) if b else None
    elif n_ceiling is not None and wn["N"] > n_ceiling:
        # a share above its pair's figure needs a negative share of the other IMU: the pair bounds it
        terms = [t for t in terms if t["effect"] != "white_noise"]
        out["bounds"].append({"effect": "white_noise", "N": float(n_ceiling), "std": {},
                              "ci95": {"N": [0.0, float(n_ceiling)]}, "bound": True,
                              "reason": "the hat's share came out above its pair's figure (vibration the IMUs do "
                                        "not share, or too few samples): the pair's figure bounds it"})
    for t in fit.nuisance:
        p = {"bias_instability": "B", "random_walk": "K"}.get(t["effect"])
        if p and "ci95" in t:
            top = float(t["ci95"][p][1])
            out["bounds"].append({"effect": t["effect"], p: top, "std": {}, "ci95": {p: [0.0, top]}, "bound": True,
                                  "reason": "the span is too short to resolve it"})
    out["terms"] = terms
    return out
