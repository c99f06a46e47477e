"""Replay a .tlog through the live pipeline, as fast as it can, in the file's frame order.

Frames are found by the fast walker (:mod:`companion.sources.tlog`) and decoded vectorised with the
same rules as live messages (:mod:`companion.sources.decode`); HEARTBEATs and IMU samples are then
handed to :class:`companion.service.pipeline.Pipeline` in file order as arrays (:func:`feed_in_order`):
every stretch of a stream that closes no block and meets no check goes in one
:meth:`~companion.service.pipeline.Pipeline.on_samples` call, the samples that do (and the HEARTBEATs) at
their place in the file, so the result is the one the live loop would give sample by sample (message time
only: it does not depend on how fast the log was recorded or is replayed).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.sources import messages as M
from companion.sources import tlog
from companion.sources.decode import ScaleTable, split_by_imu
from companion.sources.timestamps import OK, classify_steps, step_rules


def replay_tlog(path, pipeline, scales: ScaleTable | None = None, stop=lambda: False, check=None) -> dict:
    """Feed every HEARTBEAT and IMU sample of ``path`` to ``pipeline``; return counts. ``check(streams)``, when
    given, sees the streams (:func:`best_streams`, timing analysed) before anything is fed; it may raise."""
    path = Path(path)
    data = tlog.read_file(path)
    index = tlog.scan(data)
    scales = scales or ScaleTable()
    _autopilot_view(pipeline, index, scales)
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
        for raw, pos in split_by_imu(layout, rec, index.sysid[sel], index.compid[sel], scales):
            if not raw.is_imu:
                continue
            streams.append(raw)
            order_parts.append(sel[pos])
            srcs.append(np.full(raw.t.shape[0], len(streams) - 1, dtype=np.int64))
            rows.append(np.arange(raw.t.shape[0]))
    if check is not None:
        from companion.sources import build_stream

        check(best_streams([build_stream(raw) for raw in streams]))
    frame = np.concatenate(order_parts)
    src = np.concatenate(srcs)
    row = np.concatenate(rows)
    order = np.argsort(frame, kind="stable")

    def heartbeat(j):
        r = hb_rec[j]
        pipeline.on_heartbeat(int(index.sysid[hb[j]]), int(r["type"]), int(r["autopilot"]), int(r["base_mode"]))

    # the filter parameters the tlog carries (PARAM_VALUE): the estimators model the low-pass cut-off
    pipeline.set_params(tlog.param_values(index), None)
    used = feed_in_order(pipeline, streams, order, src, row, heartbeat, stop)
    pipeline.raise_if_failed()
    return {"frames": index.frames, "bad_frames": index.bad_frames, "bad_bytes": index.bad_bytes,
            "heartbeats": int(hb.size), "imu_samples": int(sum(s.t.shape[0] for s in streams)), "used": int(used)}


@dataclass
class StreamFeed:
    """One stream's samples in feed order: their event positions, rows, the samples that must go alone
    (``irregular``: positions in these arrays) and how far it has been fed (``cur``)."""

    key: object
    pos: np.ndarray  # event position (rank in the feed order) of each sample
    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    temp: np.ndarray | None
    irregular: np.ndarray
    cur: int = 0

    @property
    def done(self) -> bool:
        return self.cur >= self.pos.size

    def quiet_end(self, pipeline) -> int:
        """The index up to which the samples from ``cur`` on close no block and meet no check, and are
        regular steps: they may go in one call."""
        c, irr = self.cur, self.irregular
        i_irr = irr[np.searchsorted(irr, c)] if irr.size and irr[-1] >= c else self.pos.size
        stop_at = min(int(i_irr), self.pos.size)
        return c + pipeline.quiet_run(self.key, self.t[c:stop_at]) if stop_at > c else c

    def feed(self, pipeline, e: int, tick: bool = True) -> int:
        """Samples ``cur`` .. ``e`` to the pipeline in one call; returns the number used."""
        c = self.cur
        self.cur = e
        return pipeline.on_samples(self.key, self.t[c:e], self.gyro[c:e], self.accel[c:e], tick=tick,
                                   temperature=None if self.temp is None else self.temp[c:e])


def _stream_feeds(pipeline, streams, rank, src, row) -> list[StreamFeed]:
    rules = step_rules(0.0, reset_s=pipeline.cfg.reset_s, gap_s=pipeline.cfg.gap_s)  # the block cutter's
    feeds = []
    for k, s in enumerate(streams):
        sel = np.flatnonzero(src == k)
        pos = rank[sel]
        o = np.argsort(pos, kind="stable")
        pos, r = pos[o], row[sel][o]
        t = np.asarray(s.t, dtype=float)[r]
        temp = getattr(s, "temperature", None)
        # a sample that is not a clean step under the block cutter's rules (and the one after it) goes alone
        bad = np.flatnonzero(classify_steps(t, None, rules)[1:] != OK) + 1
        feeds.append(StreamFeed(s.key, pos, t, np.asarray(s.gyro, dtype=float)[r], np.asarray(s.accel, dtype=float)[r],
                                None if temp is None else np.asarray(temp, dtype=float)[r],
                                np.unique(np.concatenate([bad, bad + 1]))))
    return feeds


def _feed_quiet(pipeline, feeds: list[StreamFeed], barrier: int, ends: list[int]) -> int:
    """Every stream's quiet samples before ``barrier``, stream by stream; the reporter's clock over them in
    file order. Returns the samples used."""
    used = 0
    ticks_pos, ticks_t = [], []
    for f, end in zip(feeds, ends):
        c = f.cur
        e = min(end, int(np.searchsorted(f.pos, barrier)))
        if e > c:
            u = f.feed(pipeline, e, tick=False)
            used += u
            if u:
                ticks_pos.append(f.pos[c:e])
                ticks_t.append(f.t[c:e])
    if len(ticks_t) == 1:
        pipeline.tick(ticks_t[0])
    elif ticks_t:
        pipeline.tick(np.concatenate(ticks_t)[np.argsort(np.concatenate(ticks_pos), kind="stable")])
    return used


def feed_in_order(pipeline, streams, order, src, row, heartbeat, stop=lambda: False) -> int:
    """Feed events in the order ``order`` (indices into ``src`` / ``row``: ``src`` -1 a HEARTBEAT, handed to
    ``heartbeat(row)``, else sample ``row`` of ``streams[src]``) as arrays: each stream's samples up to the
    next one that closes a block or falls due for a check (``Pipeline.quiet_run``), up to the next
    HEARTBEAT, go at once; that sample or HEARTBEAT then alone, at its place. Nothing but the one-sample
    events reads another stream's state, so the result is that of feeding every event one by one.
    Returns the samples used."""
    rank = np.empty(order.shape[0], dtype=np.int64)
    rank[order] = np.arange(order.shape[0])
    hb_pos = np.sort(rank[src < 0])
    hb_row = row[order[hb_pos]] if hb_pos.size else hb_pos
    feeds = _stream_feeds(pipeline, streams, rank, src, row)
    h = 0
    used = 0
    n_events = order.shape[0]
    while not stop():
        # the next position where something happens that others may see
        barrier = int(hb_pos[h]) if h < hb_pos.size else n_events
        ends = []
        for f in feeds:
            q = f.cur if f.done else f.quiet_end(pipeline)
            ends.append(q)
            if q < f.pos.size:
                barrier = min(barrier, int(f.pos[q]))
        used += _feed_quiet(pipeline, feeds, barrier, ends)
        if barrier >= n_events:
            break
        if h < hb_pos.size and hb_pos[h] == barrier:
            heartbeat(int(hb_row[h]))
            h += 1
            continue
        for f in feeds:
            if not f.done and f.pos[f.cur] == barrier:
                used += f.feed(pipeline, f.cur + 1)
                break
        if pipeline.failed:
            break
    return used


MAV_MODE_FLAG_SAFETY_ARMED = 128  # HEARTBEAT base_mode bit of an armed vehicle (MAVLink common.xml)
_AUTOPILOT = {"dataflash": 3, "ulog": 12}  # MAV_AUTOPILOT_ARDUPILOTMEGA, MAV_AUTOPILOT_PX4; else GENERIC (0)


def is_replay_source(spec) -> bool:
    """True for a file ``companion run --source`` replays: a log by its name (.tlog/.tlog.bin/.mavlink,
    DataFlash .bin, .ulg, .csv; each optionally .gz) or an existing file whose content is a log whatever its
    name (a Mission Planner text .log, say: :func:`companion.sources.kind_of` decides, the one rule)."""
    from companion.sources.kind import FILE_KINDS, file_kind, kind_of

    # by name first: a log named so is replayed (and its reader says what is wrong with it) without reading it
    return file_kind(spec) is not None or kind_of(spec) in FILE_KINDS


def replay_log(path, pipeline, stop=lambda: False, time_unit: str | None = None, check=None) -> dict:
    """Feed a DataFlash .bin, a ULog .ulg or a CSV file to ``pipeline`` in message-time order.

    Per IMU instance the stream with the most samples is replayed (a ULog holds sensor_combined,
    sensor_gyro and vehicle_imu of the same IMU). A DataFlash log's batch-sampler bursts (ISB_*) are not
    replayed: a kHz burst of a second every few seconds is no stream for the blocks of a live monitor (the
    bursts outnumber the IMU messages: chosen, they would give no block and leave the IMU unwatched); ``analyze``
    reads them.
    The log's armed state becomes a HEARTBEAT (base_mode armed flag) at every transition and once a
    second, exactly as a live vehicle sends them; a source without armed state sends none.
    ``check(streams)``, when given, sees the streams to be replayed before anything is fed; it may raise.
    """
    from companion.sources import load

    res = load(path, time_unit=time_unit)  # time_unit: of a CSV's time column
    pipeline.autopilot_view = res.meta.get("autopilot")  # the autopilot's own IMU health, for the summary
    streams = replayed_streams(res)
    if check is not None:
        check(streams)
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

    def heartbeat(j):
        pipeline.on_heartbeat(sysid, 2, autopilot, MAV_MODE_FLAG_SAFETY_ARMED if hb_armed[j] else 0)

    # the log's filter parameters (INS_GYRO_FILTER, IMU_GYRO_CUTOFF): the estimators model the low-pass
    # cut-off, as `companion analyze` does for the same log
    pipeline.set_params(res.meta.get("params"), res.meta.get("format"))
    used = feed_in_order(pipeline, streams, order, kind, rows, heartbeat, stop)
    pipeline.raise_if_failed()
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
            pipeline.on_samples(key, blk.t, g, blk.accel[i],
                                temperature=None if blk.temperature is None else blk.temperature[i])
        fed += blk.n
        if on_chunk is not None and on_chunk(float(blk.t[-1])):
            break
    return fed


def _autopilot_view(pipeline, index, scales) -> None:
    """The tlog's SYS_STATUS and VIBRATION (the autopilot's own IMU health), for the summary."""
    from companion.sources.autopilot_health import from_tlog, safe_view

    keys = []
    for msgid, layout in M.IMU_BY_ID.items():
        sel = np.flatnonzero(index.msgid == msgid)
        if sel.size:
            rec = index.payloads(sel, layout.full_len).view(layout.dtype).reshape(-1)
            keys += [raw.key for raw, _ in split_by_imu(layout, rec, index.sysid[sel], index.compid[sel], scales)
                     if raw.is_imu]
    pipeline.autopilot_view = safe_view("tlog", from_tlog, index, keys)


def replayed_streams(res) -> list:
    """The IMU streams a replay of the loaded log ``res`` feeds (:func:`best_streams`)."""
    return best_streams(res.imu_streams())


def best_streams(streams) -> list:
    """Of IMU ``streams``, per instance the one with the most samples, no batch-sampler bursts (ISB_*), none
    whose first gyro value is missing (also what a restored state is checked against)."""
    best: dict = {}
    for s in streams:
        if not np.all(np.isfinite(s.gyro[:1])) or s.key.message.startswith("ISB_"):
            continue
        cur = best.get(s.key.instance)
        if cur is None or s.samples > cur.samples:
            best[s.key.instance] = s
    return [best[k] for k in sorted(best)]
