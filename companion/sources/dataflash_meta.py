"""Metadata and identity of an ArduPilot DataFlash log (:mod:`companion.sources.dataflash`).

Log metadata (:func:`log_metadata`): ``PARM`` (name -> last value), armed state from ``EV`` ids 10
(armed) / 11 (disarmed) and ``ARM`` (``ArmState``), ``MODE`` changes, ``MSG`` texts, ``ERR``.
Identity (:func:`log_identity`): the board id from the boot banner, the gyro device ids from ``PARM``, the
start time from the first GPS record with a 3D fix.
"""

from __future__ import annotations

import re

import numpy as np

from companion.sources.dataflash import DataFlashLog, int_codes

#: ``EV`` ids of the armed and disarmed events (ArduPilot LogEvent ARMED / DISARMED)
EV_ARMED, EV_DISARMED = 10, 11


def log_metadata(log: DataFlashLog) -> dict:
    """Parameters, armed transitions, modes, texts and errors of the log (times in s since boot)."""
    meta: dict = {"params": {}, "armed": [], "modes": [], "messages": [], "errors": []}
    if log.has("PARM", "Name", "Value"):
        rec = log.records("PARM")
        for nm, v in zip(log.strings("PARM", "Name", rec), log.values("PARM", "Value", rec)):
            meta["params"][nm] = float(v)
    trans = []
    if log.has("EV", "Id"):
        rec = log.records("EV")
        t = log.time_s("EV", rec)
        for ti, i in zip(t, int_codes(log.values("EV", "Id", rec))):
            if i in (EV_ARMED, EV_DISARMED):
                trans.append((float(ti), bool(i == EV_ARMED)))
    if log.has("ARM", "ArmState"):
        rec = log.records("ARM")
        t = log.time_s("ARM", rec)
        for ti, s in zip(t, int_codes(log.values("ARM", "ArmState", rec))):
            trans.append((float(ti), bool(s)))
    trans.sort()
    dedup = []
    for ti, s in trans:
        if not dedup or dedup[-1][1] != s:
            dedup.append((ti, s))
    meta["armed"] = dedup
    meta["has_armed_state"] = bool(log.has("EV") or log.has("ARM"))
    mode_col = next((c for c in ("ModeNum", "Mode") if c in log.columns("MODE")), None)
    if mode_col and log.has("MODE", mode_col):
        rec = log.records("MODE")
        t = log.time_s("MODE", rec)
        num = int_codes(log.values("MODE", mode_col, rec))
        meta["modes"] = [(float(a), int(b)) for a, b in zip(t, num)]
    if log.has("MSG", "Message"):
        rec = log.records("MSG")
        t = log.time_s("MSG", rec)
        meta["messages"] = [(float(a), s) for a, s in zip(t, log.strings("MSG", "Message", rec))]
    if log.has("ERR", "Subsys", "ECode"):
        rec = log.records("ERR")
        t = log.time_s("ERR", rec)
        meta["errors"] = [(float(a), int(b), int(c)) for a, b, c in
                          zip(t, int_codes(log.values("ERR", "Subsys", rec)), int_codes(log.values("ERR", "ECode", rec)))]
    return meta


# --------------------------------------------------------------------------------------------------
# identity: which board flew the log, and when

#: ArduPilot's banner line with the MCU's unique id, sent at boot and logged as MSG, e.g.
#: "Pixhawk4 0047002B 34385105 36363539" (board name, then 96 bits as three 32-bit hex words)
BOARD_BANNER = re.compile(r"^(\S+) ([0-9A-Fa-f]{8}) ([0-9A-Fa-f]{8}) ([0-9A-Fa-f]{8})\s*$")
GPS_EPOCH_UNIX = 315964800.0  #: unix time of the GPS epoch, 1980-01-06 00:00:00 UTC
#: GPS - UTC leap seconds from these unix times on (a fleet's start times need seconds, not better)
GPS_LEAP_S = ((1483228800.0, 18.0), (1435708800.0, 17.0), (1341100800.0, 16.0), (1230768000.0, 15.0),
              (0.0, 14.0))
GPS_FIX_3D = 3  #: GPS ``Status`` of a 3D fix: the first one whose week and ms of week are trusted


def board_from_messages(messages) -> tuple[str | None, str | None]:
    """(board id as 24 lowercase hex digits, board name) from the boot banner among MSG texts."""
    for _, text in messages:
        m = BOARD_BANNER.match(text.strip())
        if m and m.group(1) not in ("Frame:", "PX4:", "ChibiOS:", "NuttX:"):
            return "".join(m.group(i) for i in (2, 3, 4)).lower(), m.group(1)
    return None, None


def utc_at_boot(log: DataFlashLog) -> float | None:
    """Unix time at the autopilot's boot from the first GPS record with a 3D fix (instance 0), or None.

    New logs: ``GWk``/``GMS`` (GPS week, ms of week) with ``TimeUS`` since boot; old ones (3.3): ``Week``/
    ``TimeMS`` (ms of week) with ``T`` (ms since boot)."""
    if not log.has("GPS"):
        return None
    cols = log.columns("GPS")
    rec = log.records("GPS")

    def v(c):
        return log.values("GPS", c, rec)

    if {"GWk", "GMS", "TimeUS"} <= set(cols):
        wk, ms, boot = v("GWk"), v("GMS"), v("TimeUS") * 1e-6
    elif {"Week", "TimeMS", "T"} <= set(cols):
        wk, ms, boot = v("Week"), v("TimeMS"), v("T") * 1e-3
    else:
        return None
    ok = (wk > 0) & (boot > 0) & np.isfinite(ms)
    if "Status" in cols:
        ok &= v("Status") >= GPS_FIX_3D
    if "I" in cols:
        ok &= v("I") == 0
    i = np.flatnonzero(ok)
    if not i.size:
        return None
    k = int(i[0])
    gps = GPS_EPOCH_UNIX + float(wk[k]) * 604800.0 + float(ms[k]) * 1e-3
    if not gps >= 0.0:
        return None
    leap = next(v for t0, v in GPS_LEAP_S if gps >= t0)
    return gps - leap - float(boot[k])


def log_identity(log: DataFlashLog, meta: dict) -> dict:
    """``{"board_id", "board", "imu_ids": {instance: INS_GYRn_ID}, "start_time": unix s of the first IMU
    sample or None}`` (see :mod:`companion.fleet.identity`)."""
    board_id, board = board_from_messages(meta.get("messages") or [])
    params = meta.get("params") or {}
    ids = {}
    from companion.sources.messages import ARDUPILOT_GYRO_ID_PARAMS

    for name, inst in ARDUPILOT_GYRO_ID_PARAMS.items():
        v = params.get(name)
        if v is not None and np.isfinite(v) and v != 0:
            ids[inst] = int(round(v))
    start = None
    boot = utc_at_boot(log)
    if boot is not None:
        t0 = log.time_s("IMU")[:1] if log.has("IMU") else np.zeros(1)
        start = boot + (float(t0[0]) if t0.size and np.isfinite(t0[0]) else 0.0)
    return {"board_id": board_id, "board": board, "imu_ids": ids, "start_time": start}
