"""Fast, robust tlog frame walker: every CRC-valid MAVLink 1/2 frame, garbage counted, numpy only.

A tlog is ``[8-byte big-endian unix usec][MAVLink frame]`` repeated (../shared/REFERENCE.md). pymavlink
reads it byte by byte and, after garbage between records, can lose sync for a long stretch (on a tlog
with a 1-40 byte garbage run every 500 records it returns 13,776 of 60,000 RAW_IMU messages). This
walker does not follow a chain, so it cannot lose sync:

1. candidates: every byte 0xFD (v2) or 0xFE (v1) at offset >= 8 (room for the record's time stamp);
2. implied frame: header (6 or 10 bytes), payload length byte, message id, incompat flags (v2: only
   0x00 or 0x01 = signed, which adds a 13-byte signature); the frame must fit in the file and its
   id must be known (CRC_EXTRA from :mod:`companion.sources.messages`);
3. CRC-16/MCRF4XX of bytes [1, header + len) + CRC_EXTRA, vectorised per (header, length) group,
   column by column over a 2-D byte array (:func:`messages.crc_x25_rows`); compared with the
   frame's two little-endian CRC bytes. Pass 1 checks the candidates whose implied end is followed
   by another record's magic byte 8 bytes later (or the end of the file): in a clean tlog, all real
   frames. Pass 2 checks the remaining candidates unless their record would start inside a frame
   pass 1 accepted (such a candidate would be dropped in step 4 anyway), so magic-valued bytes
   inside payloads cost no CRC;
4. overlaps: valid candidates are taken in file order and a record ``[p-8, p+frame_len)`` that starts
   before the end of the last accepted one is dropped (a magic byte inside a payload that happens to
   pass the CRC, probability 2^-16). Runs where nothing overlaps are accepted in bulk; only the rare
   clusters go through a Python loop.

Counted: ``frames`` (accepted), ``bad_bytes`` (file bytes not in an accepted record), ``bad_frames``
(candidates with a plausible header -- known id, fits -- whose CRC fails and which do not lie inside an
accepted record: frames corrupted in transit or sent with another definition of the message, which
is what pymavlink reports as BAD_DATA "invalid MAVLink CRC").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from companion.errors import CompanionError
from companion.sources.kind import opens_as_gzip
from companion.sources import messages as M


@dataclass
class FrameIndex:
    """Accepted frames of a tlog, in file order (all arrays have one entry per frame)."""

    buf: np.ndarray  # the whole file, uint8
    pos: np.ndarray  # int64 offset of the magic byte
    header_len: np.ndarray  # int64: 6 (v1) or 10 (v2)
    length: np.ndarray  # int64 payload length on the wire (v2 may be truncated)
    msgid: np.ndarray  # int64
    sysid: np.ndarray  # uint8
    compid: np.ndarray  # uint8
    stamp_us: np.ndarray  # uint64 record time stamp (unix usec, low 2 bits may hold a link number)
    bad_bytes: int = 0
    bad_frames: int = 0
    candidates: int = 0
    counts: dict = field(default_factory=dict)  # message name -> frames

    @property
    def frames(self) -> int:
        return int(self.pos.shape[0])

    def payloads(self, sel: np.ndarray, width: int) -> np.ndarray:
        """(len(sel), width) uint8 payloads of frames ``sel``, zero-padded (MAVLink 2 truncation) or cut."""
        out = np.zeros((sel.shape[0], width), dtype=np.uint8)
        start = self.pos[sel] + self.header_len[sel]
        length = np.minimum(self.length[sel], width)
        for ln in np.unique(length):
            rows = np.flatnonzero(length == ln)
            if ln == 0:
                continue
            out[rows, :ln] = _windows(self.buf, int(ln))[start[rows]]
        return out


def _windows(buf: np.ndarray, width: int) -> np.ndarray:
    if buf.shape[0] < width:
        return np.zeros((0, width), dtype=np.uint8)
    return sliding_window_view(buf, width)


def _crc_ok(buf: np.ndarray, pos: np.ndarray, hl: int, ln: int, extra: np.ndarray,
            chunk: int = 65536) -> np.ndarray:
    """CRC check of frames at ``pos`` (all with header ``hl`` and payload ``ln``)."""
    ok = np.empty(pos.shape[0], dtype=bool)
    win = _windows(buf, hl - 1 + ln)
    crc_lo = pos + hl + ln
    for s in range(0, pos.shape[0], chunk):
        p = pos[s:s + chunk]
        rows = win[p + 1]  # bytes after the magic up to the end of the payload
        crc = M.crc_x25_rows(rows, extra[s:s + chunk])
        stored = buf[crc_lo[s:s + chunk]].astype(np.uint16) | (buf[crc_lo[s:s + chunk] + 1].astype(np.uint16) << 8)
        ok[s:s + chunk] = crc == stored
    return ok


_EXTRA_PADDED = np.r_[M.CRC_EXTRA_TABLE, -1].astype(np.int32)  # index MAX_MSGID + 1: unknown


def _crc_groups(buf, p, hl, ln, extra) -> np.ndarray:
    """CRC validity of candidates, grouped by (header length, payload length)."""
    ok = np.zeros(p.shape[0], dtype=bool)
    if p.shape[0] == 0:
        return ok
    key = hl * 256 + ln
    order = np.argsort(key, kind="stable")
    bounds = np.flatnonzero(np.diff(key[order])) + 1
    for grp in np.split(order, bounds):
        ok[grp] = _crc_ok(buf, p[grp], int(hl[grp[0]]), int(ln[grp[0]]), extra[grp].astype(np.uint16))
    return ok


@dataclass
class _Candidates:
    """Plausible frame starts (known id, the frame fits in the file), one entry per candidate."""

    p: np.ndarray  # offset of the magic byte
    hl: np.ndarray  # header length
    ln: np.ndarray  # payload length
    msgid: np.ndarray
    flen: np.ndarray  # whole frame length (header, payload, CRC, signature)
    extra: np.ndarray  # CRC_EXTRA of the id


def _candidates(buf: np.ndarray, bufp: np.ndarray) -> _Candidates:
    """Steps 1-2 of the module docstring: every magic byte whose implied frame is plausible."""
    n = buf.shape[0]
    p = np.flatnonzero(buf[8:] >= M.MAGIC_V2) + 8 if n > 8 else np.zeros(0, np.int64)
    magic = buf[p]
    keep = magic != 0xFF  # 0xFD (v2) or 0xFE (v1)
    p, magic = p[keep], magic[keep]
    v2 = (magic == M.MAGIC_V2).astype(np.int64)
    hl = M.HEADER_V1 + 4 * v2
    ln = bufp[p + 1].astype(np.int64)
    # v1 id at p+5; v2 id (3 bytes, little-endian) at p+7
    msgid = (bufp[p + 5 + 2 * v2].astype(np.int64)
             | ((bufp[p + 8].astype(np.int64) << 8 | bufp[p + 9].astype(np.int64) << 16) * v2))
    incompat = bufp[p + 2].astype(np.int64) * v2
    flen = hl + ln + 2 + M.SIGNATURE_LEN * (incompat & M.IFLAG_SIGNED)
    extra = _EXTRA_PADDED[np.minimum(msgid, M.MAX_MSGID + 1)]
    plausible = (p + flen <= n) & (extra >= 0) & (incompat <= M.IFLAG_SIGNED)
    return _Candidates(*(a[plausible] for a in (p, hl, ln, msgid, flen, extra)))


def _crc_passes(buf: np.ndarray, bufp: np.ndarray, c: _Candidates) -> tuple[np.ndarray, np.ndarray]:
    """Step 3: (CRC valid, skipped: inside a pass-1 frame's record, never checked) per candidate."""
    n = buf.shape[0]
    p, flen = c.p, c.flen
    # pass 1: candidates followed by the next record's magic byte (or the end of the file): the chain
    nxt = p + flen + 8
    after = bufp[np.minimum(nxt, n + 299)]
    chain = (p + flen == n) | ((nxt < n) & (after >= M.MAGIC_V2) & (after <= M.MAGIC_V1))
    ok = np.zeros(p.shape[0], dtype=bool)
    first = np.flatnonzero(chain)
    ok[first] = _crc_groups(buf, p[first], c.hl[first], c.ln[first], c.extra[first])
    # pass 2: the others (frames before garbage, garbage itself), unless inside a pass-1 frame's record
    rest = np.flatnonzero(~chain)
    skipped = np.zeros(p.shape[0], dtype=bool)
    good1 = first[ok[first]]
    if rest.shape[0] and good1.shape[0]:
        cm_end = np.maximum.accumulate(p[good1] + flen[good1])
        j = np.searchsorted(p[good1], p[rest], side="left") - 1
        inside = (j >= 0) & (p[rest] - 8 < cm_end[np.maximum(j, 0)])
        skipped[rest[inside]] = True
        rest = rest[~inside]
    ok[rest] = _crc_groups(buf, p[rest], c.hl[rest], c.ln[rest], c.extra[rest])
    return ok, skipped


def _no_overlap(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Step 4: which of the CRC-valid records ``[start, end)`` (file order) are kept: a record that starts
    before the end of the last kept one is dropped. Runs that overlap nothing are kept in bulk."""
    keep = np.ones(start.shape[0], dtype=bool)
    if start.shape[0] > 1:
        prev_max = np.maximum.accumulate(end)[:-1]
        clean = np.r_[True, start[1:] >= prev_max]  # starts a run that overlaps nothing before it
        if not clean.all():
            run_start = np.flatnonzero(clean)
            sizes = np.diff(np.r_[run_start, start.shape[0]])
            for r in np.flatnonzero(sizes > 1):
                last_end = -1
                for i in range(run_start[r], run_start[r] + sizes[r]):
                    if start[i] >= last_end:
                        last_end = end[i]
                    else:
                        keep[i] = False
    return keep


def scan(data) -> FrameIndex:
    """Index every intact frame of tlog bytes ``data`` (bytes, bytearray, memoryview or uint8 array)."""
    buf = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    n = buf.shape[0]
    # a zero-padded copy: header and "next record" lookups never need bounds checks
    bufp = np.zeros(n + 300, dtype=np.uint8)
    bufp[:n] = buf
    c = _candidates(buf, bufp)
    ok, skipped = _crc_passes(buf, bufp, c)
    keep = _no_overlap(c.p[ok] - 8, c.p[ok] + c.flen[ok])
    acc = np.flatnonzero(ok)[keep]
    pos, hlen, length, mid = c.p[acc], c.hl[acc], c.ln[acc], c.msgid[acc]
    acc_start, acc_end = pos - 8, pos + c.flen[acc]

    # bad frames: plausible headers failing the CRC that are not inside an accepted record
    bad = c.p[~ok & ~skipped]
    if bad.shape[0] and pos.shape[0]:
        j = np.searchsorted(acc_start, bad, side="right") - 1
        inside = (j >= 0) & (bad < acc_end[np.maximum(j, 0)])
        bad = bad[~inside]
    covered = int((acc_end - acc_start).sum())

    stamps = _windows(buf, 8)[acc_start] if pos.shape[0] else np.zeros((0, 8), np.uint8)
    stamp_us = np.ascontiguousarray(stamps).view(">u8").reshape(-1).astype(np.uint64)
    v2a = hlen == M.HEADER_V2
    sysid = np.where(v2a, buf[pos + 5], buf[pos + 3])
    compid = np.where(v2a, buf[pos + 6], buf[pos + 4])
    ids, cnt = np.unique(mid, return_counts=True)
    counts = {M.MSG_NAMES.get(int(i), str(int(i))): int(k) for i, k in zip(ids, cnt)}
    return FrameIndex(buf=buf, pos=pos, header_len=hlen, length=length, msgid=mid, sysid=sysid,
                      compid=compid, stamp_us=stamp_us, bad_bytes=n - covered,
                      bad_frames=int(bad.shape[0]), candidates=int(c.p.shape[0]), counts=counts)


def read_file(path) -> bytes:
    """The bytes of a tlog file; a missing or unreadable file is a one-line :class:`CompanionError`."""
    import gzip
    import zlib

    try:
        if opens_as_gzip(path):
            with gzip.open(path, "rb") as fh:
                return fh.read()
        with open(path, "rb") as fh:
            return fh.read()
    except (gzip.BadGzipFile, zlib.error, EOFError) as exc:
        raise CompanionError(f"{path}: not a readable gzip file ({exc})") from None
    except FileNotFoundError:
        raise CompanionError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise CompanionError(f"{path}: is a directory, expected a .tlog file") from None
    except OSError as exc:
        raise CompanionError(f"{path}: cannot read ({exc.strerror or exc})") from None


# --------------------------------------------------------------------------------------------------
# identity: which board sent the log, its gyro ids, and when it started

AUTOPILOT_VERSION_ID = 148  #: MAVLink id of AUTOPILOT_VERSION (its ``uid`` names the board)
PARAM_VALUE_ID = 22  #: MAVLink id of PARAM_VALUE (the gyro device ids)
#: ArduPilot gyro device-id parameters and the IMU instance each names
GYRO_ID_PARAMS = M.ARDUPILOT_GYRO_ID_PARAMS
_UNIX_US = (1e15, 4.1e15)  # 2001..2099 in unix microseconds: a plausible tlog record stamp


def identity(idx: FrameIndex) -> dict:
    """``{"board_id": hex or None, "board": None, "imu_ids": {instance: int}, "start_time": unix s or None,
    "board_by_sysid": {sysid: hex}}`` of an indexed tlog.

    ``AUTOPILOT_VERSION.uid`` is the board's 64-bit unique id (0 = not provided); ``PARAM_VALUE`` of
    ``INS_GYR_ID``/``INS_GYR2_ID``/``INS_GYR3_ID`` are ArduPilot's gyro device ids of IMU 0, 1, 2 (the
    integer sent as a float, exact below 2^24); the start time is the first record's time stamp (unix
    microseconds; its low 2 bits may hold a link number, irrelevant here)."""
    out = {"board_id": None, "board": None, "imu_ids": {}, "start_time": None, "board_by_sysid": {}}
    if idx.frames:
        stamps = idx.stamp_us.astype(np.float64)
        good = stamps[(stamps > _UNIX_US[0]) & (stamps < _UNIX_US[1])]
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
    for name, v in param_values(idx).items():
        inst = GYRO_ID_PARAMS.get(name)
        if inst is not None and v != 0:
            out["imu_ids"][inst] = int(round(v))
    return out


def param_values(idx: FrameIndex) -> dict[str, float]:
    """{name: value} of the tlog's PARAM_VALUE messages (the last finite value of each name; the value is a
    float on the wire, integers below 2^24 exact)."""
    out: dict[str, float] = {}
    sel = np.flatnonzero(idx.msgid == PARAM_VALUE_ID)
    if sel.size:
        pl = idx.payloads(sel, 25)
        names = [bytes(r[8:24]).split(b"\0", 1)[0].decode("ascii", "replace") for r in pl]
        values = pl[:, 0:4].copy().view("<f4").reshape(-1)
        for name, v in zip(names, values):
            if np.isfinite(v):
                out[name] = float(v)
    return out


# --------------------------------------------------------------------------------------------------
# armed state: the vehicle's HEARTBEATs, on its IMU messages' clock

HEARTBEAT_ID = M.HEARTBEAT.msgid
MAV_MODE_FLAG_SAFETY_ARMED = 128  #: the armed bit of HEARTBEAT.base_mode
MAV_AUTOPILOT_INVALID = 8  #: HEARTBEAT.autopilot of a component that is not a flight controller
#: HEARTBEAT types of components that are not a vehicle's autopilot (MAV_TYPE: GCS, onboard controller,
#: gimbal, ADS-B, camera, charging station, FLARM, servo, OpenDroneID, battery, parachute, log, OSD, IMU,
#: GPS, winch, illuminator, gripper). A ground station's HEARTBEAT may carry the armed bit (QGC sends
#: base_mode 192 from sysid 255) and so may a companion computer's (type 18, base_mode 128), neither of
#: which says anything about the vehicle.
NOT_AUTOPILOT_TYPES = frozenset((6, 18, 26, 27, 30, 31, 32, 33, 34, 36, 37, 38, 39, 40, 41, 42, 44, 48))


def vehicle_heartbeats(idx: FrameIndex, sysid: int, compid: int | None = None) -> tuple[np.ndarray, np.ndarray, int | None]:
    """(frame indices, armed flags, component id) of the autopilot HEARTBEATs of system ``sysid``.

    A HEARTBEAT counts when its autopilot is not MAV_AUTOPILOT_INVALID and its type is not in
    :data:`NOT_AUTOPILOT_TYPES`. Where several components of the system send such HEARTBEATs, only one is
    used (two sources of one flag could alternate): ``compid`` (the IMU messages' component) when it sends
    any, else the one that sends the most."""
    sel = np.flatnonzero((idx.msgid == HEARTBEAT_ID) & (idx.sysid == sysid))
    empty = (np.zeros(0, np.int64), np.zeros(0, bool), None)
    if not sel.size:
        return empty
    rec = idx.payloads(sel, M.HEARTBEAT.full_len).view(M.HEARTBEAT.dtype).reshape(-1)
    ok = (rec["autopilot"] != MAV_AUTOPILOT_INVALID) & ~np.isin(rec["type"], list(NOT_AUTOPILOT_TYPES))
    if not ok.any():
        return empty
    comps, counts = np.unique(idx.compid[sel][ok], return_counts=True)
    comp = int(compid) if compid is not None and compid in comps else int(comps[np.argmax(counts)])
    ok &= idx.compid[sel] == comp
    return sel[ok], (rec["base_mode"][ok] & MAV_MODE_FLAG_SAFETY_ARMED) != 0, comp


def imu_clock(idx: FrameIndex, key) -> tuple[np.ndarray, np.ndarray]:
    """(frame indices, message times in s) of the IMU stream ``key`` (a StreamKey), in file order."""
    layout = M.IMU_LAYOUTS[key.message]
    sel = np.flatnonzero((idx.msgid == layout.msgid) & (idx.sysid == key.sysid) & (idx.compid == key.compid))
    if not sel.size:
        return sel, np.zeros(0)
    rec = idx.payloads(sel, layout.full_len).view(layout.dtype).reshape(-1)
    if layout.name not in M.FIXED_INSTANCE:
        keep = rec["id"].astype(np.int64) == key.instance
        sel, rec = sel[keep], rec[keep]
    t = (rec["time_usec"].astype(np.float64) * 1e-6 if "time_usec" in rec.dtype.names
         else rec["time_boot_ms"].astype(np.float64) * 1e-3)
    return sel, t


def to_message_time(idx: FrameIndex, frames: np.ndarray, clock_frames: np.ndarray, clock_t: np.ndarray) -> np.ndarray:
    """Message times (the IMU stream's clock) of the frames ``frames``, which carry no time field.

    Each frame takes the IMU message next to it in the file (the one before or after, whichever has the
    closer record stamp) and that message's offset between its own time and its record stamp: t = stamp +
    (t_imu - stamp_imu). The record stamp is when the ground station logged the frame; the offset moves
    only with the link's latency (tens of ms) and jumps at a reboot, where the nearest message is already
    on the new clock. Where either record stamp is not a plausible unix time (a writer that leaves it
    zero), the frame takes the neighbouring message's time as it is."""
    out = np.full(frames.shape[0], np.nan)
    if not frames.size or not clock_frames.size:
        return out
    stamps = idx.stamp_us.astype(np.float64) * 1e-6
    j = np.searchsorted(clock_frames, frames)  # the IMU message after each frame (file order)
    after = np.minimum(j, clock_frames.shape[0] - 1)
    before = np.maximum(j - 1, 0)
    s = stamps[frames]
    sa, sb = stamps[clock_frames[after]], stamps[clock_frames[before]]
    k = np.where(np.abs(sa - s) < np.abs(sb - s), after, before)
    sk = stamps[clock_frames[k]]
    lo, hi = _UNIX_US[0] * 1e-6, _UNIX_US[1] * 1e-6
    plausible = (s > lo) & (s < hi) & (sk > lo) & (sk < hi)
    return clock_t[k] + np.where(plausible, s - sk, 0.0)


def armed_state(idx: FrameIndex, imu_keys) -> dict:
    """Armed state of the systems whose IMU streams ``imu_keys`` (StreamKeys, the analysed IMUs) a tlog holds:
    ``{"armed": [(t_s, armed)], "has_armed_state": bool, "armed_source": [{"sysid", "compid",
    "heartbeats", "clock"}]}``.

    Per system: its autopilot's HEARTBEATs (:func:`vehicle_heartbeats`; other systems are ignored), the
    first one's state and every change (and the state again at each reboot, where the time steps back, so
    that the boot sessions can be laid end to end), each at the time of the first HEARTBEAT that shows it,
    mapped to the clock of that system's IMU stream with the most messages (:func:`to_message_time`): the
    still selection works on message time. A HEARTBEAT comes about once a second, so a change is seen up to
    1 s late; the still selection's guard (3 s) covers that. Several systems: the union of their armed
    periods (the still selection takes every IMU of the log on one time axis)."""
    from companion.sources.sessions import RESET_S

    by_sys: dict = {}
    for key in imu_keys:
        by_sys.setdefault(int(key.sysid), []).append(key)
    per_sys, sources = [], []
    for sysid, keys in sorted(by_sys.items()):
        ref = max((_ImuClock(k, *imu_clock(idx, k)) for k in keys), key=lambda c: c.frames.shape[0])
        frames, armed, comp = vehicle_heartbeats(idx, sysid, ref.key.compid)
        if not frames.size:
            continue
        t = to_message_time(idx, frames, ref.frames, ref.t)
        good = np.isfinite(t)
        t, armed = t[good], armed[good]
        if not t.size:
            continue
        # a change of state, and the first HEARTBEAT after a reboot (its time steps back with the IMU clock):
        # join_sessions finds the boot session of each event by those steps back, in file order, and an
        # arming after a reboot can be later on its clock than every event of the session before
        change = np.r_[True, (armed[1:] != armed[:-1]) | (np.diff(t) < -RESET_S)]
        per_sys.append([(float(a), bool(b)) for a, b in zip(t[change], armed[change])])
        sources.append({"sysid": sysid, "compid": comp, "heartbeats": int(frames.size), "clock": ref.key.label()})
    trans = (per_sys[0] if per_sys else []) if len(per_sys) <= 1 else _union_transitions(per_sys)
    return {"armed": trans, "has_armed_state": bool(per_sys), "armed_source": sources}


@dataclass
class _ImuClock:
    """The frames of one IMU stream and their message times (s): the clock HEARTBEATs are mapped to."""

    key: object  # StreamKey
    frames: np.ndarray
    t: np.ndarray


def _union_transitions(per_sys: list[list[tuple[float, bool]]]) -> list[tuple[float, bool]]:
    """The union of several systems' armed periods, as transitions (disarmed at the earliest first state)."""
    from companion.sources.still import armed_intervals

    iv = sorted(iv for tr in per_sys for iv in armed_intervals(tr, np.inf))  # inf: armed to the end
    merged: list = []
    for a, b in iv:
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    t0 = min(tr[0][0] for tr in per_sys)
    trans = [(t0, False)] if not merged or merged[0][0] > t0 else []
    for a, b in merged:
        trans += [(a, True)] + ([(b, False)] if np.isfinite(b) else [])
    return trans
