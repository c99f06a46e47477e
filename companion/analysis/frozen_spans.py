"""A whole log's gyros that hold one value while the vehicle moves (or, for a gyro that resolves its own noise,
at rest): the sample-level test that ``companion run`` uses (health/frozen_watch.py), run offline over the log.

The log's IMU streams (one per IMU instance: the one covering the most time) are handed to one
:class:`~companion.health.frozen_watch.FrozenWatch` in ``CHUNK_S`` pieces in message-time order, as the live
loop hands them, and its dead/stuck events become spans: from the first sample of the frozen run (the
run of equal values that was named) to the sample that cleared it, or the end of the stream. The watch names a
frozen axis only on evidence a live gyro does not give (another IMU's same axis moving by 50 steps while this
one repeats its value, the accelerometer turning while all three axes repeat theirs): a gyro frozen in flight
is named whatever the rate and message, where the whole-log rules (health/dead.py, health/log_faults.py) see
only a gyro that never changes or a float gyro's improbable run.

An axis that reads one value over the whole log is left to health/dead.py (named there, compass-only
instances included)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CHUNK_S = 10.0  # seconds of every IMU handed to the watch before each judge (the live loop's block closes)


@dataclass
class FrozenSpan:
    sysid: int
    compid: int
    instance: int
    label: str  # the stream's label, e.g. "SCALED_IMU2[1] sys1/comp1"
    axis: str  # "gx", "gy", "gz"
    kind: str  # "dead" (exactly 0) or "stuck"
    value: float  # rad/s, the value it held
    t0: float  # s: the first sample of the frozen run
    t1: float  # s: the sample that cleared it, or the stream's last
    cleared: bool

    def text(self) -> str:
        what = "reads exactly 0 (dead)" if self.kind == "dead" else f"stuck at {self.value:.6g} rad/s"
        until = f"{self.t1:.0f} s" if self.cleared else f"{self.t1:.0f} s (the end of its record)"
        return (f"{self.label}: gyro {self.axis[1].upper()} frozen: {what} from {self.t0:.0f} to {until} "
                "while the vehicle moved (another IMU's gyro or the accelerometers changed where it held its value)")


def _stream_per_instance(streams) -> dict:
    """{(sysid, compid, instance): stream}: the IMU stream of each instance that covers the most time."""
    best: dict = {}
    for s in streams:
        if not getattr(s, "is_imu", True) or s.gyro is None or s.samples < 2:
            continue
        k = (s.key.sysid, s.key.compid, s.key.instance)
        score = (float(s.timing.duration_s), s.samples)
        if k not in best or score > best[k][0]:
            best[k] = (score, s)
    return {k: v[1] for k, v in best.items()}


def _monotonic(s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, gyro, accel) of the stream where its time only grows (the longest piece when the clock restarts)."""
    t = np.asarray(s.t, dtype=float)
    g = np.asarray(s.gyro, dtype=float)
    a = np.asarray(s.accel, dtype=float) if s.accel is not None else np.zeros_like(g)
    if not (t.shape[0] > 1 and np.all(np.diff(t) > 0)):
        i, j = s.longest_segment()
        t, g, a = t[i:j], g[i:j], a[i:j]
        keep = np.r_[True, np.diff(t) > 0]
        t, g, a = t[keep], g[keep], a[keep]
    return t, g, a


def frozen_spans(streams, axes=("gx", "gy", "gz")) -> list[FrozenSpan]:
    """The frozen spans of every vehicle's gyro ``axes`` in ``streams`` (companion.samples.ImuStream), in time
    order."""
    by_vehicle: dict = {}
    for (sysid, compid, inst), s in _stream_per_instance(streams).items():
        by_vehicle.setdefault((sysid, compid), {})[inst] = s
    out = []
    for members in by_vehicle.values():
        out += _vehicle_spans(members)
    return sorted((sp for sp in out if sp.axis in axes), key=lambda sp: (sp.t0, sp.instance, sp.axis))


def _vehicle_spans(members: dict) -> list[FrozenSpan]:
    from companion.health.frozen_watch import AXES, FrozenWatch
    from companion.health.hold import FAULT

    data = {i: _monotonic(s) for i, s in members.items()}
    data = {i: d for i, d in data.items() if d[0].shape[0] >= 2}
    if not data:
        return []
    lo = min(d[0][0] for d in data.values())
    hi = max(d[0][-1] for d in data.values())
    watch = FrozenWatch()
    events = []
    for a in np.arange(lo, hi + CHUNK_S, CHUNK_S):
        for i, (t, g, acc) in data.items():
            j0, j1 = np.searchsorted(t, [a, a + CHUNK_S])
            if j1 > j0:
                watch.add(i, t[j0:j1], g[j0:j1], acc[j0:j1])
        events += watch.judge()
    spans, open_ = [], {}
    for t_ev, ev in sorted(events, key=lambda te: te[0]):
        key = (ev.imu, ev.axis)
        if ev.state == FAULT:
            open_.setdefault(key, (t_ev, ev))
        elif key in open_:
            spans.append((open_.pop(key), t_ev, True))
    spans += [(v, None, False) for v in open_.values()]
    out = []
    for (t_on, ev), t_off, cleared in spans:
        t, g, _ = data[ev.imu]
        j = AXES.index(ev.axis)
        if np.all(g[:, j] == g[0, j]):  # one value over the whole record: health/dead.py names it
            continue
        k = int(np.searchsorted(t, t_on))
        k = min(k, t.shape[0] - 1)
        start = k
        while start > 0 and g[start - 1, j] == g[k, j]:
            start -= 1
        key = members[ev.imu].key
        out.append(FrozenSpan(key.sysid, key.compid, ev.imu, members[ev.imu].key.label(), ev.axis, ev.kind, float(ev.value),
                              float(t[start]), float(t_off if cleared else t[-1]), cleared))
    return out


def spans_by_instance(spans: list[FrozenSpan]) -> dict:
    """{(sysid, compid, instance): [(t0, t1), ...]} merged per IMU (any axis)."""
    from companion.timespans import merge_intervals

    out: dict = {}
    for sp in spans:
        out.setdefault((sp.sysid, sp.compid, sp.instance), []).append((sp.t0, sp.t1))
    return {i: merge_intervals(iv) for i, iv in out.items()}


def leave_out(spans: list[FrozenSpan], sel, meta: dict) -> None:
    """The IMUs' frozen spans out of their still analysis (``sel``: sources.still.StillSelection, per instance)
    and, through ``meta["frozen"]``, out of the ground and flight figures (analysis/inflight.py)."""
    by_imu = spans_by_instance(spans)
    for (_, _, inst), iv in by_imu.items():
        sel.excluded[inst] = sorted(sel.excluded.get(inst, []) + iv)
    meta["frozen"] = by_imu
