"""The ground and flight rows of one log for the fleet database: each IMU's own noise in those conditions
(:func:`companion.analysis.inflight.condition_reports`, what ``companion analyze`` reports as ``ground`` and
``flight``), in the row form of :func:`companion.fleet.task.analyze_log` with ``condition`` set.

A white-noise figure that is only a bound (two IMUs without a known ratio) leaves ``N`` empty and goes to
``extra`` as ``{"bounds": [...]}`` with the method, so that the trend test sees resolved values only.
"""

from __future__ import annotations

import math

from companion.samples import GYRO_AXES

#: the columns of a row that are the fit's terms (value, 95 % interval)
_PARAMS = {"quantization": "Q", "white_noise": "N", "bias_instability": "B", "random_walk": "K", "ramp": "R"}


def _row(stream, vehicle: str, condition: str, d: dict, axis: str) -> dict:
    r = d["axes"][axis]
    rate = float(stream.rate_hz)
    row = {"vehicle": vehicle, "sysid": int(stream.key.sysid), "compid": int(stream.key.compid),
           "imu": int(stream.key.instance), "message": stream.key.message, "axis": axis,
           "status": r.get("status", "ok"), "note": None, "rate_hz": rate if math.isfinite(rate) else None,
           "samples": int(round(d.get("seconds", 0.0) * rate)) if math.isfinite(rate) else 0,
           "still_s": float(d.get("seconds", 0.0)), "temp_min": None, "temp_max": None,
           "model_error": (r.get("fit") or {}).get("model_error"), "chi2": (r.get("fit") or {}).get("chi2"),
           "dof": (r.get("fit") or {}).get("dof"), "extra": None, "condition": condition}
    for p in _PARAMS.values():
        row[p] = row[p + "_lo"] = row[p + "_hi"] = None
    other = []
    for t in r.get("terms", []):
        p = _PARAMS.get(t["effect"])
        if p:
            lo, hi = t.get("ci95", {}).get(p, (None, None))
            row[p], row[p + "_lo"], row[p + "_hi"] = float(t[p]), lo, hi
        else:
            other.append(t)
    bounds = [{k: v for k, v in b.items() if k in ("effect", "N", "B", "K", "reason")} for b in r.get("bounds", [])]
    if other or bounds:
        row["extra"] = {"terms": other, "bounds": bounds, "method": d.get("method")}
    if row["N"] is None and not bounds:
        row["status"] = "no_figure"
        row["note"] = "; ".join(d.get("notes", []))[:300] or None
    return row


def condition_rows(streams, meta: dict, still_entries: dict, vehicle_of, axes=GYRO_AXES) -> list[dict]:
    """Rows of every stream's ground and flight figures; ``still_entries`` {StreamKey: still entry} (splits a
    pair by the still ratio), ``vehicle_of(stream)`` the vehicle name."""
    from companion.analysis.inflight import CONDITIONS, condition_reports
    from companion.analysis.stream import stream_filters

    cond, _ = condition_reports(streams, meta, lambda s: stream_filters(s, meta), still_entries)
    rows = []
    for s in streams:
        for c in CONDITIONS:
            d = cond.get(s.key, {}).get(c)
            if not d or not d.get("axes"):
                continue
            rows += [_row(s, vehicle_of(s), c, d, a) for a in axes if a in d["axes"]]
    return rows
