"""What ``companion inspect`` shows of a loaded source (:class:`companion.sources.LoadResult`): one row per
stream (message, instance, system, component, samples, rate, duration, gaps, whether it is an IMU), the
frame totals, what an autopilot log says about its IMU data (filter parameters, identity, armed periods,
modes) and the notes on the data; the same as a JSON document.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from companion.errors import CompanionError

#: the fields of a stream in the JSON document, in order
STREAM_KEYS = ("message", "instance", "sysid", "compid", "samples", "rate_hz", "duration_s", "gaps", "is_imu")
#: the frame totals of the JSON document
TOTAL_KEYS = ("frames", "bad_bytes", "bad_frames")


def summary(res) -> dict:
    """The JSON document: exactly the stream keys and the totals."""
    streams = []
    for s in res.streams:
        rate = s.timing.rate_hz
        streams.append({
            "message": s.key.message, "instance": s.key.instance, "sysid": s.key.sysid,
            "compid": s.key.compid, "samples": s.samples,
            "rate_hz": None if not math.isfinite(rate) else round(rate, 6),
            "duration_s": round(s.timing.duration_s, 6), "gaps": s.timing.gaps, "is_imu": bool(s.is_imu),
        })
    out = {"streams": streams}
    out.update({k: int(res.totals.get(k, 0)) for k in TOTAL_KEYS})
    view = (getattr(res, "meta", None) or {}).get("autopilot")
    if view is not None and (view.fields or view.error):  # the autopilot's own IMU health, where the log has it
        out["autopilot"] = view.to_dict()
    return out


def render(res) -> str:
    doc = summary(res)
    head = ("message", "inst", "sys", "comp", "samples", "rate_hz", "duration_s", "gaps", "is_imu")
    rows = [head]
    for s in doc["streams"]:
        rows.append((s["message"], str(s["instance"]), str(s["sysid"]), str(s["compid"]), str(s["samples"]),
                     "-" if s["rate_hz"] is None else f"{s['rate_hz']:.3f}", f"{s['duration_s']:.1f}",
                     str(s["gaps"]), "yes" if s["is_imu"] else "no"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    lines = [f"source: {res.source}"]
    lines += ["  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
              for r in rows]
    if not doc["streams"]:
        lines.append("(no IMU messages)")
    lines.append(f"frames {doc['frames']}, bad bytes {doc['bad_bytes']}, bad frames {doc['bad_frames']}")
    lines += log_lines(res)
    from companion.analysis.notes import notes
    from companion.health.autopilot_view import view_lines

    lines += view_lines((getattr(res, "meta", None) or {}).get("autopilot"))

    lines += [f"note: {n}" for n in notes(res)]
    return "\n".join(lines)


#: autopilot parameters that shape the logged IMU data (low-pass filters, fast sampling, batch logging)
FILTER_PARAMS = ("INS_GYRO_FILTER", "INS_ACCEL_FILTER", "INS_MPU6K_FILTER", "INS_FAST_SAMPLE", "INS_LOG_BAT_MASK",
                 "INS_LOG_BAT_OPT", "IMU_GYRO_CUTOFF", "IMU_ACCEL_CUTOFF", "IMU_INTEG_RATE")


def log_lines(res) -> list[str]:
    """What an autopilot log says about its IMU data: filter parameters, armed periods, modes (one line each);
    for a tlog only its armed state."""
    meta = getattr(res, "meta", None) or {}
    fmt = meta.get("format")
    if "armed_source" in meta:  # a tlog: only the armed state from its HEARTBEATs
        return [tlog_armed_line(res)]
    if fmt not in ("dataflash", "ulog"):
        return []
    out = []
    params = meta.get("params") or {}
    p = [f"{k} {params[k]:g}" for k in FILTER_PARAMS if k in params]
    out.append(f"log: {'ArduPilot DataFlash' if fmt == 'dataflash' else 'PX4 ULog'}, {len(params)} parameters"
               + (f" ({', '.join(p)})" if p else ""))
    ident = meta.get("identity") or {}
    who = [x for x in (ident.get("board"), ident.get("board_id")) if x]
    if ident.get("imu_ids"):
        who.append("gyro ids " + ", ".join(f"IMU{k} {v}" for k, v in sorted(ident["imu_ids"].items())))
    if ident.get("start_time"):
        import time

        who.append("started " + time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(ident["start_time"])))
    if who:
        out.append("log: board " + ", ".join(who) if ident.get("board_id") else "log: " + ", ".join(who))
    if meta.get("has_armed_state"):
        out.append("log: armed state: " + armed_text(meta.get("armed") or [], _imu_end(res)))
    if meta.get("modes"):
        k = len(meta["modes"])
        out.append(f"log: {k} mode {'entry' if k == 1 else 'entries'} ({', '.join(f'{t:.1f} s' for t, _ in meta['modes'][:5])}"
                   + (", ..." if k > 5 else "") + ")")
    return out


def _imu_end(res) -> float | None:
    """The time of the last IMU sample (where the still selection ends a log that is still armed)."""
    ends = [float(s.t[-1]) for s in res.imu_streams() if s.samples]
    return max(ends) if ends else None


def armed_text(transitions, t_end: float | None, shown: int = 5) -> str:
    """The armed periods of transitions [(t, armed)] as "armed 72.6-254.1 s (181 s in 1 period; ...)", or
    "never armed". Periods, not transition times: "72.6 s armed" read as a duration. A log still armed
    at its end is armed up to its last IMU sample (what the still selection leaves out)."""
    from companion.sources.still import armed_intervals

    last = max((t for t, _ in transitions), default=0.0)
    iv = armed_intervals(transitions, t_end if t_end is not None else last)
    if not iv:
        return "never armed"
    total = sum(b - a for a, b in iv)
    text = "armed " + ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in iv[:shown]) + (", ..." if len(iv) > shown else "")
    text += f" ({total:.0f} s in {len(iv)} period{'s' if len(iv) != 1 else ''}"
    still_on = bool(sorted(transitions)[-1][1])
    return text + ("; still armed at the end of the IMU data)" if still_on else ")")


def tlog_armed_line(res) -> str:
    """The armed-state line of a tlog: whose HEARTBEATs gave it, and the armed periods."""
    meta = res.meta
    src = meta.get("armed_source") or []
    if not meta.get("has_armed_state") or not src:
        systems = sorted({s.key.sysid for s in res.imu_streams()})
        who = ", ".join(f"sys{k}" for k in systems) or "the IMU data"
        return (f"log: armed state: none (no autopilot HEARTBEAT from {who}; still segments from motion only)")
    whose = ", ".join(f"sys{d['sysid']}/comp{d['compid']}, {d['heartbeats']} messages" for d in src)
    return f"log: armed state (HEARTBEAT of {whose}): " + armed_text(meta.get("armed") or [], _imu_end(res))


def write_summary(path, res) -> None:
    """``inspect --json``: :func:`summary` to ``path``; a failure is one error line."""
    try:
        Path(path).write_text(json.dumps(summary(res), indent=2) + "\n")
    except OSError as exc:
        raise CompanionError(f"{path}: cannot write ({exc.strerror or exc})") from None
