"""Ingestion: IMU samples from a .tlog, an ArduPilot DataFlash .bin, a PX4 .ulg, a CSV file or a live
MAVLink link, in SI, with their timing.

>>> from companion.sources import load
>>> res = load("flight.tlog")                 # or "imu.csv.gz", or "udpin:0.0.0.0:14550" (duration=...)
>>> [s.key.label() for s in res.streams], res.totals

``load`` returns a :class:`LoadResult`: ``streams`` (one :class:`companion.samples.ImuStream` per
(sysid, compid, message, instance), sorted by key, compass-only instances included with
``is_imu=False``) and ``totals`` (``frames``, ``bad_bytes``, ``bad_frames``, ``imu_messages``).
Messages: RAW_IMU, SCALED_IMU, SCALED_IMU2, SCALED_IMU3, HIGHRES_IMU. Units and per-stream scale
overrides: :mod:`companion.sources.decode`; timing rules: :mod:`companion.sources.timestamps`; the tlog
walker: :mod:`companion.sources.tlog`; links: :mod:`companion.sources.connection`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from companion.errors import CompanionError, NoUsableData
from companion.samples import ImuStream
from companion.sources import autopilot_health as _ap
from companion.sources import timestamps as _timing
from companion.sources.kind import decide, kind_of
from companion.sources.decode import (COMPASS_ONLY_CAN, TIME_RESOLUTION, RawStream, ScaleTable,
                                      imu_sample_from_message)

__all__ = ["load", "kind_of", "LoadResult", "ScaleTable", "build_stream", "imu_sample_from_message", "load_config"]


@dataclass
class LoadResult:
    """What a source held: IMU streams in SI and the frame totals."""

    source: str
    streams: list[ImuStream]
    totals: dict = field(default_factory=dict)  # frames, bad_bytes, bad_frames, imu_messages
    messages: dict = field(default_factory=dict)  # message name -> valid frames (tlog / live)
    # log metadata where the format has it (DataFlash, ULog, tlog): params {name: value}, armed [(t_s, bool)],
    # has_armed_state, modes [(t_s, number)], messages [(t_s, text)], format, extra per-format keys (a tlog:
    # identity, armed_source [{sysid, compid, heartbeats, clock}]; no format key: MAVLink rules are the default)
    meta: dict = field(default_factory=dict)

    def imu_streams(self) -> list[ImuStream]:
        return [s for s in self.streams if s.is_imu]


def load_config(config) -> dict:
    """``config`` as a dict: None, a dict, or a path to a YAML file (checked: :func:`companion.config.load`)."""
    from companion.config import load

    return load(config)


def build_stream(raw: RawStream, split_periods: float = _timing.SPLIT_PERIODS) -> ImuStream:
    """Apply the timing rules to decoded samples: drop duplicates/backward steps, segment, report.

    A sample with a non-finite time, an infinite value, or a NaN gyro value in a stream that has gyro data
    comes from a damaged record (a flipped float exponent, a zero integration interval, a burst header with
    no rate): it is dropped before the timing rules and counted in ``timing.damaged``."""
    bad = _damaged_samples(raw)
    if bad is not None:
        raw = RawStream(raw.key, raw.t[~bad], raw.gyro[~bad], raw.accel[~bad],
                        None if raw.temperature is None else raw.temperature[~bad], raw.is_imu,
                        raw.gyro_lsb, raw.accel_lsb, raw.time_resolution, raw.notes)
    keep, segments, report = _timing.analyse(raw.t, raw.time_resolution, split_periods)
    report.damaged = 0 if bad is None else int(bad.sum())
    all_kept = bool(keep.all())

    def k(a):
        return a if (a is None or all_kept) else a[keep]

    return ImuStream(key=raw.key, t=k(raw.t), gyro=k(raw.gyro), accel=k(raw.accel),
                     temperature=k(raw.temperature), is_imu=raw.is_imu, segments=segments, timing=report,
                     gyro_lsb=raw.gyro_lsb, accel_lsb=raw.accel_lsb)


def _damaged_samples(raw: RawStream) -> np.ndarray | None:
    """Mask of the samples of damaged records (see :func:`build_stream`), None when there are none."""
    if (np.isfinite(raw.t).all() and np.isfinite(raw.gyro).all() and not np.isinf(raw.accel).any()
            and (raw.temperature is None or not np.isinf(raw.temperature).any())):
        return None  # the usual case, tested whole (row-wise tests cost more than the timing rules)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(raw.t)
        bad |= np.isinf(raw.gyro).any(axis=1) | np.isinf(raw.accel).any(axis=1)
        if raw.temperature is not None:
            bad |= np.isinf(raw.temperature)
        nan_gyro = np.isnan(raw.gyro).any(axis=1)
        if not nan_gyro.all():  # a stream without gyro data (an accel-only burst) has NaN there by design
            bad |= nan_gyro
    return bad if bad.any() else None


def _check_has_imu(res: LoadResult, require_imu: bool) -> LoadResult:
    if require_imu and not res.imu_streams():
        if res.streams:
            what = ", ".join(s.key.label() for s in res.streams)
            raise NoUsableData(f"{res.source}: no IMU data (only compass-only streams: {what})")
        fmt = (res.meta or {}).get("format")
        wanted = {"dataflash": "IMU, IMU2, IMU3, ISBH/ISBD", "ulog": "sensor_combined, sensor_gyro, vehicle_imu",
                  "csv": "gyro rows"}.get(fmt, "RAW_IMU, SCALED_IMU*, HIGHRES_IMU")
        raise NoUsableData(f"{res.source}: no IMU messages ({wanted}) in {res.totals.get('frames', 0)} valid "
                             f"{'messages' if fmt in ('dataflash', 'ulog') else 'frames'}")
    return res


def load_tlog(path, config=None, split_periods: float = _timing.SPLIT_PERIODS) -> LoadResult:
    from companion.sources import tlog
    from companion.sources.decode import decode_index

    path = Path(path)
    data = tlog.read_file(path)
    index = tlog.scan(data)
    raws = decode_index(index, ScaleTable(load_config(config)))
    streams = sorted((build_stream(r, split_periods) for r in raws), key=lambda s: s.key)
    totals = {"frames": index.frames, "bad_bytes": index.bad_bytes, "bad_frames": index.bad_frames,
              "imu_messages": int(sum(r.t.shape[0] for r in raws))}
    meta = {"identity": tlog.identity(index), "params": tlog.param_values(index)}
    # the armed state of the systems whose IMUs are analysed (their autopilots' HEARTBEATs, on the IMU clock)
    meta.update(tlog.armed_state(index, [s.key for s in streams if s.is_imu and s.samples]))
    meta["autopilot"] = _ap.safe_view("tlog", _ap.from_tlog, index, [s.key for s in streams if s.is_imu and s.samples])
    return LoadResult(str(path), streams, totals, dict(index.counts), meta)


def load_csv(path, split_periods: float = _timing.SPLIT_PERIODS, time_unit: str | None = None) -> LoadResult:
    from companion.sources.csvfile import read_csv

    raw = read_csv(path, time_unit)
    n = raw.t.shape[0]
    return LoadResult(str(path), [build_stream(raw, split_periods)],
                      {"frames": n, "bad_bytes": 0, "bad_frames": 0, "imu_messages": n}, {"CSV": n},
                      {"format": "csv", "notes": list(raw.notes)})


def load_dataflash(path, split_periods: float = _timing.SPLIT_PERIODS) -> LoadResult:
    """An ArduPilot DataFlash .bin (or .bin.gz): every IMU instance, batch-sampler bursts, metadata."""
    from companion.sources import dataflash as df
    from companion.sources.dataflash_imu import imu_raw_streams, isb_raw_streams
    from companion.sources.dataflash_meta import log_identity, log_metadata

    log = df.open_log(path)
    raws, extras = imu_raw_streams(log)
    meta = log_metadata(log)
    isb, bursts = isb_raw_streams(log, meta["params"], len({r.key.instance for r in raws}) or None)
    streams = sorted((build_stream(r, split_periods) for r in raws + isb), key=lambda s: s.key)
    counts = log.counts()
    imu_n = int(sum(r.t.shape[0] for r in raws))
    totals = {"frames": int(sum(counts.values())), "bad_bytes": int(log.bad_bytes), "bad_frames": 0,
              "imu_messages": imu_n}
    meta["format"] = "dataflash"
    meta["identity"] = log_identity(log, meta)
    meta["isb_bursts"] = bursts
    meta["autopilot"] = _ap.safe_view("dataflash", _ap.from_dataflash, log)
    meta["imu_extras"] = {k.instance: {n: int(np.nansum(v)) if n.endswith("errors") else None
                                       for n, v in e.items()} for k, e in extras.items()}
    meta["notes"] = []
    name = Path(str(path)).name
    if log.truncated:
        meta["notes"].append(f"{name}: the file ends inside a message (truncated log: its last "
                             f"{log.truncated} bytes are an incomplete message, skipped)")
    if log.bad_bytes - log.truncated > 0:
        meta["notes"].append(f"{name}: {log.bad_bytes - log.truncated} bytes outside valid messages skipped "
                             "(corrupt blocks or headers of undefined message types)")
    if log.text_lines_skipped:
        meta["notes"].append(f"{name}: {log.text_lines_skipped} line(s) of the text log fit no FMT layout, skipped")
    meta["notes"] += [f"{name}: {text}" for text in log.implausible]
    for mname, why in sorted(log.damaged.items()):
        meta["notes"].append(f"{name}: message {mname} not read, its FMT record is damaged: {why}")
    totals["damaged_types"] = len(log.damaged)
    return LoadResult(str(path), streams, totals, counts, meta)


def load_ulog(path, split_periods: float = _timing.SPLIT_PERIODS) -> LoadResult:
    """A PX4 ULog .ulg (or .ulg.gz) through pyulog: IMU topics per multi_id, armed state, parameters."""
    from companion.sources import ulog as ul

    u = ul.open_ulog(path)
    with np.errstate(all="ignore"):  # casts of a damaged topic's fields: the values are checked in build_stream
        raws, counts = ul.raw_streams(u)
    streams = sorted((build_stream(r, split_periods) for r in raws), key=lambda s: s.key)
    totals = {"frames": int(sum(counts.values())), "bad_bytes": 0, "bad_frames": 0,
              "imu_messages": int(sum(r.t.shape[0] for r in raws))}
    meta = ul.metadata(u)
    meta["format"] = "ulog"
    meta["identity"] = ul.identity(u, meta)
    meta["autopilot"] = _ap.safe_view("ulog", _ap.from_ulog, u)
    name = Path(str(path)).name
    notes = []
    if getattr(u, "companion_truncated", 0):
        notes.append(f"{name}: the file ends inside a message (truncated log: its last "
                     f"{u.companion_truncated} bytes are an incomplete message, skipped)")
    warned = getattr(u, "companion_warnings", [])
    if warned:
        notes.append(f"{name}: pyulog reported {len(warned)} problem(s) with the file, e.g. \"{warned[0][:120]}\" "
                     "(damaged data skipped)")
    notes += [f"{name}: {d}" for d in getattr(u, "companion_damaged", [])]
    if meta.get("damaged_params"):
        notes.append(f"{name}: {meta['damaged_params']} parameter(s) of a non-numeric type skipped (damaged definition)")
    totals["reader_warnings"] = len(warned)
    meta["notes"] = notes
    return LoadResult(str(path), streams, totals, counts, meta)


def load_live(spec: str, duration: float, config=None, baud=None, split_periods: float = _timing.SPLIT_PERIODS,
              clock=time.monotonic) -> LoadResult:
    """Listen to a link for ``duration`` seconds and return what arrived (message timestamps, not arrival)."""
    from companion.sources.connection import open_connection

    if not duration or duration <= 0:
        raise CompanionError("a live source needs --duration SECONDS > 0")
    scales = ScaleTable(load_config(config))
    conn = open_connection(spec, baud=baud)
    acc: dict = {}
    counts: dict = {}
    bad = 0
    health = _ap.LinkHealth()  # the autopilot's SYS_STATUS and VIBRATION, as they come
    end = clock() + float(duration)
    try:
        while True:
            left = end - clock()
            if left <= 0:
                break
            msg = conn.recv_match(blocking=True, timeout=min(left, 0.5))
            if msg is None:
                continue
            name = msg.get_type()
            if name == "BAD_DATA":
                bad += 1
                continue
            counts[name] = counts.get(name, 0) + 1
            _ap.on_link_message(health, msg, acc)
            s = imu_sample_from_message(msg, scales)
            if s is None:
                continue
            acc.setdefault(s.key, []).append((s.t_s, *s.gyro, *s.accel, s.temperature))
    finally:
        conn.close()
    raws = []
    for key, rows in acc.items():
        a = np.array([r[:7] for r in rows], dtype=np.float64)
        temp = np.array([np.nan if r[7] is None else r[7] for r in rows])
        gs, as_ = scales.lookup(key) if key.message != "HIGHRES_IMU" else (None, None)
        is_imu = not (key.message in COMPASS_ONLY_CAN and not np.any(a[:, 1:7]))
        raws.append(RawStream(key, a[:, 0], a[:, 1:4], a[:, 4:7],
                              None if np.all(np.isnan(temp)) else np.nan_to_num(temp),
                              is_imu, gs, as_, TIME_RESOLUTION[key.message]))
    streams = sorted((build_stream(r, split_periods) for r in raws), key=lambda s: s.key)
    totals = {"frames": int(sum(counts.values())), "bad_bytes": 0, "bad_frames": bad,
              "imu_messages": int(sum(len(v) for v in acc.values()))}
    view = health.view(sorted({s.key.instance for s in streams if s.is_imu}))
    return LoadResult(str(spec), streams, totals, counts, {"autopilot": view} if view is not None else {})


def load(spec, config=None, *, duration: float | None = None, baud: int | None = None,
         require_imu: bool = True, split_periods: float = _timing.SPLIT_PERIODS,
         time_unit: str | None = None) -> LoadResult:
    """Load IMU streams from ``spec``: a ``.tlog``, an ArduPilot DataFlash ``.bin``, a PX4 ``.ulg``, a
    ``.csv`` file (each may be gzip-compressed, ``.gz``), or a connection string (listened to for
    ``duration`` seconds). Log metadata (parameters, armed state, modes) is in ``LoadResult.meta``.

    ``config``: None, a dict (the whole configuration; its ``streams:`` list overrides scales) or a
    YAML path. ``require_imu``: raise :class:`CompanionError` when no stream is an IMU. ``time_unit``
    ("s", "ms", "us"): the unit of a CSV's time column (default: seconds, ms/us refused). A log spanning
    reboots has its boot sessions laid end to end (:func:`companion.sources.sessions.join_sessions`).
    Any user-caused problem raises :class:`CompanionError` (one line).
    """
    from companion.sources.connection import parse_connection, unknown_file

    s = str(spec)
    decision = decide(s)
    kind = decision.kind
    if kind == "csv":
        res = load_csv(s, split_periods, time_unit)
    elif kind == "tlog":
        res = load_tlog(s, config, split_periods)
    elif kind == "dataflash":
        res = load_dataflash(s, split_periods)
    elif kind == "ulog":
        res = load_ulog(s, split_periods)
    elif kind == "connection":
        parse_connection(s, baud)  # validate before anything else
        res = load_live(s, duration or 0.0, config, baud, split_periods)
    elif Path(s).is_file():
        raise CompanionError(unknown_file(s))
    else:
        parse_connection(s, baud)  # raises the 'unknown source' error
        raise CompanionError(f"{s}: unknown source")  # pragma: no cover - parse_connection raised
    if decision.note:
        res.meta.setdefault("notes", []).insert(0, decision.note)
    from companion.sources.sessions import join_sessions

    return join_sessions(_check_has_imu(res, require_imu))
