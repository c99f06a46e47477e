"""Who flew a log: the autopilot's board id, the IMU ids and the log's start time, from its metadata.

The IMU samples come from :func:`companion.sources.load`; this module reads what the fleet database
adds around them. Per format:

- telemetry log (.tlog): ``AUTOPILOT_VERSION.uid`` (the board's 64-bit unique id; 0 = not provided),
  ``PARAM_VALUE`` of ``INS_GYR_ID``, ``INS_GYR2_ID``, ``INS_GYR3_ID`` (ArduPilot's gyro device ids of IMU
  0, 1, 2; the value is the integer sent as a float, exact below 2^24), and the start time = the first
  record's time stamp (unix microseconds; its low 2 bits may hold a link number, irrelevant here).
  Frames are found by the same walker as the IMU data (:mod:`companion.sources.tlog`).
- CSV: nothing (no ids, no time of day): the vehicle is ``sys0`` unless ``--vehicle dir`` is used, the
  start time is the file's modification time (recorded as such in ``logs.start_source``).
- DataFlash .bin / ULog .ulg: read by their own modules once companion.sources has them (DataFlash
  ``VER``/``MSG`` board id, ULog ``sys_uuid``); until then only what the reader's streams carry.

All functions return a plain dict and never raise for a log the IMU reader accepted: missing metadata
is simply absent.
"""

from __future__ import annotations

import numpy as np

AUTOPILOT_VERSION_ID = 148
PARAM_VALUE_ID = 22
#: ArduPilot gyro device-id parameters and the IMU instance each names
GYRO_ID_PARAMS = {"INS_GYR_ID": 0, "INS_GYR2_ID": 1, "INS_GYR3_ID": 2}


def tlog_identity(data: bytes) -> dict:
    """``{"board_id": hex str or None, "imu_ids": {instance: int}, "start_time": unix s or None,
    "board_by_sysid": {sysid: hex}}`` from the bytes of a tlog."""
    from companion.sources import tlog

    idx = tlog.scan(data)
    out = {"board_id": None, "imu_ids": {}, "start_time": None, "board_by_sysid": {}}
    if idx.frames:
        stamps = idx.stamp_us.astype(np.float64)
        good = stamps[(stamps > 1e15) & (stamps < 4.1e15)]  # 2001..2099 in unix microseconds
        if good.size:
            out["start_time"] = float(good.min()) / 1e6
    sel = np.flatnonzero(idx.msgid == AUTOPILOT_VERSION_ID)
    if sel.size:
        pl = idx.payloads(sel, 16)
        uids = pl[:, 8:16].copy().view("<u8").reshape(-1)
        for s, uid in zip(idx.sysid[sel], uids):
            if uid:
                out["board_by_sysid"][int(s)] = f"{int(uid):016x}"
        if out["board_by_sysid"]:
            out["board_id"] = next(iter(out["board_by_sysid"].values()))
    sel = np.flatnonzero(idx.msgid == PARAM_VALUE_ID)
    if sel.size:
        pl = idx.payloads(sel, 25)
        names = [bytes(r[8:24]).split(b"\0", 1)[0].decode("ascii", "replace") for r in pl]
        values = pl[:, 0:4].copy().view("<f4").reshape(-1)
        for name, v in zip(names, values):
            inst = GYRO_ID_PARAMS.get(name)
            if inst is not None and np.isfinite(v):
                out["imu_ids"][inst] = int(round(float(v)))
    return out


def log_identity(path: str, fmt: str, data: bytes | None = None) -> dict:
    """Metadata of one log (see the module docstring); ``data``: its bytes if already read."""
    if fmt == "tlog":
        if data is None:
            with open(path, "rb") as fh:
                data = fh.read()
        return tlog_identity(data)
    return {"board_id": None, "imu_ids": {}, "start_time": None, "board_by_sysid": {}}
