"""A small PX4 ULog ``.ulg`` writer for tests and simulations (numpy, vectorised).

File layout (PX4 ULog spec, as pyulog reads it): 16-byte header ``ULog\\x01\\x12\\x35``, version 1, start
time (uint64 us); a flag-bits message ``B``; format definitions ``F`` (``name:type field;...``, packed, no
padding); initial parameters ``P`` (``float NAME`` / ``int32_t NAME``); then subscriptions ``A``
(multi_id, msg_id, name) and data messages ``D`` (msg_id + packed fields) in time order. Every message is
``uint16 size, uint8 type, payload``.

Topics written (fields as the readers need them): ``sensor_combined`` (primary IMU; gyro averaged over
``gyro_integral_dt``), ``sensor_gyro``/``sensor_accel`` per ``multi_id``, optionally ``sensor_gyro_fifo``,
``vehicle_status`` (``arming_state``
2 = armed, 1 = standby). Only for tests and examples.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

MAGIC = b"ULog\x01\x12\x35"  #: the ULog file magic (PX4 spec), followed by the version byte
DEVICE_ID = 1000  #: device_id of IMU instance 0 (instance i: DEVICE_ID + i), any distinct ids do
FIFO_PUBLISH_US = 50  #: a FIFO message is published this long after its last sample
_C = {"uint64_t": "<u8", "uint32_t": "<u4", "int32_t": "<i4", "float": "<f4", "uint8_t": "u1", "int16_t": "<i2"}

FORMATS = {
    "sensor_combined": [("uint64_t", "timestamp", 0), ("float", "gyro_rad", 3), ("uint32_t", "gyro_integral_dt", 0),
                        ("int32_t", "accelerometer_timestamp_relative", 0), ("float", "accelerometer_m_s2", 3),
                        ("uint32_t", "accelerometer_integral_dt", 0)],
    "sensor_gyro": [("uint64_t", "timestamp", 0), ("uint64_t", "timestamp_sample", 0), ("uint32_t", "device_id", 0),
                    ("float", "x", 0), ("float", "y", 0), ("float", "z", 0), ("float", "temperature", 0),
                    ("uint32_t", "error_count", 0)],
    "sensor_accel": [("uint64_t", "timestamp", 0), ("uint64_t", "timestamp_sample", 0), ("uint32_t", "device_id", 0),
                     ("float", "x", 0), ("float", "y", 0), ("float", "z", 0), ("float", "temperature", 0),
                     ("uint32_t", "error_count", 0)],
    "sensor_gyro_fifo": [("uint64_t", "timestamp", 0), ("uint64_t", "timestamp_sample", 0),
                         ("uint32_t", "device_id", 0), ("float", "dt", 0), ("float", "scale", 0),
                         ("uint8_t", "samples", 0), ("int16_t", "x", 32), ("int16_t", "y", 32), ("int16_t", "z", 32)],
    "vehicle_status": [("uint64_t", "timestamp", 0), ("uint8_t", "arming_state", 0), ("uint8_t", "nav_state", 0)],
}


def _dtype(name):
    fields = [("_hdr", "<u2"), ("_type", "u1"), ("_id", "<u2")]
    for typ, fname, arr in FORMATS[name]:
        fields.append((fname, _C[typ], (arr,)) if arr else (fname, _C[typ]))
    return np.dtype(fields)


def _msg(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


@dataclass
class _Topic:
    """One subscription's data messages: their timestamps (us) and their bytes, a row each."""

    ts: np.ndarray
    rows: np.ndarray


def write_ulog(path, t_s, gyro, accel, combined=None, params: dict | None = None,
               armed: list[tuple[float, bool]] | None = None, temperature: float = 45.0, fifo=None) -> int:
    """Write a ULog: ``t_s`` (n,) s since boot, ``gyro``/``accel`` (k, n, 3) as sensor_gyro/sensor_accel of
    ``k`` IMUs; ``combined`` = (gyro, accel) (n, 3) each for sensor_combined (default: IMU 0's data).
    ``fifo`` = (t0_s, rate_hz, counts (m, 3) int16, scale, per_message): a sensor_gyro_fifo[0] topic whose
    message j holds samples [j*per, (j+1)*per) (the last message may hold fewer), the last one at
    ``timestamp_sample``. ``temperature``: degC, one value or (k, n) per IMU and sample (a simulated
    warm-up, :attr:`companion.sim.vehicle.VehicleBlock.temperature`). Returns the bytes written."""
    t_s = np.asarray(t_s, dtype=float)
    gyro, accel = np.asarray(gyro, dtype=float), np.asarray(accel, dtype=float)
    if gyro.ndim == 2:
        gyro, accel = gyro[None], accel[None]
    k, n = gyro.shape[:2]
    us = np.round(t_s * 1e6).astype(np.uint64)
    subs = [("sensor_combined", 0)] + [(s, i) for i in range(k) for s in ("sensor_gyro", "sensor_accel")]
    if fifo is not None:
        subs.append(("sensor_gyro_fifo", 0))
    subs.append(("vehicle_status", 0))
    out = _definitions(int(us[0]) if n else 0, params, subs)
    topics = []
    for msg_id, (name, mid) in enumerate(subs):
        dt = _dtype(name)
        if name == "sensor_gyro_fifo":
            rec = _fifo_records(dt, fifo)
        elif name == "vehicle_status":
            rec = _status_records(dt, t_s, armed)
        elif name == "sensor_combined":
            rec = _combined_records(dt, us, t_s, combined if combined is not None else (gyro[0], accel[0]))
        else:
            rec = _sensor_records(dt, us, gyro[mid] if name == "sensor_gyro" else accel[mid], mid, temperature)
        rec["_hdr"], rec["_type"], rec["_id"] = dt.itemsize - 3, ord("D"), msg_id
        topics.append(_Topic(rec["timestamp"].astype(np.int64), rec.view(np.uint8).reshape(rec.shape[0], -1)))
    out += _in_time_order(topics)
    with open(path, "wb") as fh:
        fh.write(out)
    return len(out)


def _definitions(t0_us: int, params, subs) -> bytes:
    """The header, flag bits, format definitions, initial parameters and subscriptions."""
    out = bytearray(MAGIC + bytes([1]) + struct.pack("<Q", t0_us))
    out += _msg(b"B", bytes(16) + struct.pack("<QQQ", 0, 0, 0))
    for name, fields in FORMATS.items():
        spec = name + ":" + "".join(f"{t}[{a}] {f};" if a else f"{t} {f};" for t, f, a in fields)
        out += _msg(b"F", spec.encode())
    for pname, v in (params or {}).items():
        if isinstance(v, int):
            out += _msg(b"P", bytes([len(f"int32_t {pname}")]) + f"int32_t {pname}".encode() + struct.pack("<i", v))
        else:
            out += _msg(b"P", bytes([len(f"float {pname}")]) + f"float {pname}".encode() + struct.pack("<f", float(v)))
    for msg_id, (name, mid) in enumerate(subs):
        out += _msg(b"A", struct.pack("<BH", mid, msg_id) + name.encode())
    return bytes(out)


def _fifo_records(dt, fifo) -> np.ndarray:
    """sensor_gyro_fifo: ``per`` samples a message, the last message maybe fewer, stamped at its last sample."""
    t0f, rate, counts, scale, per = fifo
    counts = np.asarray(counts, dtype=np.int16)
    m = counts.shape[0]
    nmsg = -(-m // per)
    rec = np.zeros(nmsg, dtype=dt)
    k_last = np.minimum((np.arange(nmsg) + 1) * per, m) - 1
    rec["samples"] = k_last - np.arange(nmsg) * per + 1
    rec["timestamp_sample"] = np.round((t0f + k_last / rate) * 1e6).astype(np.uint64)
    rec["timestamp"] = rec["timestamp_sample"] + FIFO_PUBLISH_US
    rec["dt"], rec["scale"], rec["device_id"] = 1e6 / rate, scale, DEVICE_ID
    pad = np.zeros((nmsg * per, 3), dtype=np.int16)
    pad[:m] = counts
    blk = pad.reshape(nmsg, per, 3)
    for j, ax in enumerate("xyz"):
        rec[ax][:, :per] = blk[:, :, j]
    return rec


def _status_records(dt, t_s, armed) -> np.ndarray:
    """vehicle_status once a second and at each armed transition (2 armed, 1 standby)."""
    trans = sorted(armed or [])
    times = np.unique(np.r_[np.arange(float(t_s[0]), float(t_s[-1]), 1.0), [a for a, _ in trans]])
    rec = np.zeros(times.shape[0], dtype=dt)
    rec["timestamp"] = np.round(times * 1e6).astype(np.uint64)
    state = np.ones(times.shape[0], dtype=np.uint8)
    for ta, a in trans:
        state[times >= ta] = 2 if a else 1
    rec["arming_state"] = state
    return rec


def _combined_records(dt, us, t_s, combined) -> np.ndarray:
    """sensor_combined: the primary IMU, integrated over the median sample interval."""
    n = us.shape[0]
    dt_us = int(round(float(np.median(np.diff(t_s))) * 1e6)) if n > 1 else 0
    rec = np.zeros(n, dtype=dt)
    rec["timestamp"] = us
    g, a = combined
    rec["gyro_rad"], rec["accelerometer_m_s2"] = g, a
    rec["gyro_integral_dt"] = rec["accelerometer_integral_dt"] = dt_us
    return rec


def _sensor_records(dt, us, v, mid: int, temperature) -> np.ndarray:
    """sensor_gyro / sensor_accel of instance ``mid``."""
    rec = np.zeros(us.shape[0], dtype=dt)
    rec["timestamp"] = us
    rec["timestamp_sample"] = us
    rec["device_id"] = DEVICE_ID + mid
    rec["x"], rec["y"], rec["z"] = v[:, 0], v[:, 1], v[:, 2]
    tmp = np.asarray(temperature, dtype=float)
    rec["temperature"] = tmp[mid] if tmp.ndim == 2 else tmp  # (k, n) per IMU, or one value
    return rec


def _in_time_order(topics: list[_Topic]) -> bytes:
    """The data messages of every topic merged by a stable sort on the timestamp (rows of different sizes)."""
    ts = np.concatenate([b.ts for b in topics])
    src = np.concatenate([np.full(b.ts.shape[0], i) for i, b in enumerate(topics)])
    row = np.concatenate([np.arange(b.ts.shape[0]) for b in topics])
    order = np.lexsort((src, ts))
    s_o, r_o = src[order], row[order]
    # every row's place in the output, then each topic's rows scattered there at once (rows of one topic
    # share a size; a byte-string join per run of rows costs a Python step per message when topics alternate)
    width = np.array([b.rows.shape[1] for b in topics], dtype=np.int64)
    start = np.r_[0, np.cumsum(width[s_o])]
    body = np.empty(int(start[-1]), dtype=np.uint8)
    for i, b in enumerate(topics):
        sel = np.flatnonzero(s_o == i)
        body[start[sel][:, None] + np.arange(width[i])] = b.rows[r_o[sel]]
    return body.tobytes()
