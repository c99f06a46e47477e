"""The IMU streams of an ArduPilot DataFlash log (:mod:`companion.sources.dataflash`): every IMU instance of
the three logged layouts and the batch sampler's bursts, as :class:`companion.sources.decode.RawStream`.

IMU layouts (all produce :class:`companion.samples.ImuStream`, message ``IMU``, instance 0, 1, 2):

- 2014-16 (Copter 3.2-3.3): ``IMU``, ``IMU2``, ``IMU3`` with ``TimeMS`` (ms), ``ErrG/ErrA/Temp``;
- 3.4-3.6: the same three messages with ``TimeUS``;
- 4.x: one ``IMU`` with the instance field ``I``, ``TimeUS``, ``T``, ``EG/EA``, ``GH/AH``.

Batch sampler (``INS_LOG_BAT_*``): an ``ISBH`` header (``type`` 0 accel / 1 gyro, ``instance``, ``mul``,
``smp_cnt``, ``SampleUS`` of the first sample, ``smp_rate``) followed by ``ISBD`` messages (``N`` = the
header's sequence number, ``seqno``, ``x/y/z`` int16[32]: value = int16 / ``mul``, rad/s or m/s^2).
Each (type, instance) becomes its own stream ``ISB_GYRO``/``ISB_ACCEL`` of bursts (sample ``k`` of a
burst at ``SampleUS + k / smp_rate``; the timing rules split the bursts into segments); the other
sensor's columns are NaN. Batches sampled after the autopilot's filters (``INS_LOG_BAT_OPT`` bit 1, or
bit 2: before and after, the post-filter ones numbered from the number of IMUs on) are
``ISB_GYRO_POST``/``ISB_ACCEL_POST`` of their own sensor's instance, never an extra IMU (with two IMUs and
``INS_LOG_BAT_MASK`` 1 the instances are 0 and 2, 2 being IMU 0 filtered).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.samples import StreamKey
from companion.sources.dataflash import DataFlashLog, int_codes
from companion.sources.decode import RawStream

#: (extra name, the columns that carry it in the old and new layouts): per-sample error counts and health
IMU_EXTRA_COLUMNS = (("gyro_errors", ("EG", "ErrG")), ("accel_errors", ("EA", "ErrA")), ("gyro_healthy", ("GH",)),
                     ("accel_healthy", ("AH",)), ("gyro_rate_hz", ("GHz",)), ("accel_rate_hz", ("AHz",)))
#: message names of the old layouts and the instance each stands for (the 4.x ``IMU`` carries ``I``)
IMU_MESSAGES = (("IMU", 0), ("IMU2", 1), ("IMU3", 2))
ISB_SAMPLES_PER_MESSAGE = 32  #: an ``ISBD`` message carries int16[32] per axis
ISB_TYPE_GYRO = 1  #: ``ISBH.type`` of a gyro batch (0: accelerometer)


@dataclass
class _ImuColumns:
    """The decoded columns of one IMU message type (SI units)."""

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    temp: np.ndarray | None
    instance: np.ndarray | None  # the 4.x layout's ``I`` column; None: one instance per message name
    resolution: float  # s: 1e-6 for ``TimeUS``, 1e-3 for ``TimeMS``
    extra: dict[str, np.ndarray]


def _imu_columns(log: DataFlashLog, name: str) -> _ImuColumns:
    rec = log.records(name)
    cols = log.columns(name)
    t = log.time_s(name, rec)
    gyro = np.column_stack([log.values(name, c, rec) for c in ("GyrX", "GyrY", "GyrZ")])
    accel = np.column_stack([log.values(name, c, rec) for c in ("AccX", "AccY", "AccZ")])
    tcol = "T" if "T" in cols else ("Temp" if "Temp" in cols else None)
    temp = log.values(name, tcol, rec) if tcol else None
    inst = int_codes(log.values(name, "I", rec)) if "I" in cols else None
    res = 1e-6 if "TimeUS" in cols else 1e-3
    extra = {}
    for short, names in IMU_EXTRA_COLUMNS:
        c = next((c for c in names if c in cols), None)
        if c:
            extra[short] = log.values(name, c, rec)
    return _ImuColumns(t, gyro, accel, temp, inst, res, extra)


#: ArduPilot logs at most 3 IMUs (INS_MAX_INSTANCES); 0-9 leaves room for boards with more. A larger ``I`` is a
#: damaged record whose bytes still decode (a flipped bit in the instance field), not an IMU
MAX_IMU_INSTANCE = 9
#: an instance with fewer samples than this while another has at least ``PHANTOM_RATIO`` times as many is damaged
#: records: a real IMU is logged at >= 25 Hz from boot to the end of the log, like the others
PHANTOM_SAMPLES = 10
PHANTOM_RATIO = 100


def _real_instances(log: DataFlashLog, name: str, inst: np.ndarray) -> list[int]:
    """The IMU instances of message ``name`` that are IMUs; the records of the others (an instance outside
    0-``MAX_IMU_INSTANCE``, or a few samples beside thousands: :data:`PHANTOM_SAMPLES`) are noise from
    damaged records, skipped and noted in ``log.implausible``."""
    ids, counts = np.unique(inst, return_counts=True)
    most = int(counts.max()) if counts.shape[0] else 0
    keep = []
    for k, n in zip(ids.tolist(), counts.tolist()):
        if not 0 <= k <= MAX_IMU_INSTANCE:
            why = f"instance {k} is outside 0-{MAX_IMU_INSTANCE}"
        elif n < PHANTOM_SAMPLES and most >= PHANTOM_RATIO * n:
            why = f"{n} sample(s) beside {most} of another instance"
        else:
            keep.append(k)
            continue
        log.implausible.append(f"{n} {name} record(s) with instance {k} skipped as damaged records ({why}), "
                               "not an IMU")
    return keep


def imu_raw_streams(log: DataFlashLog):
    """RawStreams of every IMU instance (all three layouts) plus per-instance extras (errors, health)."""
    out, extras = [], {}
    for name, default_inst in IMU_MESSAGES:
        if not log.has(name, "GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ"):
            continue
        if not {"TimeUS", "TimeMS"} & set(log.columns(name)):
            log.damaged.setdefault(name, "no TimeUS/TimeMS column")
            continue
        c = _imu_columns(log, name)
        inst = c.instance if c.instance is not None else np.full(c.t.shape[0], default_inst, dtype=np.int64)
        for k in _real_instances(log, name, inst):
            sel = inst == k
            key = StreamKey(0, 0, "IMU", int(k))
            out.append(RawStream(key, c.t[sel], c.gyro[sel], c.accel[sel], None if c.temp is None else c.temp[sel],
                                 True, None, None, c.resolution))
            extras[key] = {k2: v[sel] for k2, v in c.extra.items()}
    return out, extras


#: INS_LOG_BAT_OPT bits: 1 the batches are sampled after the filters; 2 before and after, the post-filter
#: batches written with the instance plus the number of gyros (a 2-IMU log's instance 2 is IMU 0 filtered)
BAT_OPT_POST, BAT_OPT_PRE_POST = 2, 4


def isb_name(is_gyro: bool, instance: int, opt: int, n_imu: int) -> tuple[str, int]:
    """(message, instance) of a batch: ``ISB_GYRO``/``ISB_ACCEL`` of the raw sensor, ``..._POST`` after the
    filters (``opt``: INS_LOG_BAT_OPT; with pre and post, an instance from ``n_imu`` on is the post-filter
    batch of instance - ``n_imu``)."""
    post = bool(opt & BAT_OPT_POST) or (bool(opt & BAT_OPT_PRE_POST) and instance >= n_imu)
    if opt & BAT_OPT_PRE_POST and instance >= n_imu:
        instance -= n_imu
    return ("ISB_GYRO" if is_gyro else "ISB_ACCEL") + ("_POST" if post else ""), instance


def bat_opt(params: dict | None) -> int:
    """INS_LOG_BAT_OPT from the log's parameters; 0 where absent or damaged (nan, inf, not a number)."""
    try:
        return int(float((params or {}).get("INS_LOG_BAT_OPT", 0)))
    except (TypeError, ValueError, OverflowError):
        return 0


@dataclass
class _Burst:
    """One ``ISBH`` header's samples: times (s), values (SI) and the header's multiplier."""

    sensor: tuple[int, int]  # (type, instance) of the header
    t: np.ndarray
    values: np.ndarray
    mul: float
    expected: int  # the header's ``smp_cnt``
    rate_hz: float
    t0: float

    def summary(self) -> dict:
        return {"type": self.sensor[0], "instance": self.sensor[1], "samples": int(self.t.shape[0]),
                "expected": self.expected, "rate_hz": self.rate_hz, "t0": self.t0, "mul": self.mul}


@dataclass
class _IsbTables:
    """The batch sampler's header values and data messages, with the file offsets that pair them."""

    header: dict[str, np.ndarray]  # ISBH column -> float values
    data: np.ndarray  # ISBD records
    header_n: np.ndarray
    data_n: np.ndarray
    data_seq: np.ndarray
    header_pos: np.ndarray
    data_pos: np.ndarray


def _isb_tables(log: DataFlashLog) -> _IsbTables | None:
    """The ISBH/ISBD messages of the log, or None where it has none (or their layout is damaged)."""
    if not (log.has("ISBH", "N", "type", "instance", "mul", "smp_cnt", "SampleUS", "smp_rate")
            and log.has("ISBD", "N", "seqno", "x", "y", "z")):
        return None
    hdr = log.records("ISBH")
    dat = log.records("ISBD")
    if any(dat.dtype[c].shape != (ISB_SAMPLES_PER_MESSAGE,) for c in "xyz"):
        log.damaged.setdefault("ISBD", f"x/y/z are not int16[32] ({dat.shape[0]} messages skipped)")
        return None
    hv = {c: log.values("ISBH", c, hdr) for c in ("N", "type", "instance", "mul", "smp_cnt", "SampleUS",
                                                  "smp_rate")}
    return _IsbTables(hv, dat, int_codes(hv["N"]), int_codes(log.values("ISBD", "N", dat)),
                      int_codes(log.values("ISBD", "seqno", dat)), log.offsets[log.names["ISBH"]][:hdr.shape[0]],
                      log.offsets[log.names["ISBD"]][:dat.shape[0]])


def _burst(tab: _IsbTables, j: int) -> _Burst | None:
    """The samples of header ``j``: its data messages are those after it and before the next header with its
    sequence number ``N`` (which wraps at 65536), ordered by ``seqno``; None when it has none."""
    hv, hpos, dpos = tab.header, tab.header_pos, tab.data_pos
    nxt_h = hpos[j + 1] if j + 1 < hpos.shape[0] else np.iinfo(np.int64).max
    sel = (dpos > hpos[j]) & (dpos < nxt_h) & (tab.data_n == tab.header_n[j])
    d = tab.data[sel]
    if d.shape[0] == 0:
        return None
    o = np.argsort(tab.data_seq[sel], kind="stable")
    d, seq = d[o], tab.data_seq[sel][o]
    vals = np.stack([d["x"].reshape(-1), d["y"].reshape(-1), d["z"].reshape(-1)], axis=1).astype(np.float64)
    idx = (seq[:, None] * ISB_SAMPLES_PER_MESSAGE + np.arange(ISB_SAMPLES_PER_MESSAGE)).reshape(-1)
    cnt = int(int_codes(hv["smp_cnt"][j:j + 1])[0])
    keep = idx < cnt if cnt > 0 else np.ones(idx.shape[0], bool)
    vals, idx = vals[keep], idx[keep]
    mul = float(hv["mul"][j])
    mul = mul if np.isfinite(mul) and mul != 0 else 1.0
    rate = float(hv["smp_rate"][j])
    t0 = float(hv["SampleUS"][j]) * 1e-6
    t = t0 + idx / rate if rate > 0 and np.isfinite(rate) else np.full(idx.shape[0], np.nan)
    sensor = (int(int_codes(hv["type"][j:j + 1])[0]), int(int_codes(hv["instance"][j:j + 1])[0]))
    return _Burst(sensor, t, vals / mul, mul, cnt, rate, t0)


def isb_raw_streams(log: DataFlashLog, params: dict | None = None, imu_instances: int | None = None):
    """Batch-sampler bursts (ISBH/ISBD) as one RawStream per (sensor type, instance). With ``params``
    (the log's PARM) the post-filter batches (``INS_LOG_BAT_OPT``) are ``ISB_GYRO_POST``/``ISB_ACCEL_POST``
    of their sensor's instance (``imu_instances``: the number of IMUs, for the pre+post numbering).
    Returns (streams, one summary dict per burst)."""
    tab = _isb_tables(log)
    if tab is None:
        return [], []
    bursts = [b for b in (_burst(tab, j) for j in range(tab.header_pos.shape[0])) if b is not None]
    per: dict[tuple[int, int], list[_Burst]] = {}
    for b in bursts:
        per.setdefault(b.sensor, []).append(b)
    opt = bat_opt(params)
    n_imu = imu_instances or (max(i for _, i in per) // 2 + 1 if per else 1)
    out = []
    for (typ, inst), parts in sorted(per.items()):
        t = np.concatenate([p.t for p in parts])
        v = np.concatenate([p.values for p in parts])
        nan = np.full_like(v, np.nan)
        is_gyro = typ == ISB_TYPE_GYRO
        key = StreamKey(0, 0, *isb_name(is_gyro, inst, opt, n_imu))
        lsb = 1.0 / parts[0].mul
        out.append(RawStream(key, t, v if is_gyro else nan, nan if is_gyro else v, None, True,
                             lsb if is_gyro else None, None if is_gyro else lsb, 1e-6))
    return out, [b.summary() for b in bursts]
