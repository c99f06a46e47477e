"""Each IMU stream's gyro noise in the ground and flight conditions of a log (numpy and scipy only).

Steps of :func:`condition_reports`: the redundant IMU streams of each vehicle (:func:`imu_family`), the
conditions from one of them (:func:`companion.analysis.conditions.condition_intervals`), and per condition
each IMU's own noise (:func:`companion.redundancy.redundant_noise`; several IMUs: the calibrated pair
differences, the three-cornered hat). A vehicle with a single IMU gets, on the ground, the Allan analysis of
that IMU over the ground stretches (motor vibration included in the figure, said so), and in flight no figure
with the reason (:data:`companion.redundancy.ONE_IMU`).

Each stream's entry gains ``flight`` and ``ground``: ``{"axes": {axis: entry}, "seconds": s, "method": str,
"notes": [...]}`` with ``axes`` in ``analyze``'s form (``terms``, ``bounds``, each term's ``ci95``).
"""

from __future__ import annotations

import numpy as np

from companion.samples import GYRO_AXES

CONDITIONS = ("ground", "flight")
#: tlog IMU messages are one family (RAW_IMU is IMU 0, SCALED_IMU2/3 IMUs 1 and 2)
_TLOG_IMU = {"RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3", "HIGHRES_IMU"}
#: a family member slower than this fraction of the family's fastest is left out (a 1-Hz copy beside 250 Hz)
MIN_RATE_FRACTION = 0.5
#: the fewest seconds of aligned data for a ground or flight figure. The pair figure's 95 % interval widens as
#: the span shortens and still holds the truth at this length (575 of 600 axes of simulated 10.5-s flights,
#: benchmarks/bench_inflight_short.py; tests/analysis/test_inflight_short.py); many real multi-IMU logs fly
#: little once take-off and landing are cut, and a figure with its wide interval, or a bound, says more than none
MIN_FIGURE_SECONDS = 10.0
ONE_IMU_GROUND = ("one IMU, armed on the ground: its Allan analysis over the ground stretches; the motors' "
                  "vibration is in the figure (a second IMU would cancel it)")


def _family(msg: str) -> str:
    return "MAVLINK_IMU" if msg in _TLOG_IMU else msg


def _has_gyro(s) -> bool:
    if not getattr(s, "is_imu", True):
        return False
    g = s.gyro
    if np.isfinite(g).all():  # the usual case, without a row-wise test and a masked copy
        return g.shape[0] >= 16 and bool(np.any(g != 0))
    ok = np.all(np.isfinite(g), axis=1)
    return int(ok.sum()) >= 16 and bool(np.any(g[ok] != 0))


def imu_family(streams) -> list:
    """The IMU streams of one vehicle used for redundancy: the message family with the most distinct
    instances carrying a gyro (the fastest family among equals), one stream per instance, at least
    MIN_RATE_FRACTION of the fastest member's rate; a single stream (the fastest) when no family has two."""
    cands = [s for s in streams if _has_gyro(s) and np.isfinite(s.rate_hz) and s.rate_hz > 0]
    fams: dict = {}
    for s in cands:
        fams.setdefault(_family(s.key.message), {}).setdefault(s.key.instance, s)
    best = None
    for members in fams.values():
        ms = list(members.values())
        top = max(m.rate_hz for m in ms)
        ms = [m for m in ms if m.rate_hz >= MIN_RATE_FRACTION * top]
        score = (len(ms), top)
        if best is None or score > best[0]:
            best = (score, ms)
    if best is None:
        return []
    return sorted(best[1], key=lambda s: s.key.instance)[:3]


def _monotonic(s):
    """(t, gyro) of a stream whose time only grows: every segment, or the longest when the clock restarts."""
    t = np.asarray(s.t, dtype=float)
    if t.shape[0] > 1 and np.all(np.diff(t) > 0):
        return t, np.asarray(s.gyro, dtype=float)
    a, b = s.longest_segment()
    tt, gg = t[a:b], np.asarray(s.gyro, dtype=float)[a:b]
    keep = np.r_[True, np.diff(tt) > 0]
    return tt[keep], gg[keep]


def _tracks(members, filters_of):
    from companion.redundancy import ImuTrack

    out = []
    for s in members:
        t, g = _monotonic(s)
        fc = (filters_of(s) or {}).get("gyro")
        out.append(ImuTrack(t, g, float(s.rate_hz), float(fc) if fc else None, s.gyro_lsb or None, s.key.label()))
    return out


def _one_imu_ground(s, intervals, filters_of) -> dict:
    """One IMU on the ground: its plain Allan analysis over the ground stretches."""
    from companion.analysis.axis import analyze_axis
    from companion.analysis.stream import stream_sampling

    t, g = _monotonic(s)
    rate = float(s.rate_hz)
    idx = [(int(np.searchsorted(t, a)), int(np.searchsorted(t, b, side="right"))) for a, b in intervals]
    idx = [(a, b) for a, b in idx if b - a >= 16]
    secs = sum(b - a for a, b in idx) / rate
    if not idx:
        return {"axes": {}, "seconds": secs, "method": "none", "notes": ["no ground stretch of 16 samples"]}
    fc = (filters_of(s) or {}).get("gyro")
    samp = stream_sampling(s)
    wf = {"filter_hz": float(fc), "sample_hz": rate if samp == "point" else None} if fc else None
    axes = {ax: analyze_axis(None, rate, "octave", lsb=s.gyro_lsb, segments=[g[a:b, j] for a, b in idx],
                             white_filter=wf, sampling=samp) for j, ax in enumerate(GYRO_AXES)}
    return {"axes": axes, "seconds": secs, "method": "one IMU", "notes": [ONE_IMU_GROUND]}


def _still_n(entries_by_key, members) -> list | None:
    """Per member {axis: N} from its still entry (N resolved on every gyro axis), else None."""
    out = []
    for s in members:
        e = entries_by_key.get(s.key)
        n = {}
        for ax in GYRO_AXES:
            terms = ((e or {}).get("axes", {}).get(ax) or {}).get("terms", [])
            v = next((t["N"] for t in terms if t["effect"] == "white_noise"), None)
            if v:
                n[ax] = float(v)
        out.append(n or None)
    return out if all(out) else None


def _n_value(entry: dict):
    """The white-noise N of an axes entry (a bound counts), or None."""
    for t in list(entry.get("terms", [])) + list(entry.get("bounds", [])):
        if t["effect"] == "white_noise":
            return float(t["N"])
    return None


def _without_frozen(cond: dict, members, frozen: dict) -> tuple[dict, str | None]:
    """The condition intervals less every member's frozen spans (analysis/frozen_spans.py; ``frozen``
    {(sysid, compid, instance): [(t0, t1)]}), and the note saying so: a pair's difference over a frozen gyro is
    its twin's whole motion, which would be split onto the healthy IMU."""
    from companion.timespans import merge_intervals, minus

    # the members' spans may overlap
    cut = merge_intervals(iv for s in members for iv in frozen.get((s.key.sysid, s.key.compid, s.key.instance), []))
    if not cut:
        return cond, None
    out = dict(cond)
    for c in CONDITIONS:
        out[c] = minus(cond[c], cut)
    who = ", ".join(sorted({f"IMU {s.key.instance}" for s in members
                            if frozen.get((s.key.sysid, s.key.compid, s.key.instance))}))
    span = f"{cut[0][0]:.0f}-{cut[-1][1]:.0f} s"
    return out, (f"{who} frozen within {span} (the notes name it): that time left out of every pair's figure, "
                 "whose difference there would be the twin's whole motion")


def condition_reports(streams, meta: dict, filters_of, still_entries=None) -> tuple[dict, list]:
    """({StreamKey: {"ground": ..., "flight": ...}}, notes) for every vehicle of ``streams``; ``filters_of(s)``
    gives a stream's low-pass cut-offs ({"gyro": Hz}); ``still_entries`` {StreamKey: still entry} gives the
    ratio that splits a pair."""
    from companion.analysis.conditions import condition_intervals
    from companion.redundancy import ONE_IMU, redundant_noise

    by_vehicle: dict = {}
    for s in streams:
        by_vehicle.setdefault((s.key.sysid, s.key.compid), []).append(s)
    out, notes = {}, []
    for vstreams in by_vehicle.values():
        members = imu_family(vstreams)
        if not members:
            continue
        t, g = _monotonic(members[0])
        cond = condition_intervals(t, g, (meta or {}).get("armed"), bool((meta or {}).get("has_armed_state")))
        cond, frozen_note = _without_frozen(cond, members, (meta or {}).get("frozen") or {})
        tracks = _tracks(members, filters_of)
        still_n = _still_n(still_entries or {}, members)
        per = {s.key: {} for s in members}
        for c in CONDITIONS:
            iv = cond[c]
            if len(members) == 1 and c == "ground" and iv:
                per[members[0].key][c] = _one_imu_ground(members[0], iv, filters_of)
                continue
            res = redundant_noise(tracks, iv, still_n=still_n, min_seconds=MIN_FIGURE_SECONDS) if iv else None
            for k, s in enumerate(members):
                if res is None:
                    per[s.key][c] = {"axes": {}, "seconds": 0.0, "method": "none",
                                     "notes": [f"no {c} stretch of at least 5 s ({cond['method']})"]}
                else:
                    d = res.per_imu[k]
                    d["intervals_s"] = [[float(a), float(b)] for a, b in iv]
                    d["condition_method"] = cond["method"]
                    if frozen_note:
                        d["notes"] = list(d.get("notes", [])) + [frozen_note]
                    d["pairs"] = [{"imus": [members[i].key.instance for i in pr["imus"]],
                                   "dt_s": pr["calibration"]["dt_s"],
                                   "fitted_matrix": pr["calibration"]["fitted_matrix"],
                                   "N": {ax: _n_value(e) for ax, e in pr["axes"].items()}}
                                  for pr in res.pairs if k in pr["imus"]]
                    per[s.key][c] = d
        out.update(per)
        if len(members) == 1 and cond["flight"]:
            notes.append(f"{members[0].key.label()}: {ONE_IMU}")
    return out, notes
