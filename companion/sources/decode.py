"""IMU payloads -> SI samples, identical for tlog frames (numpy, vectorised) and live pymavlink messages.

Default scales follow ArduPilot (../shared/REFERENCE.md): RAW_IMU and SCALED_IMU* carry int16 gyro in
mrad/s (1e-3 rad/s per LSB) and accel in mG (9.80665e-3 m/s^2 per LSB); HIGHRES_IMU carries float SI.
A ``streams:`` list in the YAML configuration overrides the scale per stream, first match wins::

    streams:
      - {message: RAW_IMU, sysid: 1, instance: 0, gyro_scale: 8.7266e-4, accel_scale: 0.0326561}

(``gyro_scale`` in rad/s per LSB, ``accel_scale`` in m/s^2 per LSB; ``sysid``, ``compid``, ``instance``
optional). The scale of an int16 format is also its quantisation step (``ImuStream.gyro_lsb``).

Time: RAW_IMU/HIGHRES_IMU ``time_usec`` * 1e-6 s, SCALED_IMU* ``time_boot_ms`` * 1e-3 s (resolution 1 ms).
Temperature: int16 cdegC (RAW_IMU extension, SCALED_IMU*) or float degC (HIGHRES_IMU); an all-zero
column means "not provided" (None). A SCALED_IMU2/3 (or SCALED_IMU) whose accel and gyro are zero in
every sample only carries a compass: ``is_imu`` False.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from companion.errors import CompanionError
from companion.samples import StreamKey
from companion.sources import messages as M

G0 = 9.80665  #: m/s^2 per g (standard gravity)
#: SI per int16 count of RAW_IMU/SCALED_IMU: ArduPilot sends mrad/s and mG
DEFAULT_SCALES = {"gyro_scale": 1e-3, "accel_scale": G0 * 1e-3}
#: s per timestamp count: time_usec (RAW_IMU, HIGHRES_IMU) or time_boot_ms (SCALED_IMU*); a CSV has no fixed one
TIME_RESOLUTION = {"RAW_IMU": 1e-6, "HIGHRES_IMU": 1e-6, "SCALED_IMU": 1e-3, "SCALED_IMU2": 1e-3,
                   "SCALED_IMU3": 1e-3, "CSV": 0.0}
#: messages that may carry a compass only (accel and gyro all zero), not an IMU
COMPASS_ONLY_CAN = ("SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3")
_MATCH_KEYS = ("message", "sysid", "compid", "instance")


class ScaleTable:
    """Per-stream scale overrides from the ``streams:`` configuration section (a list of dicts)."""

    def __init__(self, entries=None):
        if entries is None:
            entries = []
        if isinstance(entries, dict):  # a whole configuration
            entries = entries.get("streams") or []
        if not isinstance(entries, list):
            raise CompanionError("config 'streams' must be a list of {message, instance?, sysid?, compid?, "
                                 "gyro_scale?, accel_scale?}")
        self.entries = []
        for i, e in enumerate(entries):
            if not isinstance(e, dict) or "message" not in e:
                raise CompanionError(f"config streams[{i}] must be a mapping with at least 'message'")
            unknown = set(e) - set(_MATCH_KEYS) - set(DEFAULT_SCALES)
            if unknown:
                raise CompanionError(f"config streams[{i}]: unknown key(s) {', '.join(sorted(unknown))}")
            if str(e["message"]) not in M.IMU_LAYOUTS:
                raise CompanionError(f"config streams[{i}]: message {e['message']!r} is not one of "
                                     f"{', '.join(M.IMU_LAYOUTS)}")
            for k in DEFAULT_SCALES:
                if k in e:
                    try:
                        v = float(e[k])
                    except (TypeError, ValueError):
                        v = float("nan")
                    if not (np.isfinite(v) and v > 0):
                        raise CompanionError(f"config streams[{i}]: {k} must be a positive number")
            self.entries.append(dict(e))
        self.live_keys: dict = {}  # (sysid, compid, message, instance) -> (StreamKey, gyro, accel scale)

    def lookup(self, key: StreamKey) -> tuple[float, float]:
        """(gyro_scale rad/s per LSB, accel_scale m/s^2 per LSB) for an int16 stream."""
        for e in self.entries:
            if all(k not in e or str(e[k]) == str(getattr(key, k)) for k in _MATCH_KEYS):
                return (float(e.get("gyro_scale", DEFAULT_SCALES["gyro_scale"])),
                        float(e.get("accel_scale", DEFAULT_SCALES["accel_scale"])))
        return DEFAULT_SCALES["gyro_scale"], DEFAULT_SCALES["accel_scale"]


@dataclass
class RawStream:
    """Decoded samples of one stream in arrival order (before timing analysis)."""

    key: StreamKey
    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    temperature: np.ndarray | None
    is_imu: bool
    gyro_lsb: float | None
    accel_lsb: float | None
    time_resolution: float
    notes: list = field(default_factory=list)  # what the reader repaired (e.g. rows sorted), for the report


def _instance(layout: M.MessageLayout, rec: np.ndarray) -> np.ndarray:
    if layout.name in M.FIXED_INSTANCE:
        return np.full(rec.shape[0], M.FIXED_INSTANCE[layout.name], dtype=np.int64)
    return rec["id"].astype(np.int64)


def split_by_imu(layout: M.MessageLayout, rec: np.ndarray, sysid: np.ndarray, compid: np.ndarray,
                 scales: ScaleTable) -> list[tuple[RawStream, np.ndarray | slice]]:
    """The per-IMU split: decoded payload records of one message type as streams (sysid, compid, instance)
    in SI, each with the positions of its records in ``rec`` (offline loading and the tlog replay, which
    interleaves the streams again in frame order, both use it)."""
    inst = _instance(layout, rec)
    key3 = sysid.astype(np.int64) * 65536 + compid.astype(np.int64) * 256 + inst
    out = []
    keys = np.unique(key3)
    for k in keys:
        pos = slice(None) if keys.shape[0] == 1 else np.flatnonzero(key3 == k)
        key = StreamKey(int(k >> 16), int((k >> 8) & 0xFF), layout.name, int(k & 0xFF))
        out.append((_to_si(layout, key, rec[pos], scales), pos))
    return out


def streams_from_records(layout: M.MessageLayout, rec: np.ndarray, sysid: np.ndarray, compid: np.ndarray,
                         scales: ScaleTable) -> list[RawStream]:
    """Split decoded payload records of one message type into streams (sysid, compid, instance) in SI."""
    return [raw for raw, _ in split_by_imu(layout, rec, sysid, compid, scales)]


def _to_si(layout: M.MessageLayout, key: StreamKey, r: np.ndarray, scales: ScaleTable) -> RawStream:
    n = r.shape[0]
    if "time_usec" in r.dtype.names:
        t = r["time_usec"].astype(np.float64) * 1e-6
    else:
        t = r["time_boot_ms"].astype(np.float64) * 1e-3
    gyro = np.empty((n, 3))
    accel = np.empty((n, 3))
    for j, ax in enumerate("xyz"):
        gyro[:, j] = r[ax + "gyro"]
        accel[:, j] = r[ax + "acc"]
    temp = r["temperature"].astype(np.float64)
    if layout.name == "HIGHRES_IMU":
        glsb = alsb = None
    else:
        gs, as_ = scales.lookup(key)
        gyro *= gs
        accel *= as_
        temp *= 0.01
        glsb, alsb = gs, as_
    temperature = None if not np.any(temp) else temp
    is_imu = not (layout.name in COMPASS_ONLY_CAN and n > 0 and not np.any(gyro) and not np.any(accel))
    return RawStream(key, t, gyro, accel, temperature, is_imu, glsb, alsb, TIME_RESOLUTION[layout.name])


def decode_index(index, scales: ScaleTable | None = None) -> list[RawStream]:
    """Every IMU stream of a :class:`companion.sources.tlog.FrameIndex`, in SI, arrival order."""
    scales = scales or ScaleTable()
    out: list[RawStream] = []
    for msgid, layout in M.IMU_BY_ID.items():
        sel = np.flatnonzero(index.msgid == msgid)
        if sel.shape[0] == 0:
            continue
        rec = index.payloads(sel, layout.full_len).view(layout.dtype).reshape(-1)
        out.extend(streams_from_records(layout, rec, index.sysid[sel], index.compid[sel], scales))
    return out


@dataclass
class ImuSample:
    """One live IMU message in SI (what :func:`imu_sample_from_message` returns)."""

    key: StreamKey
    t_s: float
    gyro: tuple[float, float, float]
    accel: tuple[float, float, float]
    temperature: float | None
    is_imu: bool


_DEFAULT_TABLE = None


def imu_sample_from_message(msg, scales: ScaleTable | None = None) -> ImuSample | None:
    """A pymavlink message -> :class:`ImuSample` (None for non-IMU messages), same rules as the file path.

    ``is_imu`` is False for a SCALED_IMU* message whose accel and gyro are all zero (a compass-only
    instance: the stream is not an IMU if every sample is like that).

    The int16 messages take a scalar path (one message per call on a live link: a one-row numpy record
    costs ~20 us, most of a message's decoding); its arithmetic is the array path's, operation for
    operation (an int to a double, times the scale), so the samples are bit-identical
    (tests/sources/test_tlog.py). HIGHRES_IMU keeps the array path (float32 fields rounded as on the wire).
    """
    global _DEFAULT_TABLE
    name = msg.get_type()
    layout = M.IMU_LAYOUTS.get(name)
    if layout is None:
        return None
    if scales is None:
        if _DEFAULT_TABLE is None:
            _DEFAULT_TABLE = ScaleTable()
        scales = _DEFAULT_TABLE
    if name != "HIGHRES_IMU":
        v = [getattr(msg, f, 0) or 0 for f in layout.dtype.names]
        g = v[1:10]
        if (type(sum(v)) is int and v[0] >= 0 and min(g) >= -32768 and max(g) <= 32767  # all ints, in range
                and -32768 <= v[-1] <= 32767 and (name != "RAW_IMU" or 0 <= v[-2] <= 255)):
            return _int16_sample(layout, msg, v, scales)
    rec = np.array([tuple(getattr(msg, f, 0) or 0 for f in layout.dtype.names)], dtype=layout.dtype)
    s = _to_si(layout, StreamKey(int(msg.get_srcSystem()), int(msg.get_srcComponent()), name,
                                 int(_instance(layout, rec)[0])), rec, scales)
    temp = None if s.temperature is None else float(s.temperature[0])
    return ImuSample(s.key, float(s.t[0]), tuple(s.gyro[0].tolist()), tuple(s.accel[0].tolist()), temp, s.is_imu)


def _int16_sample(layout: M.MessageLayout, msg, v: list, scales: ScaleTable) -> ImuSample:
    """RAW_IMU/SCALED_IMU* field values (wire order: time, xacc..zgyro, xmag..zmag, [id,] temperature)."""
    name = layout.name
    instance = M.FIXED_INSTANCE[name] if name in M.FIXED_INSTANCE else v[-2]
    ids = (msg.get_srcSystem(), msg.get_srcComponent(), name, instance)
    known = scales.live_keys.get(ids)
    if known is None:
        key = StreamKey(int(ids[0]), int(ids[1]), name, int(instance))
        known = scales.live_keys[ids] = (key, *scales.lookup(key))
    key, gs, as_ = known
    t = float(v[0]) * (1e-6 if name == "RAW_IMU" else 1e-3)
    accel = (float(v[1]) * as_, float(v[2]) * as_, float(v[3]) * as_)
    gyro = (float(v[4]) * gs, float(v[5]) * gs, float(v[6]) * gs)
    temp = float(v[-1]) * 0.01 if v[-1] else None
    is_imu = not (name in COMPASS_ONLY_CAN and not any(v[1:7]))
    return ImuSample(key, t, gyro, accel, temp, is_imu)
