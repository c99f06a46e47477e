"""The per-log analysis task: one log file in, a plain dict of database rows out. Never raises.

This is what a Dask worker runs (it must stay importable and picklable: plain arguments, plain dict
result). The numbers are those of ``companion analyze``: the log is read by
:func:`companion.sources.load` (so every format it reads flows in), each IMU stream is analysed by
:func:`companion.analysis.stream.analyze_stream` over the still segments that
:func:`companion.sources.still.select_still` picks (armed state and motion, as ``companion analyze``
does), pooled, with the same filter handling, fit and intervals. Only the gyro axes by default.

Result (see :func:`analyze_log`)::

    {"path", "format", "status": "ok" | "failed", "error": one line or None, "elapsed_s",
     "log": {"sysid", "vehicle", "board_id", "imu_ids", "start_time", "duration_s", "streams"},
     "rows": [{"vehicle", "sysid", "compid", "imu", "message", "axis", "status", "note", "rate_hz",
               "samples", "still_s", "temp_min", "temp_max", "Q", "Q_lo", "Q_hi", "N", ..., "R_hi",
               "model_error", "chi2", "dof", "extra", "condition"}, ...]}

Besides the still rows (``condition`` "still"), each IMU's ground and flight figures from the vehicle's
redundant IMUs (:mod:`companion.fleet.condition_rows`): a flight log without still data is analysed, not
failed, when it has either.

A failure (unreadable file, no IMU data, a bug) gives ``status="failed"`` and a one-line ``error``.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

from companion.samples import GYRO_AXES

#: linear IEEE 952 terms stored as columns (value, 95 % interval); other terms go to ``extra`` (JSON)
COLUMN_PARAMS = {"quantization": "Q", "white_noise": "N", "bias_instability": "B", "random_walk": "K", "ramp": "R"}


def one_line(exc: BaseException) -> str:
    """A one-line reason: the user-error text as is, anything else prefixed with its type."""
    from companion.errors import CompanionError

    text = str(exc).strip().replace("\n", " ")
    if isinstance(exc, CompanionError):
        return text or "error"
    if isinstance(exc, MemoryError):
        return "out of memory"
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def vehicle_name(sysid: int, board_id: str | None, path: str, vehicle_from: str = "auto") -> str:
    """Vehicle id text: the folder name (``vehicle_from="dir"``), else the board id, else ``sys<sysid>``."""
    if vehicle_from == "dir":
        return os.path.basename(os.path.dirname(os.path.abspath(path))) or f"sys{sysid}"
    if board_id:
        return board_id
    return f"sys{sysid}"


def _row(entry: dict, stream, axis: str, vehicle: str, ranges) -> dict:
    r = entry["axes"][axis]
    temp = None
    if stream.temperature is not None and ranges:
        temp = np.concatenate([stream.temperature[a:b] for a, b in ranges])
        temp = temp[np.isfinite(temp)]
    row = {"vehicle": vehicle, "sysid": int(entry["sysid"]), "compid": int(entry["compid"]),
           "imu": int(entry["instance"]), "message": entry["message"], "axis": axis,
           "status": r["status"], "note": r.get("note"),
           "rate_hz": float(entry["rate_hz"]) if math.isfinite(entry["rate_hz"]) else None,
           "samples": int(entry["samples"]), "still_s": float(entry["duration_s"]),
           "temp_min": float(temp.min()) if temp is not None and temp.size else None,
           "temp_max": float(temp.max()) if temp is not None and temp.size else None,
           "model_error": None, "chi2": None, "dof": None, "extra": None, "condition": "still"}
    for p in COLUMN_PARAMS.values():
        row[p] = row[p + "_lo"] = row[p + "_hi"] = None
    extra = []
    for t in r.get("terms", []):
        p = COLUMN_PARAMS.get(t["effect"])
        if p:
            lo, hi = t.get("ci95", {}).get(p, (None, None))
            row[p], row[p + "_lo"], row[p + "_hi"] = float(t[p]), lo, hi
        else:
            extra.append(t)
    fit = r.get("fit") or {}
    row["model_error"] = fit.get("model_error")
    row["chi2"] = fit.get("chi2")
    row["dof"] = fit.get("dof")
    if extra:
        row["extra"] = {"terms": extra}
    return row


#: result statuses of an axis found dead, stuck or saturated (companion.health.log_faults): flagged in the ranking
FAULT_STATUSES = ("dead", "stuck", "saturated")


def fault_rows(stream, axes, vehicle: str, frozen=()) -> dict:
    """{axis: row} for the gyro axes of ``stream`` (among ``axes``) that are dead, stuck or saturated: status
    the fault's kind, note its sentence, no coefficients. ``frozen``: the log's spans of gyros frozen while the
    vehicle moved (analysis/frozen_spans.py), each a stuck (or dead) axis of its stream."""
    from companion.health.log_faults import AxisFault, gyro_faults

    if stream.gyro is None or stream.samples < 1:
        return {}
    out = {}
    found = gyro_faults(stream.gyro, float(stream.rate_hz), stream.t, getattr(stream, "gyro_lsb", None),
                        stream.key.label())
    named = {f.axis for f in found}
    found += [AxisFault(GYRO_AXES.index(sp.axis), sp.kind, sp.text()) for sp in frozen
              if sp.label == stream.key.label() and GYRO_AXES.index(sp.axis) not in named]
    for f in found:
        axis = GYRO_AXES[f.axis]
        if axis not in axes:
            continue
        row = {"vehicle": vehicle, "sysid": int(stream.key.sysid), "compid": int(stream.key.compid),
               "imu": int(stream.key.instance), "message": stream.key.message, "axis": axis, "status": f.kind,
               "note": f.text[:300], "rate_hz": float(stream.rate_hz) if math.isfinite(stream.rate_hz) else None,
               "samples": int(stream.samples), "still_s": 0.0, "temp_min": None, "temp_max": None,
               "model_error": None, "chi2": None, "dof": None, "extra": None}
        for p in COLUMN_PARAMS.values():
            row[p] = row[p + "_lo"] = row[p + "_hi"] = None
        out[axis] = row
    return out


def _condition_figure(row: dict) -> bool:
    """A ground or flight row that carries a figure: a fitted N, or a white-noise bound (a pair's IMUs, a
    stretch too short to fit: what ``companion analyze`` reports for it too)."""
    bounds = (row.get("extra") or {}).get("bounds") or []
    return row["status"] == "ok" or any(b.get("effect") == "white_noise" for b in bounds)


def analyze_log(path: str, axes=GYRO_AXES, vehicle_from: str = "auto", config=None) -> dict:
    """Analyse one log file (see the module docstring). Never raises (but KeyboardInterrupt)."""
    from companion.fleet.discover import log_format

    t0 = time.perf_counter()
    fmt = log_format(path)
    out = {"path": str(path), "format": fmt, "status": "failed", "error": None, "log": {}, "rows": [],
           "elapsed_s": 0.0}
    try:
        from companion.analysis.stream import analyze_stream, stream_filters
        from companion.fleet.identity import log_identity
        from companion.sources import load
        from companion.sources.still import select_still

        res = load(path, config=config)
        streams = res.imu_streams()
        sel = select_still(streams, getattr(res, "meta", {}) or {})
        from companion.analysis.frozen_spans import frozen_spans, leave_out

        frozen = frozen_spans(streams, axes)
        if frozen:
            res.meta = dict(getattr(res, "meta", {}) or {})
            leave_out(frozen, sel, res.meta)
        ident = log_identity(getattr(res, "meta", None))
        sysids = sorted({s.key.sysid for s in streams})
        sysid = sysids[0] if sysids else 0
        boards = ident.get("board_by_sysid", {})
        board = boards.get(sysid) or ident.get("board_id")
        vehicle = vehicle_name(sysid, board, path, vehicle_from)
        rows, duration, still, lacking, entries = [], 0.0, False, [], {}

        def vehicle_of(s):
            return vehicle if s.key.sysid == sysid else vehicle_name(s.key.sysid, boards.get(s.key.sysid), path,
                                                                      vehicle_from)
        for s in streams:
            v = vehicle_of(s)
            duration = max(duration, float(s.timing.duration_s))
            faulty = fault_rows(s, axes, v, frozen)  # a dead, stuck or saturated axis: a flagged IMU, not a failed log
            rows += faulty.values()
            ranges = sel.ranges(s)
            if not ranges:  # no still data in this stream: nothing to analyse (said in the log's error)
                continue
            still = True
            entry = analyze_stream(s, list(axes), "octave", ranges=ranges,
                                   filters=stream_filters(s, getattr(res, "meta", {}) or {}))
            # an axis the stream does not carry (an accelerometer-only ISB_ACCEL batch asked for gyro axes)
            # is no IMU of the fleet: a row of it would rank the accelerometer as a gyro without data
            absent = [a for a in axes if entry["axes"][a]["status"] == "absent"]
            if len(absent) == len(axes):
                lacking.append(s.key.label())
            rows += [_row(entry, s, a, v, ranges) for a in axes if a not in absent and a not in faulty]
            entries[s.key] = entry
        from companion.fleet.condition_rows import condition_rows  # ground and flight (redundant IMUs)

        cond_rows = condition_rows(streams, getattr(res, "meta", {}) or {}, entries, vehicle_of,
                                   [a for a in axes if a in GYRO_AXES])
        figures = any(_condition_figure(r) for r in cond_rows)
        rows += cond_rows
        out["log"] = {"sysid": sysid, "vehicle": vehicle, "board_id": board,
                      "imu_ids": {int(k): int(v) for k, v in ident.get("imu_ids", {}).items()},
                      "start_time": ident.get("start_time"), "duration_s": duration, "streams": len(streams)}
        out["rows"] = rows
        if any(r["status"] in FAULT_STATUSES for r in rows):  # ranked as a flagged IMU, whatever else it lacks
            out["status"] = "ok"
        elif not rows and still:
            out["error"] = (f"no stream carries the axes {','.join(axes)} (only {', '.join(lacking)})")
        elif not rows or not (still or figures):
            out["error"] = f"no still data ({sel.describe()}) and no ground or flight figure"
        elif not any(r["status"] == "ok" for r in rows) and not figures:
            notes = sorted({f"{r['status']}" + (f" ({r['note']})" if r.get("note") else "") for r in rows})
            out["error"] = "no axis could be analysed: " + "; ".join(notes)[:300]
        else:
            out["status"] = "ok"
    except KeyboardInterrupt:
        raise
    except Exception as exc:  # noqa: BLE001 - a failing log is recorded, never aborts the run
        out["error"] = _without_path(one_line(exc), path)[:500]
        out["rows"] = []
    out["elapsed_s"] = time.perf_counter() - t0
    return out


def _without_path(reason: str, path) -> str:
    """The reason without the log's own name in front: the readers' errors start with it (right for
    `companion analyze`), but the database keeps the path beside the reason and every message prints
    both, which showed the path twice."""
    for name in (str(path), os.path.abspath(str(path)), os.path.basename(str(path))):
        if name and reason.startswith(name + ": "):
            return reason[len(name) + 2:]
    return reason


def analyze_logs(paths, axes=GYRO_AXES, vehicle_from: str = "auto", config=None) -> list[dict]:
    """:func:`analyze_log` over several logs in one task (``--batch``: fewer, longer tasks for the scheduler).

    ``axes``: one tuple of axes for all, or a list of one tuple per log."""
    each = axes if axes and not isinstance(axes[0], str) else [axes] * len(paths)
    return [analyze_log(p, a, vehicle_from, config) for p, a in zip(paths, each)]
