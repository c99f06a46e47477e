"""Write telemetry logs (.tlog): IMU streams from SI arrays, fast, and any pymavlink message.

A tlog is a sequence of records ``[8-byte big-endian unix time in microseconds][one MAVLink frame]``
(the format MAVProxy and Mission Planner write). :func:`write_imu_tlog` builds all frames at once
with numpy (a 720,000-message file takes about a second) and pymavlink decodes them to the same
values (tests/sources/test_tlog.py checks it).

Units written (ArduPilot's conventions, see ../shared/REFERENCE.md):

- ``RAW_IMU``, ``SCALED_IMU``, ``SCALED_IMU2``, ``SCALED_IMU3``: int16 gyro in mrad/s and accel in mG by
  default (``gyro_scale`` rad/s per LSB = 1e-3, ``accel_scale`` m/s^2 per LSB = 9.80665e-3); the SI value
  is divided by the scale, ROUNDED to the nearest integer and CLIPPED to [-32768, 32767]. Temperature in
  cdegC (int16). RAW_IMU carries ``time_usec``, SCALED_IMU* ``time_boot_ms`` (``round(t_s * 1000)``, so
  1 ms resolution).
- ``HIGHRES_IMU``: float32 SI values (rad/s, m/s^2, degC), ``time_usec``; no quantisation.

MAVLink 2 frames have their payload's trailing zero bytes trimmed like pymavlink and ArduPilot do;
MAVLink 1 frames carry the base payload only (no extension fields: RAW_IMU ``id``/``temperature`` and
HIGHRES_IMU ``id`` are lost, as on a real MAVLink 1 link).
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from companion.sources import messages as M

G0 = 9.80665  # m/s^2, standard gravity: ArduPilot's accelerometer unit mG is G0 / 1000
DEFAULT_GYRO_SCALE = 1e-3  # rad/s per LSB (mrad/s, ArduPilot's RAW_IMU/SCALED_IMU gyro unit)
DEFAULT_ACCEL_SCALE = G0 * 1e-3  # m/s^2 per LSB (mG)
MAV_STATE_ACTIVE = 4  # HEARTBEAT system_status of a running autopilot (MAVLink MAV_STATE_ACTIVE)


def _int16(values: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(values), -32768, 32767).astype("<i2")


def imu_payloads(message: str, t_s, gyro, accel, instance: int = 0, temperature=None,
                 gyro_scale: float | None = None, accel_scale: float | None = None) -> np.ndarray:
    """Full-length payloads of ``message`` as a structured array (one row per sample), from SI arrays."""
    if message not in M.IMU_LAYOUTS:
        raise ValueError(f"unknown IMU message {message!r}; expected one of {', '.join(M.IMU_LAYOUTS)}")
    layout = M.IMU_LAYOUTS[message]
    t_s = np.asarray(t_s, dtype=np.float64).reshape(-1)
    n = t_s.shape[0]
    gyro = np.asarray(gyro, dtype=np.float64).reshape(n, 3)
    accel = np.asarray(accel, dtype=np.float64).reshape(n, 3)
    if np.any(t_s < 0):
        raise ValueError("t_s must be >= 0 (time since boot)")
    if not (np.all(np.isfinite(t_s)) and np.all(np.isfinite(gyro)) and np.all(np.isfinite(accel))):
        raise ValueError("t_s, gyro and accel must be finite")
    rec = np.zeros(n, dtype=layout.dtype)
    temp = None if temperature is None else np.broadcast_to(np.asarray(temperature, dtype=np.float64), (n,))
    if message == "HIGHRES_IMU":
        rec["time_usec"] = np.rint(t_s * 1e6).astype(np.uint64)
        for j, ax in enumerate("xyz"):
            rec[ax + "gyro"] = gyro[:, j]
            rec[ax + "acc"] = accel[:, j]
        if temp is not None:
            rec["temperature"] = temp
        rec["fields_updated"] = 0x003F  # acc and gyro fields updated
        rec["id"] = instance
        return rec
    gs = DEFAULT_GYRO_SCALE if gyro_scale is None else float(gyro_scale)
    as_ = DEFAULT_ACCEL_SCALE if accel_scale is None else float(accel_scale)
    if message == "RAW_IMU":
        rec["time_usec"] = np.rint(t_s * 1e6).astype(np.uint64)
        rec["id"] = instance
    else:
        rec["time_boot_ms"] = np.rint(t_s * 1e3).astype(np.uint32)
    for j, ax in enumerate("xyz"):
        rec[ax + "gyro"] = _int16(gyro[:, j] / gs)
        rec[ax + "acc"] = _int16(accel[:, j] / as_)
    if temp is not None:
        rec["temperature"] = _int16(temp * 100.0)
    return rec


def heartbeat_payload(armed=False) -> np.ndarray:
    """HEARTBEAT payloads of an ArduPilot quadrotor: disarmed in standby, or armed (``base_mode`` bit 7,
    MAV_MODE_FLAG_SAFETY_ARMED) and active. ``armed`` a bool (one row) or an array of bools (one row each)."""
    armed = np.atleast_1d(np.asarray(armed, dtype=bool))
    rec = np.zeros(armed.shape[0], dtype=M.HEARTBEAT.dtype)
    rec["type"] = M.MAV_TYPE_QUADROTOR
    rec["autopilot"] = M.MAV_AUTOPILOT_ARDUPILOTMEGA
    rec["base_mode"] = np.where(armed, 0x81, 0x01)  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED (+ SAFETY_ARMED)
    rec["system_status"] = np.where(armed, MAV_STATE_ACTIVE, M.MAV_STATE_STANDBY)
    rec["mavlink_version"] = 3
    return rec


def encode_frames(payloads: np.ndarray, msgid: np.ndarray, crc_extra: np.ndarray, seq: np.ndarray,
                  sysid: int, compid: int, mavlink2: bool = True,
                  base_len: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """MAVLink frames for payload rows, vectorised.

    ``payloads`` is (n, P) uint8 (rows zero-padded to a common width); ``base_len`` (n,) is the
    MAVLink 1 length of each row's message. Returns (frames (n, F) uint8 zero-padded, lengths (n,)).
    MAVLink 2 payloads are trimmed of trailing zeros (at least one byte kept).
    """
    n, width = payloads.shape
    if mavlink2:
        nz = payloads != 0
        last = width - 1 - np.argmax(nz[:, ::-1], axis=1)
        plen = np.where(nz.any(axis=1), last + 1, 1)
        hl = M.HEADER_V2
    else:
        plen = np.asarray(base_len, dtype=np.int64)
        hl = M.HEADER_V1
    flen = hl + plen + 2
    frames = np.zeros((n, hl + width + 2), dtype=np.uint8)
    if mavlink2:
        frames[:, 0] = M.MAGIC_V2
        frames[:, 1] = plen
        frames[:, 4] = seq
        frames[:, 5] = sysid
        frames[:, 6] = compid
        frames[:, 7] = msgid & 0xFF
        frames[:, 8] = (msgid >> 8) & 0xFF
        frames[:, 9] = (msgid >> 16) & 0xFF
    else:
        frames[:, 0] = M.MAGIC_V1
        frames[:, 1] = plen
        frames[:, 2] = seq
        frames[:, 3] = sysid
        frames[:, 4] = compid
        frames[:, 5] = msgid
    cols = np.arange(width)
    frames[:, hl:hl + width] = np.where(cols[None, :] < plen[:, None], payloads, 0)
    crc = np.empty(n, dtype=np.uint16)
    for length in np.unique(plen):  # one CRC pass per payload length
        sel = np.flatnonzero(plen == length)
        crc[sel] = M.crc_x25_rows(frames[sel, 1:hl + length], crc_extra[sel])
    rows = np.arange(n)
    frames[rows, hl + plen] = crc & 0xFF
    frames[rows, hl + plen + 1] = crc >> 8
    return frames, flen


def pack_records(stamps_us: np.ndarray, frames: np.ndarray, flen: np.ndarray) -> bytes:
    """Concatenate ``[8-byte big-endian stamp][frame]`` records into the bytes of a tlog."""
    n = frames.shape[0]
    rec_len = flen + 8
    starts = np.zeros(n, dtype=np.int64)
    np.cumsum(rec_len[:-1], out=starts[1:])
    out = np.zeros(int(rec_len.sum()), dtype=np.uint8)
    stamps = np.asarray(stamps_us, dtype=">u8").view(np.uint8).reshape(n, 8)
    out[starts[:, None] + np.arange(8)] = stamps
    for length in np.unique(flen):
        sel = np.flatnonzero(flen == length)
        idx = starts[sel, None] + 8 + np.arange(length)
        out[idx] = frames[sel, :length]
    return out.tobytes()


def write_imu_tlog(path, t_s, gyro, accel, message: str = "RAW_IMU", sysid: int = 1, compid: int = 1,
                   instance: int = 0, temperature=None, heartbeat_hz: float = 1.0, mavlink2: bool = True,
                   t0_unix: float = 1.7e9, gyro_scale: float | None = None,
                   accel_scale: float | None = None) -> int:
    """Write a tlog of one IMU stream from SI arrays; returns the number of IMU messages written.

    ``t_s`` (n,) seconds since boot (the message timestamp), ``gyro`` (n, 3) rad/s, ``accel`` (n, 3) m/s^2,
    ``temperature`` scalar or (n,) degC or None. Record stamps are ``t0_unix + t_s`` in microseconds.
    A HEARTBEAT (MAV_TYPE_QUADROTOR, disarmed) precedes the first sample and then every
    ``1/heartbeat_hz`` seconds (``heartbeat_hz=0``: none). int16 formats round to nearest and clip
    (see the module docstring). Sequence numbers count all messages of the (sysid, compid) mod 256.
    """
    layout = M.IMU_LAYOUTS.get(message)
    if layout is None:
        raise ValueError(f"unknown IMU message {message!r}; expected one of {', '.join(M.IMU_LAYOUTS)}")
    rec = imu_payloads(message, t_s, gyro, accel, instance, temperature, gyro_scale, accel_scale)
    t_s = np.asarray(t_s, dtype=np.float64).reshape(-1)
    n = rec.shape[0]
    imu_bytes = rec.view(np.uint8).reshape(n, layout.full_len)
    # heartbeats: before sample i when floor(t_i * hz) increases (and before the first sample)
    if heartbeat_hz and n:
        tick = np.floor((t_s - t_s[0]) * heartbeat_hz).astype(np.int64)
        hb_before = np.flatnonzero(np.r_[True, np.diff(tick) > 0])
    else:
        hb_before = np.zeros(0, dtype=np.int64)
    n_hb = hb_before.shape[0]
    total = n + n_hb
    # position of each IMU message and each heartbeat in the output order
    imu_pos = np.arange(n) + np.searchsorted(hb_before, np.arange(n), side="right")
    hb_pos = hb_before + np.arange(n_hb)
    width = max(layout.full_len, M.HEARTBEAT.full_len)
    payloads = np.zeros((total, width), dtype=np.uint8)
    payloads[imu_pos, :layout.full_len] = imu_bytes
    payloads[hb_pos, :M.HEARTBEAT.full_len] = heartbeat_payload().view(np.uint8)
    msgid = np.full(total, layout.msgid, dtype=np.int64)
    msgid[hb_pos] = M.HEARTBEAT.msgid
    extra = np.full(total, layout.crc_extra, dtype=np.uint16)
    extra[hb_pos] = M.HEARTBEAT.crc_extra
    base = np.full(total, layout.base_len, dtype=np.int64)
    base[hb_pos] = M.HEARTBEAT.base_len
    seq = (np.arange(total) & 0xFF).astype(np.uint8)
    frames, flen = encode_frames(payloads, msgid, extra, seq, sysid, compid, mavlink2, base)
    t_all = np.empty(total)
    t_all[imu_pos] = t_s
    t_all[hb_pos] = t_s[hb_before]
    stamps = np.rint((t0_unix + t_all) * 1e6).astype(np.uint64)
    data = pack_records(stamps, frames, flen)
    Path(path).write_bytes(data)
    return n


class _TlogFile:
    """The open tlog file of a writer (``self._fh``), closed by :meth:`close` or at the end of a ``with``."""

    def close(self) -> None:
        self._fh.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


class ImuTlogStream(_TlogFile):
    """Several IMU streams and HEARTBEATs merged in time order into one tlog, appended block by block.

    >>> with ImuTlogStream("x.tlog") as out:
    ...     out.write([("RAW_IMU", 0, t, g0, a0), ("SCALED_IMU2", 1, t, g1, a1)], heartbeat_t, heartbeat_armed)

    Each ``write`` takes streams ``(message, instance, t_s, gyro, accel[, temperature degC])`` in SI (units, rounding and
    clipping as :func:`imu_payloads`) and HEARTBEAT times (s since boot) with their armed flags; the
    records of one call are sorted by time (a HEARTBEAT before samples of the same time, then the
    streams in the order given) and appended. Calls must come in time order. Sequence numbers
    continue across calls (mod 256); record stamps are ``t0_unix + t`` in microseconds.
    """

    def __init__(self, path, sysid: int = 1, compid: int = 1, mavlink2: bool = True, t0_unix: float = 1.7e9,
                 gyro_scale: float | None = None, accel_scale: float | None = None):
        self._fh = open(path, "wb")
        self.sysid, self.compid, self.mavlink2, self.t0_unix = sysid, compid, mavlink2, t0_unix
        self.gyro_scale, self.accel_scale = gyro_scale, accel_scale
        self.records = 0

    def write(self, streams, heartbeat_t=(), heartbeat_armed=None) -> int:
        """Append one time-ordered block; returns the number of records written."""
        hb_t = np.asarray(heartbeat_t, dtype=np.float64).reshape(-1)
        armed = np.zeros(hb_t.shape[0], bool) if heartbeat_armed is None else np.asarray(heartbeat_armed, bool).reshape(-1)
        rows, ids, extras, bases, times, keys = [], [], [], [], [], []
        if hb_t.size:
            rows.append(heartbeat_payload(armed).view(np.uint8).reshape(hb_t.size, M.HEARTBEAT.full_len))
            ids.append(np.full(hb_t.size, M.HEARTBEAT.msgid))
            extras.append(np.full(hb_t.size, M.HEARTBEAT.crc_extra))
            bases.append(np.full(hb_t.size, M.HEARTBEAT.base_len))
            times.append(hb_t)
            keys.append(np.full(hb_t.size, -1))
        for k, stream in enumerate(streams):
            message, instance, t_s, gyro, accel = stream[:5]
            temperature = stream[5] if len(stream) > 5 else None
            layout = M.IMU_LAYOUTS.get(message)
            if layout is None:
                raise ValueError(f"unknown IMU message {message!r}; expected one of {', '.join(M.IMU_LAYOUTS)}")
            rec = imu_payloads(message, t_s, gyro, accel, instance, temperature, self.gyro_scale, self.accel_scale)
            n = rec.shape[0]
            rows.append(rec.view(np.uint8).reshape(n, layout.full_len))
            ids.append(np.full(n, layout.msgid))
            extras.append(np.full(n, layout.crc_extra))
            bases.append(np.full(n, layout.base_len))
            times.append(np.asarray(t_s, dtype=np.float64).reshape(-1))
            keys.append(np.full(n, k))
        if not rows:
            return 0
        t_all = np.concatenate(times)
        order = np.lexsort((np.concatenate(keys), t_all))
        total = t_all.shape[0]
        width = max(r.shape[1] for r in rows)
        payloads = np.zeros((total, width), dtype=np.uint8)
        start = 0
        for r in rows:
            payloads[start:start + r.shape[0], :r.shape[1]] = r
            start += r.shape[0]
        payloads = payloads[order]
        msgid = np.concatenate(ids).astype(np.int64)[order]
        extra = np.concatenate(extras).astype(np.uint16)[order]
        base = np.concatenate(bases).astype(np.int64)[order]
        seq = ((self.records + np.arange(total)) & 0xFF).astype(np.uint8)
        frames, flen = encode_frames(payloads, msgid, extra, seq, self.sysid, self.compid, self.mavlink2, base)
        stamps = np.rint((self.t0_unix + t_all[order]) * 1e6).astype(np.uint64)
        self._fh.write(pack_records(stamps, frames, flen))
        self.records += total
        return total


class TlogWriter(_TlogFile):
    """Write any pymavlink message object to a tlog with a timestamp (tests, small files).

    >>> with TlogWriter("x.tlog") as w:
    ...     w.write(mav.heartbeat_encode(2, 3, 0, 0, 3), t_unix=1.7e9)

    ``write`` packs the message with a pymavlink ``MAVLink`` encoder (``mavlink2`` chooses the wire
    version); ``write_raw`` appends an already-packed frame (or garbage bytes when ``stamp=False``).
    """

    def __init__(self, path, sysid: int = 1, compid: int = 1, mavlink2: bool = True):
        from pymavlink.dialects.v20 import ardupilotmega as dialect

        self._fh = open(path, "wb")
        self.mav = dialect.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.mavlink2 = mavlink2
        self.records = 0

    def write(self, msg, t_unix: float) -> bytes:
        """Pack ``msg`` (a pymavlink message object) and append it stamped ``t_unix`` seconds."""
        frame = msg.pack(self.mav, force_mavlink1=not self.mavlink2)
        self.mav.seq = (self.mav.seq + 1) % 256
        self.write_raw(frame, t_unix)
        return frame

    def write_raw(self, frame: bytes, t_unix: float | None = None) -> None:
        if t_unix is not None:
            self._fh.write(struct.pack(">Q", int(round(t_unix * 1e6))))
            self.records += 1
        self._fh.write(frame)


__all__ = ["write_imu_tlog", "ImuTlogStream", "TlogWriter", "imu_payloads", "encode_frames", "pack_records",
           "DEFAULT_GYRO_SCALE", "DEFAULT_ACCEL_SCALE"]
