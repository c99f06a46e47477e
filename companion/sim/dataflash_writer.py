"""A small ArduPilot DataFlash ``.bin`` writer for tests and simulations (numpy, vectorised).

It writes self-describing logs (FMT messages first) in the three IMU layouts the reader handles:

- ``"2015"``: ``IMU``/``IMU2``/``IMU3`` with ``TimeMS`` (uint32 ms), ``ErrG``, ``ErrA``, ``Temp`` (Copter 3.3);
- ``"3.4"``: the same three messages with ``TimeUS`` (uint64 us);
- ``"4.x"``: one ``IMU`` message with instance field ``I`` (``TimeUS``, ``T``, ``EG``, ``EA``, ``GH``, ``AH``).

plus ``PARM``, ``EV`` (armed 10 / disarmed 11), ``MODE`` and ``MSG``. Messages are written in time
order, as a logger would. Only for tests and examples: real logs carry many more message types.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

HEAD = b"\xa3\x95"  #: every DataFlash message starts with these two bytes
FMT_TYPE = 128  #: the FMT message's own type id (it describes every other type)

_NP = {"b": "i1", "B": "u1", "h": "<i2", "H": "<u2", "i": "<i4", "I": "<u4", "f": "<f4", "d": "<f8",
       "n": "S4", "N": "S16", "Z": "S64", "q": "<i8", "Q": "<u8", "M": "i1", "c": "<i2", "C": "<u2",
       "e": "<i4", "E": "<u4"}

IMU_LAYOUTS = ("2015", "3.4", "4.x")


class _Type:
    def __init__(self, type_id, name, fmt, columns):
        self.id, self.name, self.fmt, self.columns = type_id, name, fmt, columns.split(",")
        self.dtype = np.dtype([("h", "S2"), ("t", "u1")] + [(c, _NP[ch]) for c, ch in zip(self.columns, fmt)])
        self.length = self.dtype.itemsize

    def fmt_bytes(self) -> bytes:
        return HEAD + bytes([FMT_TYPE]) + struct.pack("<BB4s16s64s", self.id, self.length, self.name.encode(),
                                                      self.fmt.encode(), ",".join(self.columns).encode())


def _fmt_fmt() -> bytes:
    return HEAD + bytes([FMT_TYPE]) + struct.pack("<BB4s16s64s", FMT_TYPE, 89, b"FMT", b"BBnNZ",
                                                  b"Type,Length,Name,Format,Columns")


@dataclass
class _Layout:
    """The message types of one log: its time column (ms or us ticks) and each IMU's message name."""

    types: dict
    imu_names: list
    tcol: str
    scale: float  # ticks per second

    def record(self, name: str, tt: float, *vals) -> np.ndarray:
        """One message ``name`` at ``tt`` s since boot with the values of its columns after the time, as bytes."""
        ty = self.types[name]
        rec = np.zeros(1, dtype=ty.dtype)
        rec["h"], rec["t"] = HEAD, ty.id
        rec[self.tcol] = int(round(tt * self.scale))
        for c, v in zip(ty.columns[1:], vals):
            rec[c] = v
        return rec.view(np.uint8).reshape(1, -1)


@dataclass
class _Row:
    """A non-IMU message placed at a time; ``rank`` orders messages of the same tick (before the IMU's 10)."""

    t: float
    rank: int
    blob: np.ndarray


IMU_RANK = 10  #: IMU samples sort after every other message of the same tick (parameters, events, modes, GPS)


def write_imu_log(path, t_s, gyro, accel, layout: str = "4.x", params: dict | None = None,
                  armed: list[tuple[float, bool]] | None = None, modes: list[tuple[float, int]] | None = None,
                  temperature: float = 40.0, messages: list[str] | None = None,
                  gps_utc: tuple[float, float] | None = None) -> int:
    """Write a DataFlash log: ``t_s`` (n,) seconds since boot; ``gyro``, ``accel`` (k, n, 3) per IMU.

    ``temperature``: degC, one value or (k, n) per IMU and sample (a simulated warm-up,
    :attr:`companion.sim.vehicle.VehicleBlock.temperature`).
    Returns the number of bytes written. Parameters, armed transitions and mode changes are placed at
    their times (parameters and messages at the start). ``gps_utc`` = (t since boot, unix time then): one
    ``GPS`` record with a 3D fix and that time as GPS week and ms of week (4.x layout only).
    """
    if layout not in IMU_LAYOUTS:
        raise ValueError(f"layout must be one of {IMU_LAYOUTS}")
    t_s = np.asarray(t_s, dtype=np.float64)
    gyro = np.asarray(gyro, dtype=np.float64)
    accel = np.asarray(accel, dtype=np.float64)
    if gyro.ndim == 2:
        gyro, accel = gyro[None], accel[None]
    if gps_utc is not None and layout == "2015":
        raise ValueError("gps_utc is written in the 4.x layout only")
    lay = _layout(layout, gyro.shape[0], gps_utc is not None)
    tick = np.round(t_s * lay.scale).astype(np.int64)
    imu = _imu_rows(lay, layout, tick, gyro, accel, temperature)
    t0 = float(t_s[0]) if gyro.shape[1] else 0.0
    small = _event_rows(lay, t0, params, messages, armed, modes, gps_utc)
    head = _fmt_fmt() + b"".join(ty.fmt_bytes() for ty in lay.types.values())
    out = head + _merged(lay, tick, gyro.shape[0], imu, small)
    with open(path, "wb") as fh:
        fh.write(out)
    return len(out)


def _layout(layout: str, k: int, gps: bool) -> _Layout:
    ms = layout == "2015"
    tcol, tch = ("TimeMS", "I") if ms else ("TimeUS", "Q")
    types = {"PARM": _Type(64, "PARM", tch + "Nf", f"{tcol},Name,Value"),
             "EV": _Type(65, "EV", tch + "B", f"{tcol},Id"),
             "MODE": _Type(66, "MODE", tch + "MB", f"{tcol},Mode,ModeNum"),
             "MSG": _Type(67, "MSG", tch + "Z", f"{tcol},Message")}
    if gps:
        types["GPS"] = _Type(68, "GPS", "QBBIH", "TimeUS,I,Status,GMS,GWk")
    if layout == "4.x":
        types["IMU"] = _Type(70, "IMU", "QBffffffIIfBB", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH")
        imu_names = ["IMU"] * k
    else:
        cols = f"{tcol},GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp"
        imu_names = ["IMU", "IMU2", "IMU3"][:k]
        for i, nm in enumerate(imu_names):
            types[nm] = _Type(70 + i, nm, tch + "ffffffIIf", cols)
    return _Layout(types, imu_names, tcol, 1e3 if ms else 1e6)


def _imu_rows(lay: _Layout, layout: str, tick, gyro, accel, temperature) -> np.ndarray:
    """(n k, record length) bytes: the IMUs interleaved sample by sample (IMU, IMU2, IMU3, IMU, ...), as the
    logger writes them."""
    k, n = gyro.shape[0], gyro.shape[1]
    recs = []
    for i in range(k):
        ty = lay.types[lay.imu_names[i]]
        rec = np.zeros(n, dtype=ty.dtype)
        rec["h"], rec["t"] = HEAD, ty.id
        rec[lay.tcol] = tick
        for j, c in enumerate(("GyrX", "GyrY", "GyrZ")):
            rec[c] = gyro[i, :, j]
        for j, c in enumerate(("AccX", "AccY", "AccZ")):
            rec[c] = accel[i, :, j]
        tmp = np.asarray(temperature, dtype=float)
        tmp = tmp[i] if tmp.ndim == 2 else tmp  # (k, n) per IMU and sample, or one value
        if layout == "4.x":
            rec["I"], rec["T"], rec["GH"], rec["AH"] = i, tmp, 1, 1
        else:
            rec["Temp"] = tmp
        recs.append(rec.view(np.uint8).reshape(n, -1))
    return np.stack(recs, axis=1).reshape(n * k, -1)


def _event_rows(lay: _Layout, t0: float, params, messages, armed, modes, gps_utc) -> list[_Row]:
    """Parameters and messages at the first sample, armed events and mode changes at their times, the GPS fix."""
    small = [_Row(t0, 0, lay.record("PARM", t0, nm.encode()[:16], float(v))) for nm, v in (params or {}).items()]
    small += [_Row(t0, 1, lay.record("MSG", t0, m.encode()[:64])) for m in messages or []]
    small += [_Row(tt, 2, lay.record("EV", tt, 10 if a else 11)) for tt, a in armed or []]
    small += [_Row(tt, 3, lay.record("MODE", tt, mnum, mnum)) for tt, mnum in modes or []]
    if gps_utc is not None:
        from companion.sources.dataflash_meta import GPS_EPOCH_UNIX, GPS_LEAP_S

        tt, unix = gps_utc
        gps = unix + next(v for t_from, v in GPS_LEAP_S if unix >= t_from) - GPS_EPOCH_UNIX
        week, sow = divmod(gps, 604800.0)
        small.append(_Row(tt, 4, lay.record("GPS", tt, 0, 3, int(round(sow * 1e3)), int(week))))
    return small


def _merged(lay: _Layout, tick, k: int, imu: np.ndarray, small: list[_Row]) -> bytes:
    """Every record by time (stable: small messages before IMU samples of the same tick), joined."""
    all_t = np.concatenate([np.repeat(tick, k)] + [np.array([int(round(r.t * lay.scale))]) for r in small])
    all_o = np.concatenate([np.full(imu.shape[0], IMU_RANK)] + [np.array([r.rank]) for r in small])
    blobs = [imu] + [r.blob for r in small]
    src = np.concatenate([np.full(b.shape[0], i) for i, b in enumerate(blobs)])
    row = np.concatenate([np.arange(b.shape[0]) for b in blobs])
    order = np.lexsort((all_o, all_t))
    # group consecutive rows from the same blob to keep the join fast
    s_ord, r_ord = src[order], row[order]
    brk = np.flatnonzero((np.diff(s_ord) != 0) | (np.diff(r_ord) != 1)) + 1
    starts = np.r_[0, brk]
    ends = np.r_[brk, order.shape[0]]
    return b"".join(blobs[s_ord[a]][r_ord[a]:r_ord[b - 1] + 1].tobytes() for a, b in zip(starts, ends))
