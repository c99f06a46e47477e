"""Each IMU's own gyro noise in one condition (flight, or armed on the ground) from the vehicle's redundant IMUs
(numpy and scipy only).

Steps of :func:`redundant_noise`: the IMUs on one grid (:func:`companion.redundancy.align.align`), the relative
calibration of every pair (:func:`companion.redundancy.calibration.fit_pair`), the Allan points of every pair's
calibrated difference (:func:`companion.redundancy.hat.pair_points`, the known rounding removed), then

- three IMUs: each one's share by the three-cornered hat per cluster time, fitted into an entry of
  ``companion analyze``'s form (:func:`companion.redundancy.fit_points.axis_entry`), each pair's figure bounding
  both of its IMUs;
- two IMUs: the pair's figure (N_pair^2 = N_a^2 + N_b^2), each IMU bounded by it, and split where the ratio of
  their white-noise levels is known (their still data: same IMUs, other condition), said so;
- one IMU: no figure: in motion, its noise cannot be told from the motion.

Every common-mode motion and vibration cancels in the differences: what is left is each IMU's own noise in
that condition (vibration one IMU feels and the others do not counts as its own).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from companion.redundancy.align import MIN_PIECE, ImuTrack, align
from companion.redundancy.calibration import fit_pair
from companion.redundancy.fit_points import axis_entry, tau_min_for
from companion.redundancy.hat import hat_share, pair_points, quantization_avar
from companion.redundancy.shape import avar_shape, equalize, usable

GYRO = ("gx", "gy", "gz")
#: the fewest seconds of aligned data for any figure
MIN_SECONDS = 30.0
#: with the filters known (equalized), the fit starts at this many samples, or where the cascade's shape
#: reaches SHAPE_MIN (below, the model of the filters carries too much of the point): rotor lines aliased
#: below the logged rate's Nyquist frequency reach two IMUs with different filters or sampling instants with
#: different gains and phases, do not cancel, and bend the points of fewer samples (+10-40 % on 50 Hz telemetry)
EQUALIZED_TAU0 = 8
#: a calibrated difference this small against the signal is no pair of IMUs but two copies of one
COPY_RATIO = 1e-9
SHAPE_MIN = 0.6
ONE_IMU = ("one IMU: in motion its noise cannot be separated from the motion; a second IMU, logging while "
           "disarmed (ArduPilot LOG_DISARMED=1, PX4 SDLOG_MODE=1 or 2) or ground time (armed, motors running, not moving) would give "
           "figures")
OWN_NOISE = ("the IMU's own noise in this condition: motion and vibration common to the IMUs cancel in their "
             "differences")


class _Copies(Exception):
    """Two streams that are copies of one IMU (their calibrated difference is all but zero)."""


@dataclass
class RedundancyResult:
    """``per_imu[i]``: {"axes": {axis: entry}, "seconds", "method", "notes"} of track i; ``pairs``: one dict
    per pair {"imus": [i, j], "calibration", "axes"} (the pair's figure)."""

    per_imu: list
    pairs: list = field(default_factory=list)
    seconds: float = 0.0

    def to_dict(self) -> dict:
        return {"per_imu": self.per_imu, "pairs": self.pairs, "seconds": self.seconds}


def _empty(method: str, seconds: float, notes) -> dict:
    return {"axes": {}, "seconds": float(seconds), "method": method, "notes": list(notes)}


def _pair_curves(pieces, rate, tracks, i, j, equalized):
    """Calibration and (tau, avar, edf) per axis of pair (i, j) (pieces per track), the rounding of both IMUs
    removed and, with ``equalized`` (the filters' cascade), the cascade's shape divided out."""
    fl = (None, None) if equalized else (tracks[i].filter_hz, tracks[j].filter_hz)
    cal, res = fit_pair(pieces[i], pieces[j], rate, fl, equalized=bool(equalized))
    r, b = np.vstack(res), np.vstack(pieces[j])
    if np.all(np.var(r, axis=0) <= COPY_RATIO * np.var(b, axis=0)):
        raise _Copies(f"{tracks[i].label or i} and {tracks[j].label or j}")
    curves = []
    for k in range(3):
        tau, avar, edf, m = pair_points(res, rate, k)
        q = quantization_avar(tracks[i].lsb, tau, rate) + quantization_avar(tracks[j].lsb, tau, rate)
        avar = avar - q
        if equalized:
            avar = avar / avar_shape(equalized, rate, m)
        curves.append((tau, avar, edf))
    return cal, curves


def _equalized(al, tracks):
    """(pieces per track, the cascade's filters or None, tau_min): every track through every IMU's filter when
    all are known and the rates are one, else the aligned pieces and a cut above the filters' roll-off."""
    fc = [tr.filter_hz for tr in tracks]
    pieces = [al.track(i) for i in range(len(tracks))]
    same_rate = max(tr.rate_hz for tr in tracks) <= 1.01 * min(tr.rate_hz for tr in tracks)
    if same_rate and usable(fc, al.rate_hz):
        m = np.arange(1, 257)
        shp = avar_shape(fc, al.rate_hz, m)
        first = int(m[np.argmax(shp >= SHAPE_MIN)]) if np.any(shp >= SHAPE_MIN) else 256
        return equalize(pieces, fc, al.rate_hz), fc, max(EQUALIZED_TAU0, first) / al.rate_hz
    known = [f for f in fc if f]
    return pieces, None, tau_min_for(al.rate_hz, min(known) if known else None)


def _n_of(entry: dict, upper: bool = False) -> float | None:
    for t in entry.get("terms", []):
        if t["effect"] == "white_noise":
            return float(t["ci95"]["N"][1]) if upper else float(t["N"])
    for b in entry.get("bounds", []):
        if b["effect"] == "white_noise":
            return float(b["N"])
    return None


def _pair_entries(al, tracks, pairs, curves, n, tau_min) -> list:
    out = []
    for (i, j), (cal, cv) in zip(pairs, curves):
        axes = {ax: axis_entry(*cv[k], rate_hz=al.rate_hz, n=n, tau_min=tau_min) for k, ax in enumerate(GYRO)}
        out.append({"imus": [i, j], "calibration": cal.to_dict(), "axes": axes})
    return out


def _three(al, tracks, pairs, curves, n, tau_min, pair_out) -> list:
    """Step (three IMUs): each IMU's share per cluster time, fitted; its pairs' figures bound it."""
    idx = {p: q for q, p in enumerate(pairs)}
    per = []
    for i in range(3):
        j, k = [x for x in range(3) if x != i]
        axes = {}
        for a, ax in enumerate(GYRO):
            t_ij, a_ij, e_ij = curves[idx[tuple(sorted((i, j)))]][1][a]
            _, a_ik, e_ik = curves[idx[tuple(sorted((i, k)))]][1][a]
            _, a_jk, e_jk = curves[idx[tuple(sorted((j, k)))]][1][a]
            s, e, sd = hat_share(a_ij, a_ik, a_jk, np.minimum(np.minimum(e_ij, e_ik), e_jk))
            ceil = [_n_of(pair_out[idx[tuple(sorted((i, x)))]]["axes"][ax], upper=True) for x in (j, k)]
            ceil = [c for c in ceil if c is not None]
            axes[ax] = axis_entry(t_ij, s, e, rate_hz=al.rate_hz, n=n, tau_min=tau_min,
                                  n_ceiling=min(ceil) if ceil else None, sd=sd)
        per.append({"axes": axes, "seconds": al.seconds, "method": "three-cornered hat of the calibrated pair "
                    "differences", "notes": [OWN_NOISE]})
    return per


def _split(entry: dict, share: float) -> dict:
    """A pair entry's white-noise term scaled to one IMU's share of N^2 (value and interval)."""
    out = {"status": entry.get("status", "ok"), "terms": [], "bounds": [], "fit": entry.get("fit"),
           "quantization": None, "tau": entry.get("tau", []), "adev": [], "adev_lo": [], "adev_hi": [],
           "notes": [f"N split from the pair's figure by the still ratio ({share:.3g} of N^2)"]}
    r = math.sqrt(share)
    for key in ("adev", "adev_lo", "adev_hi"):
        out[key] = [x * r for x in entry.get(key, [])]
    for t in entry.get("terms", []) + entry.get("bounds", []):
        if t["effect"] == "white_noise":
            s = dict(t, N=t["N"] * r, ci95={"N": [v * r for v in t["ci95"]["N"]]})
            (out["bounds"] if t.get("bound") else out["terms"]).append(s)
    return out


def _bounded(entry: dict) -> dict:
    """Each IMU of a pair, without a known ratio: N at most the pair's (upper end of its interval)."""
    top = _n_of(entry, upper=True)
    b = [] if top is None else [{"effect": "white_noise", "N": top, "std": {}, "ci95": {"N": [0.0, top]},
                                 "bound": True, "reason": "at most the pair's figure (the other IMU's share unknown)"}]
    return {"status": entry.get("status", "ok"), "terms": [], "bounds": b, "fit": entry.get("fit"),
            "quantization": None, "tau": [], "adev": [], "adev_lo": [], "adev_hi": [],
            "notes": [] if b else list(entry.get("notes", []))}


def _two(pair_out, still_n, seconds) -> list:
    """Step (two IMUs): each IMU bounded by the pair, or split by the known still ratio per axis."""
    per = []
    for i in range(2):
        axes, split = {}, False
        for ax in GYRO:
            e = pair_out[0]["axes"][ax]
            na = (still_n[0] or {}).get(ax) if still_n else None
            nb = (still_n[1] or {}).get(ax) if still_n else None
            if na and nb:
                own = (na, nb)[i]
                axes[ax] = _split(e, own * own / (na * na + nb * nb))
                split = True
            else:
                axes[ax] = _bounded(e)
        method = ("pair difference, split by the IMUs' still ratio" if split else
                  "pair difference: each IMU at most the pair's figure")
        per.append({"axes": axes, "seconds": seconds, "method": method, "notes": [OWN_NOISE]})
    return per


def redundant_noise(tracks: list[ImuTrack], intervals, *, still_n=None, min_seconds: float = MIN_SECONDS
                    ) -> RedundancyResult:
    """Each IMU's own noise over ``intervals`` ((t0, t1) pairs, s) from the redundant ``tracks`` (module
    docstring). ``still_n``: per track {axis: N (rad/s/sqrt(Hz))} from still data, or None (splits a pair)."""
    if len(tracks) < 2:
        secs = sum(float(np.count_nonzero((tr.t >= a) & (tr.t <= b))) / tr.rate_hz
                   for tr in tracks for a, b in intervals)
        return RedundancyResult([_empty("none", secs, [ONE_IMU]) for _ in tracks], [], secs)
    tracks = tracks[:3]
    al = align(tracks, intervals)
    if al.seconds < min_seconds:
        note = (f"only {al.seconds:.0f} s with every IMU logged, in stretches of {MIN_PIECE} samples or more "
                f"(< {min_seconds:g} s): no figure")
        return RedundancyResult([_empty("none", al.seconds, [note]) for _ in tracks], [], al.seconds)
    pieces, equalized, tau_min = _equalized(al, tracks)
    n = int(round(al.seconds * al.rate_hz))
    pairs = list(combinations(range(len(tracks)), 2))
    try:
        curves = [_pair_curves(pieces, al.rate_hz, tracks, i, j, equalized) for i, j in pairs]
    except _Copies as exc:
        note = f"{exc}: copies of one IMU (their difference is all but zero), no pair of IMUs: no figure"
        return RedundancyResult([_empty("none", al.seconds, [note]) for _ in tracks], [], al.seconds)
    pair_out = _pair_entries(al, tracks, pairs, curves, n, tau_min)
    if len(tracks) == 3:
        per = _three(al, tracks, pairs, curves, n, tau_min, pair_out)
    else:
        per = _two(pair_out, still_n, al.seconds)
    return RedundancyResult(per, pair_out, al.seconds)
