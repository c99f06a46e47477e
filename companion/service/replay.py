"""Replay a .tlog through the live pipeline, as fast as it can, in the file's frame order.

Frames are found by the fast walker (:mod:`companion.sources.tlog`) and decoded vectorised with the
same rules as live messages (:mod:`companion.sources.decode`); HEARTBEATs and IMU samples are then
handed to :class:`companion.service.pipeline.Pipeline` one by one in file order, exactly as the live
loop would (message time only, so the result does not depend on how fast the log was recorded or is
replayed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from companion.sources import messages as M
from companion.sources import tlog
from companion.sources.decode import ScaleTable, streams_from_records


def replay_tlog(path, pipeline, scales: ScaleTable | None = None, stop=lambda: False) -> dict:
    """Feed every HEARTBEAT and IMU sample of ``path`` to ``pipeline``; return counts."""
    path = Path(path)
    data = tlog.read_file(path)
    index = tlog.scan(data)
    scales = scales or ScaleTable()
    # events: frame number, source (-1: HEARTBEAT, else index into ``streams``), row in that source
    order_parts, srcs, rows = [], [], []
    hb = np.flatnonzero(index.msgid == M.HEARTBEAT.msgid)
    hb_rec = index.payloads(hb, M.HEARTBEAT.full_len).view(M.HEARTBEAT.dtype).reshape(-1) if hb.size else None
    order_parts.append(hb)
    srcs.append(np.full(hb.size, -1, dtype=np.int64))
    rows.append(np.arange(hb.size))
    streams = []
    for msgid, layout in M.IMU_BY_ID.items():
        sel = np.flatnonzero(index.msgid == msgid)
        if sel.size == 0:
            continue
        rec = index.payloads(sel, layout.full_len).view(layout.dtype).reshape(-1)
        inst = (np.full(sel.size, M.FIXED_INSTANCE[layout.name]) if layout.name in M.FIXED_INSTANCE
                else rec["id"].astype(np.int64))
        key3 = index.sysid[sel].astype(np.int64) * 65536 + index.compid[sel].astype(np.int64) * 256 + inst
        for k in np.unique(key3):
            m = key3 == k
            (raw,) = streams_from_records(layout, rec[m], index.sysid[sel][m], index.compid[sel][m], scales)
            if not raw.is_imu:
                continue
            streams.append(raw)
            order_parts.append(sel[m])
            srcs.append(np.full(int(m.sum()), len(streams) - 1, dtype=np.int64))
            rows.append(np.arange(int(m.sum())))
    frame = np.concatenate(order_parts)
    src = np.concatenate(srcs)
    row = np.concatenate(rows)
    order = np.argsort(frame, kind="stable")
    used = 0
    for i in order:
        if stop():
            break
        j = int(row[i])
        if src[i] < 0:
            r = hb_rec[j]
            pipeline.on_heartbeat(int(index.sysid[frame[i]]), int(r["type"]), int(r["autopilot"]), int(r["base_mode"]))
        else:
            s = streams[int(src[i])]
            used += pipeline.on_sample(s.key, float(s.t[j]), s.gyro[j], s.accel[j])
    return {"frames": index.frames, "bad_frames": index.bad_frames, "bad_bytes": index.bad_bytes,
            "heartbeats": int(hb.size), "imu_samples": int(sum(s.t.shape[0] for s in streams)), "used": int(used)}


REPLAY_LOG_SUFFIXES = (".bin", ".bin.gz", ".ulg", ".ulg.gz", ".csv", ".csv.gz")
MAV_MODE_FLAG_SAFETY_ARMED = 128
_AUTOPILOT = {"dataflash": 3, "ulog": 12}  # MAV_AUTOPILOT_ARDUPILOTMEGA, MAV_AUTOPILOT_PX4; else GENERIC (0)


def is_replay_source(spec) -> bool:
    """True for a file ``companion run --source`` replays (.tlog, .bin, .ulg, .csv; each optionally .gz)."""
    low = str(spec).lower()
    return low.endswith((".tlog", ".tlog.gz")) or low.endswith(REPLAY_LOG_SUFFIXES)


def replay_log(path, pipeline, stop=lambda: False, time_unit: str | None = None) -> dict:
    """Feed a DataFlash .bin, a ULog .ulg or a CSV file to ``pipeline`` in message-time order.

    Per IMU instance the stream with the most samples is replayed (a ULog holds sensor_combined,
    sensor_gyro and vehicle_imu of the same IMU; a DataFlash log its IMU and the batch sampler's bursts).
    The log's armed state becomes a HEARTBEAT (base_mode armed flag) at every transition and once a
    second, exactly as a live vehicle sends them; a source without armed state sends none.
    """
    from companion.sources import load

    res = load(path, time_unit=time_unit)  # time_unit: of a CSV's time column
    best: dict = {}
    for s in res.imu_streams():
        if not np.all(np.isfinite(s.gyro[:1])):
            continue
        cur = best.get(s.key.instance)
        if cur is None or s.samples > cur.samples:
            best[s.key.instance] = s
    streams = [best[k] for k in sorted(best)]
    if not streams:
        return {"frames": int(res.totals.get("frames", 0)), "bad_frames": 0, "bad_bytes": 0, "heartbeats": 0,
                "imu_samples": 0, "used": 0}
    t_all = np.concatenate([s.t for s in streams])
    src = np.concatenate([np.full(s.samples, i) for i, s in enumerate(streams)])
    row = np.concatenate([np.arange(s.samples) for s in streams])
    # heartbeats: transitions and 1 Hz
    hb_t, hb_armed = [], []
    if res.meta.get("has_armed_state"):
        from companion.sources.still import armed_intervals

        lo, hi = float(t_all.min()), float(t_all.max())
        iv = armed_intervals(res.meta.get("armed") or [], hi)
        grid = np.arange(np.floor(lo), hi + 1.0)
        edges = [a for a, _ in iv] + [b for _, b in iv]
        hb_t = np.sort(np.r_[grid, edges])
        hb_armed = np.zeros(hb_t.shape[0], dtype=bool)
        for a, b in iv:
            hb_armed |= (hb_t >= a) & (hb_t < b)
    hb_t = np.asarray(hb_t, dtype=float)
    t_ev = np.r_[hb_t, t_all]
    kind = np.r_[np.full(hb_t.shape[0], -1), src]
    rows = np.r_[np.arange(hb_t.shape[0]), row]
    order = np.lexsort((kind, t_ev))  # heartbeat first at equal times
    autopilot = _AUTOPILOT.get(res.meta.get("format"), 0)
    sysid = streams[0].key.sysid
    used = 0
    for i in order:
        if stop():
            break
        k, j = int(kind[i]), int(rows[i])
        if k < 0:
            pipeline.on_heartbeat(sysid, 2, autopilot, MAV_MODE_FLAG_SAFETY_ARMED if hb_armed[j] else 0)
        else:
            s = streams[k]
            used += pipeline.on_sample(s.key, float(s.t[j]), s.gyro[j], s.accel[j])
    return {"frames": int(res.totals.get("frames", 0)), "bad_frames": int(res.totals.get("bad_frames", 0)),
            "bad_bytes": int(res.totals.get("bad_bytes", 0)), "heartbeats": int(hb_t.shape[0]),
            "imu_samples": int(t_all.shape[0]), "used": int(used)}


def replay_vehicle(sim, pipeline, duration_s: float, lsb: float | None = None, chunk_s: float = 1.0,
                   sysid: int = 1, on_chunk=None) -> int:
    """Feed a :class:`companion.sim.vehicle.VehicleSimulator` to ``pipeline`` for ``duration_s`` of message
    time: a HEARTBEAT (armed bit from the simulator) before every ``chunk_s`` of samples, the IMU samples
    through :meth:`Pipeline.on_samples` (IMU i as RAW_IMU / SCALED_IMU2 / SCALED_IMU3), the gyro rounded to
    ``lsb`` rad/s when given (ArduPilot's int16 mrad/s: 1e-3). ``on_chunk(t_end)`` after each chunk (stop
    early by returning True). Returns the samples fed per IMU."""
    from companion.samples import StreamKey
    from companion.sim.vehicle import IMU_MESSAGES

    keys = [StreamKey(sysid, 1, IMU_MESSAGES[i], i) for i in range(sim.imus)]
    t_stop = sim.t_start + float(duration_s)
    fed = 0
    while sim.t_next < t_stop - 0.5 / sim.rate_hz:
        blk = sim.take_until(min(sim.t_next + chunk_s, t_stop) - 0.5 / sim.rate_hz)
        if blk.n == 0:
            break
        pipeline.on_heartbeat(sysid, 2, 3, 128 if bool(blk.armed[0]) else 0)
        for i, key in enumerate(keys):
            g = blk.gyro[i]
            if lsb:
                g = np.round(g / lsb) * lsb
            pipeline.on_samples(key, blk.t, g, blk.accel[i])
        fed += blk.n
        if on_chunk is not None and on_chunk(float(blk.t[-1])):
            break
    return fed
