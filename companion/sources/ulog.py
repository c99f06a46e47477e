"""PX4 ULog ``.ulg`` files (pyulog, the ecosystem's parser): IMU topics as :class:`ImuStream`.

Topics read (each ``multi_id`` is its own stream; time = ``timestamp_sample`` where the topic has it,
else ``timestamp``, in microseconds since boot):

- ``sensor_combined`` (instance 0): the primary IMU as the estimator sees it; ``gyro_rad[3]`` is the
  *average* over ``gyro_integral_dt`` (a boxcar of the raw samples: a low-pass filter), accel
  ``accelerometer_m_s2[3]`` (its own time offset ``accelerometer_timestamp_relative`` is ignored);
- ``sensor_gyro`` / ``sensor_accel`` per ``multi_id``: one IMU's calibrated, filtered output; the accel of
  the same ``multi_id`` is interpolated (linearly) onto the gyro times, NaN if it is absent;
- ``sensor_gyro_fifo`` / ``sensor_accel_fifo``: raw FIFO samples, ``samples`` values per message of int16
  ``x/y/z[32]`` x ``scale`` (rad/s or m/s^2), spaced ``dt`` us, the last one at ``timestamp_sample`` (an
  assumption: the message definition does not say); the other sensor's columns NaN;
- ``vehicle_imu``: integrated ``delta_angle`` / ``delta_angle_dt`` and ``delta_velocity`` /
  ``delta_velocity_dt`` (rad/s, m/s^2): averages over the integration interval.

Metadata: ``params`` (initial parameters, e.g. ``IMU_GYRO_CUTOFF``, ``IMU_INTEG_RATE``), armed state
from ``vehicle_status.arming_state`` (2 = armed) as transitions, ``messages`` (logged text).
``.ulg.gz`` is read through gzip transparently.
"""

from __future__ import annotations

import contextlib
import gzip
import io
import logging
import zlib
from pathlib import Path

import numpy as np

from companion.errors import CompanionError
from companion.sources.kind import opens_as_gzip
from companion.samples import StreamKey
from companion.sources.decode import RawStream

_log = logging.getLogger(__name__)

TOPICS = ("sensor_combined", "sensor_gyro", "sensor_accel", "sensor_gyro_fifo", "sensor_accel_fifo", "vehicle_imu",
          "vehicle_status", "vehicle_gps_position", "sensor_gps")
#: the autopilot's own IMU health (sources/autopilot_health.py), read beside the IMU topics, not counted as them
HEALTH_TOPICS = ("vehicle_imu_status", "sensors_status_imu", "sensor_preflight")
#: PX4 gyro device-id parameters (calibration slots) and the IMU instance each names
GYRO_ID_PARAMS = {"CAL_GYRO0_ID": 0, "CAL_GYRO1_ID": 1, "CAL_GYRO2_ID": 2, "CAL_GYRO3_ID": 3}
ARMING_STATE_ARMED = 2  #: vehicle_status.arming_state of an armed vehicle


class _GuardedFile(io.BytesIO):
    """The log's bytes for pyulog, with two guards against its handling of damaged files.

    pyulog skips a corrupt message by seeking back ``2 + msg_size`` bytes from where its read ended; when the
    read was cut short by the end of the file, that lands before the header it just read and it loops for
    ever. A relative seek never goes back before the last 3-byte header read + 1 here (what pyulog means:
    advance one byte), and reading more than ``MAX_PASSES`` times the file raises instead of looping."""

    MAX_PASSES = 20

    def __init__(self, data: bytes):
        super().__init__(data)
        self._last_header = 0
        self.cut = 0  # bytes of a last message cut short by the end of the file (0: none)
        self._budget = self.MAX_PASSES * max(len(data), 1 << 16)

    def read(self, n=-1):
        if n == 3:
            self._last_header = self.tell()
        out = super().read(n)
        if n is not None and n > 0 and len(out) < n and (n != 3 or len(out) > 0):
            self.cut = len(self.getbuffer()) - self._last_header
        self._budget -= len(out) + 1
        if self._budget < 0:
            raise _NoProgress("the parser made no progress through damaged data")
        return out

    def seek(self, offset, whence=0):
        if whence == 1 and offset < 0 and self.tell() + offset < self._last_header:
            return super().seek(self._last_header + 1)
        return super().seek(offset, whence)


class _NoProgress(Exception):
    pass


def open_ulog(path):
    """A ``pyulog.ULog`` of ``path`` (.ulg or .ulg.gz) holding only the IMU and status topics; what pyulog
    prints about a damaged file (``Warning: no subscription found ...``) is counted in ``ulog.companion_warnings``
    and logged, never written to stdout."""
    try:
        from pyulog import ULog
    except ImportError:  # pragma: no cover - pyulog is a dependency
        raise CompanionError("reading .ulg needs pyulog: pip install pyulog") from None
    path = Path(path)
    try:
        if opens_as_gzip(path):
            with gzip.open(path, "rb") as fh:
                data = fh.read()
        else:
            if not path.exists():
                raise FileNotFoundError
            if path.is_dir():
                raise IsADirectoryError
            data = path.read_bytes()
        printed = io.StringIO()
        fh = _GuardedFile(data)
        with contextlib.redirect_stdout(printed):
            u = ULog(fh, list(TOPICS + HEALTH_TOPICS))
        u.companion_truncated = fh.cut
        lines = [ln.strip() for ln in printed.getvalue().splitlines() if ln.strip()]
        u.companion_warnings = lines
        u.companion_size = len(data)
        for ln in lines[:5]:
            _log.warning("%s: pyulog: %s", path, ln)
        if len(lines) > 5:
            _log.warning("%s: pyulog: %d more warnings", path, len(lines) - 5)
        return u
    except FileNotFoundError:
        raise CompanionError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise CompanionError(f"{path}: is a directory, expected a .ulg file") from None
    except (gzip.BadGzipFile, zlib.error, EOFError) as exc:
        raise CompanionError(f"{path}: not a readable gzip file ({exc})") from None
    except OSError as exc:
        raise CompanionError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except Exception as exc:  # pyulog raises plain exceptions on a bad header or a corrupt file
        raise CompanionError(f"{path}: not a readable ULog file ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None


def _needed(d) -> list[str]:
    """Fields a topic must have to be read (absent ones mean a damaged format definition)."""
    name = d.name
    if name == "sensor_combined":
        return ["timestamp"] + [f"gyro_rad[{i}]" for i in range(3)]
    if name in ("sensor_gyro", "sensor_accel"):
        return ["timestamp", "x", "y", "z"]
    if name in ("sensor_gyro_fifo", "sensor_accel_fifo"):
        return ["timestamp", "samples", "dt", "scale", "x[0]", "y[0]", "z[0]"]
    if name == "vehicle_imu":
        return (["timestamp", "delta_angle_dt", "delta_velocity_dt"] + [f"delta_angle[{i}]" for i in range(3)]
                + [f"delta_velocity[{i}]" for i in range(3)])
    return ["timestamp"]


def _time(d) -> np.ndarray:
    ts = d.data.get("timestamp_sample")
    if ts is None or not np.any(ts):
        ts = d.data["timestamp"]
    return ts.astype(np.float64) * 1e-6


def _vec(d, names) -> np.ndarray:
    with np.errstate(invalid="ignore", over="ignore"):  # a damaged definition can give odd field types
        return np.column_stack([d.data[n].astype(np.float64) for n in names])


def _nan3(n: int) -> np.ndarray:
    return np.full((n, 3), np.nan)


def raw_streams(ulog) -> tuple[list[RawStream], dict]:
    """Every IMU topic instance as a RawStream, and the per-topic message counts (pyulog's rows)."""
    out: list[RawStream] = []
    counts: dict = {}
    by = {}
    damaged = getattr(ulog, "companion_damaged", None)
    if damaged is None:
        damaged = ulog.companion_damaged = []
    for d in ulog.data_list:
        if d.name in HEALTH_TOPICS:
            continue
        label = f"{d.name}[{d.multi_id}]"
        lacking = [f for f in _needed(d) if f not in d.data]
        if lacking:  # a damaged format definition: the topic cannot be read as that topic
            n = next((int(v.shape[0]) for v in d.data.values()), 0)
            damaged.append(f"{label}: no field {', '.join(lacking[:3])} (damaged definition; {n} messages skipped)")
            continue
        by[(d.name, d.multi_id)] = d
        counts[label] = int(d.data["timestamp"].shape[0])
    for (name, mid), d in sorted(by.items()):
        n = int(d.data["timestamp"].shape[0])
        key = StreamKey(0, 0, name, int(mid))
        if name == "sensor_combined":
            gyro = _vec(d, [f"gyro_rad[{i}]" for i in range(3)])
            acc = (_vec(d, [f"accelerometer_m_s2[{i}]" for i in range(3)])
                   if all(f"accelerometer_m_s2[{i}]" in d.data for i in range(3)) else _nan3(n))
            out.append(RawStream(key, _time(d), gyro, acc, None, True, None, None, 1e-6))
        elif name == "sensor_gyro":
            t = _time(d)
            gyro = _vec(d, ["x", "y", "z"])
            acc = _nan3(n)
            a = by.get(("sensor_accel", mid))
            if a is not None and a.data["timestamp"].shape[0] >= 2:
                ta = _time(a)
                o = np.argsort(ta, kind="stable")
                av = _vec(a, ["x", "y", "z"])[o]
                inside = (t >= ta[o][0]) & (t <= ta[o][-1])
                for j in range(3):
                    acc[inside, j] = np.interp(t[inside], ta[o], av[:, j])
            temp = d.data["temperature"].astype(np.float64) if "temperature" in d.data else None
            if temp is not None and not np.all(np.isfinite(temp)):
                temp = None
            out.append(RawStream(key, t, gyro, acc, temp, True, None, None, 1e-6))
        elif name in ("sensor_gyro_fifo", "sensor_accel_fifo"):
            t_last = _time(d)
            cnt = d.data["samples"].astype(np.int64)
            dt = d.data["dt"].astype(np.float64) * 1e-6
            scale = d.data["scale"].astype(np.float64)
            width = next(i for i in range(10**6) if not all(f"{ax}[{i}]" in d.data for ax in "xyz"))
            k = np.arange(width)
            valid = k[None, :] < cnt[:, None]
            tt = t_last[:, None] - (cnt[:, None] - 1 - k[None, :]) * dt[:, None]
            vals = np.stack([_vec(d, [f"{ax}[{i}]" for i in range(width)]) * scale[:, None] for ax in "xyz"], axis=2)
            lsb = float(np.median(scale)) if n else None
            v, nan = vals[valid], _nan3(int(valid.sum()))
            if name == "sensor_gyro_fifo":
                out.append(RawStream(key, tt[valid], v, nan, None, True, lsb, None, 1e-6))
            else:
                out.append(RawStream(key, tt[valid], nan, v, None, True, None, lsb, 1e-6))
        elif name == "vehicle_imu":
            dta = d.data["delta_angle_dt"].astype(np.float64) * 1e-6
            dtv = d.data["delta_velocity_dt"].astype(np.float64) * 1e-6
            with np.errstate(divide="ignore", invalid="ignore"):
                gyro = _vec(d, [f"delta_angle[{i}]" for i in range(3)]) / dta[:, None]
                acc = _vec(d, [f"delta_velocity[{i}]" for i in range(3)]) / dtv[:, None]
            out.append(RawStream(key, _time(d), gyro, acc, None, True, None, None, 1e-6))
    return out, counts


def metadata(ulog) -> dict:
    # PX4 parameters are int32 or float; one of another type comes from a damaged definition: skipped, counted
    params = {k: v for k, v in ulog.initial_parameters.items()
              if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)}
    meta: dict = {"params": params, "armed": [], "modes": [], "messages": [], "has_armed_state": False,
                  "damaged_params": len(ulog.initial_parameters) - len(params)}
    for d in ulog.data_list:
        if d.name == "vehicle_status" and "arming_state" in d.data and "timestamp" in d.data:
            meta["has_armed_state"] = True
            t = d.data["timestamp"].astype(np.float64) * 1e-6
            armed = d.data["arming_state"].astype(int) == ARMING_STATE_ARMED
            prev = None
            for ti, a in zip(t, armed):
                if prev is None or a != prev:
                    meta["armed"].append((float(ti), bool(a)))
                    prev = a
            if "nav_state" in d.data:
                ns = d.data["nav_state"].astype(int)
                change = np.r_[True, ns[1:] != ns[:-1]]
                meta["modes"] = [(float(a), int(b)) for a, b in zip(t[change], ns[change])]
    meta["messages"] = [(float(m.timestamp) * 1e-6, m.message) for m in getattr(ulog, "logged_messages", [])]
    sc = next((d for d in ulog.data_list if d.name == "sensor_combined"), None)
    if sc is not None and "gyro_integral_dt" in sc.data and sc.data["gyro_integral_dt"].shape[0]:
        v = float(np.median(sc.data["gyro_integral_dt"]))
        meta["gyro_integral_dt_s"] = v * 1e-6 if v > 1.0 else v  # uint32 us (new) or float s (old)
    return meta


def identity(ulog, meta: dict) -> dict:
    """``{"board_id", "board", "imu_ids", "start_time"}`` of a ULog (see :mod:`companion.fleet.identity`).

    ``board_id``: the info field ``sys_uuid`` (the MCU's unique id, as PX4 writes it); ``board``: ``ver_hw``;
    ``imu_ids``: ``CAL_GYROn_ID`` parameters (device ids of the calibrated gyros; 0 = empty slot);
    ``start_time``: unix time of the log's start from the first GPS message with a UTC time
    (``time_utc_usec`` minus its age against the log's start ``timestamp``)."""
    info = getattr(ulog, "msg_info_dict", {}) or {}
    uuid = str(info.get("sys_uuid") or "").strip().lower() or None
    board = str(info.get("ver_hw") or "").strip() or None
    params = meta.get("params") or {}
    ids = {inst: int(params[n]) for n, inst in GYRO_ID_PARAMS.items() if params.get(n)}
    start = None
    for d in ulog.data_list:
        if d.name in ("vehicle_gps_position", "sensor_gps") and {"time_utc_usec", "timestamp"} <= set(d.data):
            utc = d.data["time_utc_usec"].astype(np.float64)
            ok = np.flatnonzero(utc > 1e15)
            if ok.size:
                k = int(ok[0])
                start = float(utc[k] - (float(d.data["timestamp"][k]) - float(ulog.start_timestamp))) * 1e-6
                break
    return {"board_id": uuid, "board": board, "imu_ids": ids, "start_time": start}
