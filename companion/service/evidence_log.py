"""The evidence of every alarm ``run`` raises: the data around it, kept with the state.

For each IMU the log keeps, in message time, the last ``2 * WINDOW_S`` of its gyro (min/max per
``BUCKET_S`` bucket, so a spike or a plateau survives the decimation), every detector's statistic after each
block (:mod:`companion.health.evidence_data`) and the last ``SPECTRUM_S`` of raw samples. An alarm (a fault
event, or the Allan check turning to degrading) opens an item: its sentence, the spectrum of the alarm
IMU's last ``SPECTRUM_S`` (taken at the next block, which holds the alarm's data), and once ``WINDOW_S``
more of message time has passed (or the run ends) the gyro of the alarm IMU and of its twins and the
statistic against its threshold over the minute before and after. The newest ``MAX_KEPT`` items are kept;
a series holds at most ``2 * WINDOW_S / BUCKET_S`` buckets. The item schema: docs/reports.md.

The alarms of the sample-level frozen watch (service/frozen_hook.py) show its count of equal pairs while
moving (``frozen/axis``); those of the in-flight noise test (service/inflight_report.py, kinds
``flight_noise`` and ``ground_noise``) the change of the IMU's pair figures from their baseline.
"""

from __future__ import annotations

import math
import time
from collections import deque
from typing import Callable, Mapping

import numpy as np

from companion.health.evidence_data import (ALARM_BAR, STAT_NAMES, allan_statistics, frozen_statistics,
                                            imu_statistics, minmax_buckets, pair_statistics, psd_two_sided, sentence)
from companion.health.hold import FAULT

WINDOW_S = 60.0  #: s of message time kept before and after an alarm
BUCKET_S = 0.5  #: s per min/max bucket: at most 240 points per series over the two minutes
SPECTRUM_S = 8.0  #: s of raw samples whose Welch PSD is the alarm's spectrum
MAX_KEPT = 20  #: alarms whose evidence is kept (the newest)
PUBLISH_S = 0.5  #: wall-clock s between two snapshots handed to a live page


def _r(v) -> list:
    """Floats rounded to 5 significant digits, nan/inf as None (valid JSON for a browser)."""
    return [float(f"{x:.5g}") if math.isfinite(x) else None for x in np.asarray(v, dtype=float).ravel()]


def _mark_trips(stats: dict, prev: Mapping) -> None:
    """A statistic whose detector raised its alarm in this block is shown at its bar at least: a CUSUM starts
    its evidence afresh at the alarm (health.faults.Cusum), so the value after the block no longer shows what
    passed the bar."""
    for key, (v, h, s) in stats.items():
        if s == 1 and prev.get(key, (0.0, 0.0, 0))[2] == 0:
            bar = ALARM_BAR.get(key.split("/")[0], h)
            stats[key] = (max(v, bar) if math.isfinite(v) else bar, h, s)


def inflight_statistics(report, imu: int) -> dict[str, tuple[float, float, int]]:
    """The in-flight test's latest change of ``imu``'s pair figures from their baseline per condition and axis
    (service.inflight_report.InflightReport): the largest |Z| of its pairs' changes (in standard deviations, a
    fall counted as a rise) against the test's threshold, which names the IMU after ``hold_on`` checks in a
    row above it; keyed ``flight_noise/axis`` and ``ground_noise/axis``."""
    noise = getattr(report, "noise", None)
    if noise is None or not noise.pairs:
        return {}
    bar = float(noise.z_on())
    out = {}
    for cond, zs in noise.last_z.items():
        for ax in ("gx", "gy", "gz"):
            rs = [abs(z) for (k, a), z in zs.items() if a == ax and imu in k and math.isfinite(z)]
            if rs:
                out[f"{cond}_noise/{ax}"] = (max(rs), bar, int((cond, imu, ax) in noise.named))
    return out


class ImuRing:
    """The recent data of one IMU: gyro buckets, detector statistics per block, raw samples."""

    def __init__(self):
        self.buckets: deque = deque()  # (bucket index (m,), lo (m, 3), hi (m, 3)) per block
        self.stats: deque = deque()  # (t_end, {key: (value, threshold, state)}) per block
        self.raw: deque = deque()  # (t (n,), gyro (n, 3)) per block
        self.rate_hz = math.nan

    def add(self, data: np.ndarray, stats: dict, rate_hz) -> None:
        t = data[:, 0]
        self.buckets.append(minmax_buckets(t, data[:, 1:4], BUCKET_S))
        self.stats.append((float(t[-1]), stats))
        self.raw.append((t.copy(), data[:, 1:4].copy()))
        self.rate_hz = float(rate_hz) if rate_hz else math.nan
        keep = float(t[-1]) - 2.0 * WINDOW_S - 5.0
        while self.buckets and self.buckets[0][0].size and self.buckets[0][0][-1] * BUCKET_S < keep:
            self.buckets.popleft()
        while self.stats and self.stats[0][0] < keep:
            self.stats.popleft()
        while self.raw and self.raw[0][0][-1] < float(t[-1]) - SPECTRUM_S:
            self.raw.popleft()

    def series(self, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if not self.buckets:
            return np.empty(0), np.empty((0, 3)), np.empty((0, 3))
        k = np.concatenate([b[0] for b in self.buckets])
        lo = np.concatenate([b[1] for b in self.buckets])
        hi = np.concatenate([b[2] for b in self.buckets])
        tc = (k + 0.5) * BUCKET_S
        m = (tc >= t0) & (tc <= t1)
        # a bucket across two blocks is one bucket
        k, lo, hi = minmax_buckets(tc[m], lo[m], BUCKET_S, hi[m])
        return (k + 0.5) * BUCKET_S, lo, hi

    def spectrum(self) -> dict | None:
        if not self.raw or not math.isfinite(self.rate_hz):
            return None
        t = np.concatenate([r[0] for r in self.raw])
        y = np.concatenate([r[1] for r in self.raw])
        f, p = psd_two_sided(y, self.rate_hz)
        if f.size < 2:
            return None
        return {"t0_s": float(t[0]), "t1_s": float(t[-1]), "f_hz": _r(f[1:]), "unit": "(rad/s)^2/Hz",
                "two_sided": True, "psd": {ax: _r(p[1:, j]) for j, ax in enumerate(("gx", "gy", "gz"))}}


class EvidenceLog:
    """Kept by the pipeline; fed by its hooks (:meth:`on_block`, :meth:`on_alarm`, :meth:`on_check`)."""

    def __init__(self):
        self.rings: dict[int, ImuRing] = {}
        self.pending: list[dict] = []
        self.items: list[dict] = []
        self.terms: dict[int, dict] = {}  # IMU -> axis -> the terms reported at the last check (the live page)
        self.publish: Callable[[dict], None] | None = None  # the live page's receiver of snapshots
        self._last_pub = -math.inf
        self.from_watch = None  # the event the frozen watch is saying (service/frozen_hook.py)

    # ------------------------------------------------------------------ hooks
    def on_block(self, pipeline, ch, data: np.ndarray) -> None:
        """A closed block of IMU ``ch`` (after its detectors ran): recorded; items waiting for it completed."""
        if data.shape[0] < 2:
            return
        st = ch.last_stats
        stats = imu_statistics(ch.faults, getattr(st, "top", None))
        stats.update(pair_statistics(pipeline.group.pairs, ch.imu))
        stats.update(allan_statistics(ch.allan.detector, ch.allan.detector.cfg.ratio_on))
        stats.update(frozen_statistics(getattr(pipeline, "frozen", None), ch.imu))
        stats.update(inflight_statistics(getattr(pipeline, "inflight", None), ch.imu))
        ring = self.rings.setdefault(ch.imu, ImuRing())
        _mark_trips(stats, ring.stats[-1][1] if ring.stats else {})
        ring.add(data, stats, ch.rate_hz)
        t = float(data[-1, 0])
        for item in list(self.pending):
            if item["imu"] != ch.imu:
                continue
            if item["spectrum"] is None and not item.get("_spectrum_tried"):
                item["spectrum"] = ring.spectrum()
                item["_spectrum_tried"] = True
            if t >= item["t_s"] + WINDOW_S:
                self._complete(item, True)
        if self.publish is not None and time.monotonic() - self._last_pub >= PUBLISH_S:
            self.publish_now(pipeline)

    def publish_now(self, pipeline) -> None:
        from companion.service.live_snapshot import snapshot

        self._last_pub = time.monotonic()
        self.publish(snapshot(pipeline))

    def on_alarm(self, pipeline, imu: int, axis: str, kind: str, value: float, detail: str, text: str,
                 t: float, stat: str | None = None) -> None:
        """An alarm at message time ``t``: an item opened (one per IMU, axis and kind while it waits).
        ``stat``: the statistic shown when not the kind's own (``frozen``: the sample-level watch's)."""
        if any(p["imu"] == imu and p["axis"] == axis and p["kind"] == kind for p in self.pending):
            return
        stat = stat or ("stuck" if kind == "dead" else kind)
        if stat == "frozen" and kind == "dead":
            value = 0.0
        key = f"{stat}/{axis}"
        ring = self.rings.get(imu)
        last = ring.stats[-1][1].get(key) if ring and ring.stats else None
        threshold = ALARM_BAR.get(stat, last[1] if last else math.nan)
        name, unit = STAT_NAMES.get(stat, (kind, ""))
        self.pending.append({
            "source": "run", "imu": int(imu), "axis": axis, "kind": kind,
            "t_s": float(t), "text": text, "value": value if math.isfinite(value) else None,
            "sentence": sentence("frozen" if stat == "frozen" else kind, imu, axis, value, detail, threshold),
            "window_s": [float(t) - WINDOW_S, float(t) + WINDOW_S], "series": [],
            "statistic": {"name": name, "unit": unit, "key": key, "t_s": [], "value": [], "threshold": [],
                          "state": []},
            "spectrum": None, "complete": False})

    def on_fault_event(self, pipeline, ev, t: float) -> None:
        if ev.state == FAULT:
            frozen = ev is self.from_watch
            self.on_alarm(pipeline, ev.imu, ev.axis, ev.kind, ev.value, ev.detail, ev.text(), t,
                          "frozen" if frozen else None)

    def on_inflight(self, pipeline, verdict, t: float) -> None:
        """A change named by the in-flight noise test (service/inflight_live.py): an item when it turns bad."""
        if verdict.state == 1:
            self.on_alarm(pipeline, verdict.who, verdict.axis, f"{verdict.cond}_noise", verdict.ratio,
                          verdict.cond, verdict.text(), t)

    def on_check(self, pipeline, ch, reported: Mapping, transitions, t: float) -> None:
        """A check: the terms reported (the live page), and an alarm per axis turning degrading."""
        if reported:
            self.terms[ch.imu] = {ax: list(v) for ax, v in reported.items()}
        for tr in transitions:
            if tr.state == 1 and tr.axis in ("gx", "gy", "gz"):
                self.on_alarm(pipeline, tr.imu, tr.axis, "allan", tr.ratio, f"{tr.param} {tr.ratio:.1f}x baseline",
                              tr.text(), t)

    def finish(self) -> None:
        """The run ends: items still waiting are completed with what there is."""
        for item in list(self.pending):
            self._complete(item, False)

    # ------------------------------------------------------------------ items
    def _fill(self, item: dict) -> dict:
        t0, t1 = item["window_s"]
        out = dict(item, series=[])
        for imu, ring in sorted(self.rings.items()):
            tc, lo, hi = ring.series(t0, t1)
            if tc.size == 0:
                continue
            out["series"].append({"imu": imu, "role": "alarm" if imu == item["imu"] else "twin", "unit": "rad/s",
                                  "t_s": _r(tc), "lo": {ax: _r(lo[:, j]) for j, ax in enumerate(("gx", "gy", "gz"))},
                                  "hi": {ax: _r(hi[:, j]) for j, ax in enumerate(("gx", "gy", "gz"))}})
        ring = self.rings.get(item["imu"])
        stat = dict(item["statistic"], t_s=[], value=[], threshold=[], state=[])
        for t, stats in (ring.stats if ring else ()):
            v = stats.get(stat["key"])
            if v is None or not (t0 <= t <= t1):
                continue
            stat["t_s"].append(t)
            stat["value"].append(v[0])
            stat["threshold"].append(v[1])
            stat["state"].append(v[2])
        out["statistic"] = dict(stat, t_s=_r(stat["t_s"]), value=_r(stat["value"]), threshold=_r(stat["threshold"]))
        out.pop("_spectrum_tried", None)
        return out

    def _complete(self, item: dict, full: bool) -> None:
        """``full``: the minute after the alarm is in (False: the run ended first)."""
        self.pending.remove(item)
        done = self._fill(item)
        done["complete"] = full
        self.items.append(done)
        del self.items[:-MAX_KEPT]

    def all_items(self) -> list[dict]:
        """Every kept item, the waiting ones filled with the data so far (oldest first)."""
        return (self.items + [self._fill(p) for p in self.pending])[-MAX_KEPT:]

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> list[dict]:
        return self.all_items()

    def load_state_dict(self, items) -> None:
        self.items = [dict(i) for i in (items or []) if isinstance(i, Mapping) and "kind" in i][-MAX_KEPT:]
