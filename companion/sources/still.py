"""Still-segment selection for post-flight analysis: which parts of a log hold a sensor at rest.

Allan analysis of a flight log must use only the stretches where the vehicle stood still: a flight (or a
hand carrying the vehicle) puts real rotation into the gyro and turns N into junk. :func:`select_still`
decides on a common time grid of ``window_s`` windows (default 1 s; longer when even the fastest IMU stream
is slower than 16 Hz, so that a window holds 16 of its samples):

1. **armed state** from the log (DataFlash ``EV``/``ARM``, ULog ``vehicle_status``, a tlog's vehicle
   HEARTBEATs, :func:`companion.sources.tlog.armed_state`): every armed window,
   widened by ``guard_s`` on each side (motors spin up before take-off and down after landing), is out;
2. **motion** from *every* IMU stream of the log, accelerometer and gyro: per window and axis the standard
   deviation and the mean. The noise floor of each stream is the 10th percentile of its window standard
   deviations (the quietest tenth of the log; of the windows whose values vary at all, at most twice the 5th
   quietest window's for a log that is mostly flight, and at least half an LSB for quantised formats); a
   window moves when, in any IMU,

   - an axis' standard deviation exceeds ``threshold`` x its floor (3x: the spread of a 50-sample
     standard deviation is about 10 %), or exceeds an absolute limit (gyro 0.05 rad/s, accel 0.5 m/s^2:
     no MEMS sensor at rest is that noisy, so a log that is all flight is never called still), or
   - the accelerometer mean moves from the previous window by more than 5 x its standard error + 0.02
     m/s^2 (a slow tilt of ~0.1 deg), or the gyro mean leaves the median of the still windows by more than
     5 x its standard error + 0.005 rad/s (a slow turn);

   moving windows are widened by ``guard_s``. Where two or more IMU instances carry gyros, one instance's
   gyro alone (every accelerometer still, another gyro still that would have seen the same excursion: at
   least twice its own limits) is that gyro's change, not motion: the window stays still for the others and
   is left out of that instance's streams only (:attr:`StillSelection.excluded`, with a note);
3. windows without samples are **gaps**; still runs shorter than ``min_segment_s`` are left out (unless the
   run is the whole record: a short bench recording is still, only short; analyze warns about its length).

``start``/``end`` (seconds, the log's own time) restrict everything; ``use_all`` skips the selection
(the whole record between ``start`` and ``end``, for a user who knows better). The result lists the
still intervals and what was left out (flight/motion, gaps, short stretches), and maps the intervals to
index ranges of any stream (:meth:`StillSelection.ranges`), which the pooled Allan variance
(:mod:`companion.allan.pooled`) uses segment by segment.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

ABS_GYRO_STD = 0.05  # rad/s: no gyro at rest is this noisy
ABS_ACCEL_STD = 0.5  # m/s^2
ACC_MEAN_STEP = 0.02  # m/s^2: about a 0.1 deg tilt
GYRO_MEAN_OFFSET = 0.005  # rad/s: a 0.3 deg/s turn


@dataclass
class StillSelection:
    """Still time intervals of a log and the accounting of what was left out (seconds)."""

    intervals: list[tuple[float, float]]
    method: str  # "armed state + motion", "motion", "all", ...
    total_s: float = 0.0
    still_s: float = 0.0
    moving_s: float = 0.0  # armed or moving (flight, handling)
    armed_s: float = 0.0
    gap_s: float = 0.0
    short_s: float = 0.0  # still stretches shorter than min_segment_s
    outside_s: float = 0.0  # before --start / after --end
    min_segment_s: float = 10.0
    notes: list[str] = field(default_factory=list)
    # IMU instance -> intervals inside ``intervals`` left out of that instance's streams only: its gyro alone
    # showed motion there (see select_still)
    excluded: dict[int, list[tuple[float, float]]] = field(default_factory=dict)

    def ranges(self, stream, min_samples: int = 16) -> list[tuple[int, int]]:
        """Half-open index ranges of ``stream`` inside the still intervals and inside its contiguous
        segments (never across a gap), each at least ``min_samples`` long."""
        t = stream.t
        segs = stream.segments or [(0, stream.samples)]
        out = []
        key = getattr(stream, "key", None)
        for t0, t1 in _minus(self.intervals, self.excluded.get(key.instance, []) if key is not None else []):
            a = int(np.searchsorted(t, t0, side="left"))
            b = int(np.searchsorted(t, t1, side="left"))
            for s0, s1 in segs:
                lo, hi = max(a, s0), min(b, s1)
                if hi - lo >= min_samples:
                    out.append((lo, hi))
        return sorted(set(out))

    def excluded_s(self, instance: int) -> float:
        return float(sum(b - a for a, b in self.excluded.get(instance, [])))

    def describe(self) -> str:
        k = len(self.intervals)
        text = (f"{k} still segment{'s' if k != 1 else ''}, {self.still_s:.0f} s in all"
                if self.method != "all" else f"whole record (--all), {self.still_s:.0f} s")
        left = []
        if self.moving_s >= 0.5:
            left.append(f"{self.moving_s:.0f} s of flight/motion" + (f" ({self.armed_s:.0f} s armed)" if self.armed_s >= 0.5 else ""))
        if self.gap_s >= 0.5:
            left.append(f"{self.gap_s:.0f} s of gaps")
        if self.short_s >= 0.5:
            left.append(f"{self.short_s:.0f} s of still stretches shorter than {self.min_segment_s:g} s")
        if self.outside_s >= 0.5:
            left.append(f"{self.outside_s:.0f} s outside --start/--end")
        if left:
            text += "; " + (", ".join(left[:-1]) + " and " + left[-1] if len(left) > 1 else left[0]) + " left out"
        return text + f" ({self.method})"

    def to_dict(self) -> dict:
        return {"method": self.method, "intervals": [[float(a), float(b)] for a, b in self.intervals],
                "still_s": self.still_s, "moving_s": self.moving_s, "armed_s": self.armed_s, "gap_s": self.gap_s,
                "short_s": self.short_s, "outside_s": self.outside_s, "total_s": self.total_s,
                "description": self.describe(), "notes": list(self.notes),
                "excluded": {str(i): [[float(a), float(b)] for a, b in iv] for i, iv in self.excluded.items()}}


def _minus(intervals, cut) -> list[tuple[float, float]]:
    """``intervals`` with the intervals ``cut`` taken out (both sorted, non-overlapping)."""
    out = []
    for a, b in intervals:
        for c, d in cut:
            if d <= a or c >= b:
                continue
            if c > a:
                out.append((a, c))
            a = max(a, d)
            if a >= b:
                break
        if a < b:
            out.append((a, b))
    return out


def armed_intervals(transitions, t_end: float) -> list[tuple[float, float]]:
    """[(t_on, t_off)] from armed transitions [(t, armed)] (still armed at the end: until ``t_end``)."""
    out, on = [], None
    for t, a in sorted(transitions):
        if a and on is None:
            on = float(t)
        elif not a and on is not None:
            out.append((on, float(t)))
            on = None
    if on is not None:
        out.append((on, max(float(t_end), on)))
    return out


def _bin_stats(b: np.ndarray, v: np.ndarray, nb: int):
    """Per-bin count, mean and std of the columns of ``v`` (NaN where a bin has < 2 samples)."""
    cnt = np.bincount(b, minlength=nb).astype(float)
    mean = np.full((nb, v.shape[1]), np.nan)
    std = np.full((nb, v.shape[1]), np.nan)
    ok = cnt >= 2
    for j in range(v.shape[1]):
        x = v[:, j]
        ref = float(np.nanmedian(x)) if x.shape[0] else 0.0
        s1 = np.bincount(b, weights=x - ref, minlength=nb)
        s2 = np.bincount(b, weights=(x - ref) ** 2, minlength=nb)
        mu = np.where(ok, s1 / np.maximum(cnt, 1), np.nan)
        var = np.where(ok, (s2 - cnt * mu**2) / np.maximum(cnt - 1, 1), np.nan)
        # a bin whose values are all equal (a frozen sensor) has std exactly 0, not the rounding residue of
        # the sums: that residue (1e-10 and less) counted as the quietest "moving" spread and set the axis'
        # noise floor, so every window of the same axis at rest was 3x above it and called motion
        lo_v = np.full(nb, np.inf)
        hi_v = np.full(nb, -np.inf)
        np.minimum.at(lo_v, b, x)
        np.maximum.at(hi_v, b, x)
        var = np.where(hi_v > lo_v, var, np.where(ok, 0.0, np.nan))
        mean[:, j] = mu + ref
        std[:, j] = np.sqrt(np.maximum(var, 0))
    return cnt, mean, std


FLOOR_QUIETEST = 5  # the floor is at most twice the 5th quietest window's spread


def _floor(std: np.ndarray) -> float:
    """The noise floor of one axis from its window standard deviations: the 10th percentile of the windows
    whose values vary at all (a quantised sensor at rest can show windows of identical values, std 0), or
    twice the ``FLOOR_QUIETEST``-th quietest where that is lower: a log that is mostly flight holds its rest
    in fewer than a tenth of its windows, and its 10th percentile is then the flight's (or the engine's on the
    ground) level. Twice the 5th quietest of 16-sample windows at rest is their level or more (the 5th of
    thousands is about 0.5x it), so a long rest log keeps its 10th percentile. (A tenth of the median spread,
    an earlier guard, made it worse: on a public plane log, 12-25x the gyro's rest level, which let engine
    vibration on the ground in as still.)"""
    c = np.sort(std[std > 0])
    if c.size == 0:
        return 0.0
    return float(min(np.percentile(c, 10), 2.0 * c[min(FLOOR_QUIETEST, c.size) - 1]))


def _moving_windows(stream, t0: float, window_s: float, nb: int, threshold: float,
                    use_gyro: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """(moving by the accelerometer, moving by the gyro, has_data, gyro evidence) per window for one IMU
    stream; the evidence: the largest |mean - still median| and std over the axes (rad/s), and the largest
    limits those are tested against (``dev_lim``, ``sd_lim``), or {} without gyro tests."""
    b = np.floor((stream.t - t0) / window_s).astype(np.int64)
    inside = (b >= 0) & (b < nb)
    b = b[inside]
    moving = {"gyro": np.zeros(nb, dtype=bool), "accel": np.zeros(nb, dtype=bool)}
    has = np.bincount(b, minlength=nb) >= 2
    evidence = {}
    for kind, v, abs_std, lsb in (("gyro", stream.gyro[inside], ABS_GYRO_STD, stream.gyro_lsb),
                                  ("accel", stream.accel[inside], ABS_ACCEL_STD, stream.accel_lsb)):
        if v.shape[0] == 0 or not np.all(np.isfinite(v[:, 0])) or (kind == "gyro" and not use_gyro):
            continue
        cnt, mean, std = _bin_stats(b, v, nb)
        good = has & np.all(np.isfinite(std), axis=1)
        if good.sum() < 3:
            continue
        floor0 = np.array([_floor(c) for c in std[good].T])
        floor = np.maximum(floor0, 0.5 * (lsb or 0.0))
        floor = np.maximum(floor, 1e-12)
        with np.errstate(invalid="ignore"):
            sd_lim = np.minimum(threshold * floor, abs_std)
            mv = np.any(std > sd_lim, axis=1)
            se = floor / np.sqrt(np.maximum(cnt, 1))[:, None]
            if kind == "accel":
                step = np.abs(np.diff(mean, axis=0))
                lim = 5.0 * np.sqrt(se[1:] ** 2 + se[:-1] ** 2) + ACC_MEAN_STEP
                jump = np.any(step > lim, axis=1) & good[1:] & good[:-1]
                mv[1:] |= jump
                mv[:-1] |= jump
            else:
                # a window of identical values is a frozen gyro, whatever value it holds, where a live one
                # varies at rest (a float message; an integer one whose noise floor is half a step or more --
                # a gyro quieter than the step reads one code at rest): never still, and never part of the level
                # at rest the means are tested against (a gyro frozen at 20 deg/s for most of a log made that
                # level 20 deg/s)
                # (an axis that never varies is dead throughout: health.dead names it, it says nothing of motion)
                varies = (floor0 > 0) & (np.full(floor0.shape, not lsb) | (floor0 >= 0.5 * (lsb or 0.0)))
                frozen = good & np.any((std == 0) & varies, axis=1)
                base = good & ~mv & ~frozen
                ref = np.nanmedian(mean[base], axis=0) if np.any(base) else np.nanmedian(mean[good], axis=0)
                dev, dev_lim = np.abs(mean - ref), 5.0 * se + GYRO_MEAN_OFFSET
                mv |= np.any(dev > dev_lim, axis=1) | frozen
                evidence = {"frozen": frozen, "dev": np.nan_to_num(np.nanmax(dev, axis=1, initial=0.0)),
                            "sd": np.nan_to_num(np.nanmax(std, axis=1, initial=0.0)),
                            "dev_lim": np.nanmax(dev_lim, axis=1, initial=0.0), "sd_lim": float(np.max(sd_lim))}
        moving[kind] |= mv & good
    return moving["accel"], moving["gyro"], has, evidence


def _merged_evidence(a: dict, b: dict) -> dict:
    """The gyro evidence of two streams of one IMU instance (:func:`_moving_windows`): the larger excursion,
    the smaller limit, frozen in either."""
    return {"frozen": a["frozen"] | b["frozen"], "dev": np.maximum(a["dev"], b["dev"]),
            "sd": np.maximum(a["sd"], b["sd"]), "dev_lim": np.minimum(a["dev_lim"], b["dev_lim"]), "sd_lim": min(a["sd_lim"], b["sd_lim"])}


def _dilate(mask: np.ndarray, k: int) -> np.ndarray:
    if k <= 0 or not mask.any():
        return mask
    # the full convolution cut to the mask's own length: mode="same" returns max(len(mask), 2k+1)
    # values, longer than the mask when the record holds fewer windows than the guard's width
    c = np.convolve(mask.astype(np.int64), np.ones(2 * k + 1, dtype=np.int64), mode="full")
    return c[k:k + mask.shape[0]] > 0


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def select_still(streams, meta: dict | None = None, *, start: float | None = None, end: float | None = None,
                 use_all: bool = False, window_s: float | None = None, guard_s: float = 3.0,
                 min_segment_s: float = 10.0, threshold: float = 3.0, use_gyro: bool = True) -> StillSelection:
    """Still intervals of a log from its IMU ``streams`` (all of them) and its ``meta`` (armed state).

    ``streams``: :class:`companion.samples.ImuStream` list (non-IMU streams are ignored); ``meta``:
    ``LoadResult.meta`` (``armed`` transitions, ``has_armed_state``). ``use_gyro``: False detects motion
    from the accelerometers only (for analyses of drifting gyros, where a wandering gyro is the object of
    study; a stream without accelerometer then counts as still).
    See the module docstring.
    """
    meta = meta or {}
    imus = [s for s in streams if s.is_imu and s.samples >= 2]
    if not imus:
        return StillSelection([], "none", notes=["no IMU samples"])
    t_lo = min(float(s.t[0]) for s in imus)
    t_hi = max(float(s.t[-1]) for s in imus)
    lo = t_lo if start is None else max(t_lo, float(start))
    hi = t_hi if end is None else min(t_hi, float(end))
    outside = max(0.0, (t_hi - t_lo) - max(0.0, hi - lo))
    if hi <= lo:
        return StillSelection([], "all" if use_all else "none", total_s=t_hi - t_lo, outside_s=outside,
                              min_segment_s=min_segment_s,
                              notes=[f"--start/--end select nothing of the record {t_lo:.1f}-{t_hi:.1f} s"])
    # windows of 1 s, longer when even the fastest IMU stream is slower than 16 Hz (a window must hold
    # 16 samples of it); decimated per-IMU topics (1-2 Hz) then only count where they have 2 samples
    if window_s is None:
        rates = [s.rate_hz for s in imus if np.isfinite(s.rate_hz) and s.rate_hz > 0]
        window_s = max(1.0, 16.0 / max(rates)) if rates else 1.0
    nb = max(1, int(np.ceil((hi - lo) / window_s)))
    has = np.zeros(nb, dtype=bool)
    moving = np.zeros(nb, dtype=bool)
    by_gyro = {}  # instance -> [windows its gyro calls moving, windows with data, its streams' gyro evidence]
    for s in imus:
        acc_mv, gyr_mv, h, ev = _moving_windows(s, lo, window_s, nb, threshold, use_gyro)
        has |= h
        if not use_all:
            moving |= acc_mv
            e = by_gyro.setdefault(s.key.instance, [np.zeros(nb, dtype=bool), np.zeros(nb, dtype=bool), None])
            e[0] |= gyr_mv
            e[1] |= h
            if ev:
                e[2] = ev if e[2] is None else _merged_evidence(e[2], ev)
    lone = {}  # instance -> its windows left out of its own streams
    if by_gyro:
        # a rotation or a vibration reaches every gyro of the airframe: where two or more IMU instances carry
        # gyro data, one instance's gyro alone (every accelerometer still, another instance's gyro still) is
        # that gyro's doing -- frozen at a rate, its bias drifting or stepping, noisy -- not motion: the window
        # stays still for the others and is left out of that instance's own streams only (a gyro stuck at
        # 20 deg/s took its healthy twin's 20 minutes at rest out of the analysis; a public ArduCopter tlog's
        # IMU0 warming up, its bias 1 deg/s from its later level, took 130 s of rest from IMU1). With one
        # instance (or streams that share one: a log's IMU and batch messages of the same sensor) its gyro
        # counts alone, as before.
        # The other gyro is a witness only where it would have seen what this one shows (a frozen gyro aside):
        # the excursion (mean or spread) at least twice the limit the witness is tested against -- a gyro 7x
        # noisier than its twin does not see the small rotation the quiet one does (a public Pixhawk log's
        # last 3 s before handling).
        gm = np.array([v[0] for v in by_gyro.values()])
        alone = (gm.sum(axis=0) == 1) & ~moving
        seen = np.zeros(nb, dtype=bool)
        for i, (mv_i, _, ev_i) in by_gyro.items():
            for j, (mv_j, h_j, ev_j) in by_gyro.items():
                if j == i or ev_i is None or ev_j is None:
                    continue
                would_see = ((ev_i["dev"] > 2.0 * ev_j["dev_lim"]) | (ev_i["sd"] > 2.0 * ev_j["sd_lim"])
                             | ev_i["frozen"])
                seen |= mv_i & h_j & ~mv_j & would_see
        alone &= seen
        moving |= gm.any(axis=0) & ~alone
        for i, mv_i in zip(by_gyro, gm):
            if np.any(mv_i & alone):
                lone[i] = mv_i & alone
    armed = np.zeros(nb, dtype=bool)
    armed_iv = armed_intervals(meta.get("armed") or [], t_hi)
    if not use_all:
        for a, b in armed_iv:
            i0 = int(np.floor((a - guard_s - lo) / window_s))
            i1 = int(np.ceil((b + guard_s - lo) / window_s))
            armed[max(i0, 0):max(min(i1, nb), 0)] = True
    g = int(np.ceil(guard_s / window_s))
    out = (_dilate(moving, g) | armed) & has
    still = has & ~out
    if use_all:
        method = "all"
    elif meta.get("has_armed_state"):
        method = "armed state + motion"
    else:
        method = "motion (no armed state in this source)"
    runs = _runs(still)
    keep, short = [], 0.0
    for a, b in runs:
        t0, t1 = lo + a * window_s, min(lo + b * window_s, hi)
        if b == nb:  # the last window includes the last sample
            t1 = float(np.nextafter(hi, np.inf))
        if use_all or t1 - t0 >= min_segment_s or (a == 0 and b == nb):  # a short record still throughout
            keep.append((t0, t1))
        else:
            short += t1 - t0
    sel = StillSelection(keep, method, total_s=t_hi - t_lo, min_segment_s=min_segment_s, outside_s=outside)
    for i, w in sorted(lone.items()):
        cut = [(lo + a * window_s, min(lo + b * window_s, hi)) for a, b in _runs(_dilate(w, g) & still)]
        cut = [(a, b) for a, b in _minus(keep, _minus(keep, cut))]  # only what lies inside the kept intervals
        if not cut:
            continue
        sel.excluded[i] = cut
        span = f"{cut[0][0]:.0f}-{cut[-1][1]:.0f} s"
        ev = by_gyro[i][2]
        what = ("its gyro was frozen (every value of a window the same, where a live gyro varies)"
                if ev is not None and ev["frozen"][w].mean() >= 0.9
                else "its gyro alone left its level at rest (mean or spread)")
        sel.notes.append(f"IMU instance {i}: in {sel.excluded_s(i):.0f} s (within {span}) {what} while the "
                         "accelerometers and another IMU's gyro were still: the gyro changed (its bias drifting or "
                         "stepping -- warm-up, a fault --, frozen, more noise; `companion run` judges its health), "
                         "the vehicle did not move; left out of that IMU's analysis only")
    # accounting in time: samples actually present inside the kept intervals (gaps inside them excluded)
    # (the stream that covers the most time: a batch sampler's kHz bursts have the most samples and cover a
    # second in ten, and the headline said 7 s where the IMU streams had 44)
    ref = max(imus, key=lambda s: (s.timing.duration_s, s.samples))
    covered = _covered(ref, keep)
    sel.still_s = covered
    sel.gap_s = float((~has).sum() * window_s) + sum(b - a for a, b in keep) - covered
    sel.gap_s = max(0.0, min(sel.gap_s, hi - lo))
    sel.moving_s = float(out.sum() * window_s)
    sel.armed_s = float((armed & has).sum() * window_s)
    sel.short_s = short
    if not keep and not use_all:
        sel.notes.append(f"no still stretch of at least {min_segment_s:g} s: the vehicle moved or was armed "
                         "throughout (use --start/--end or --all if you know better)")
    return sel


def _covered(stream, intervals) -> float:
    """Seconds of ``stream`` samples inside ``intervals`` (sum over its contiguous pieces)."""
    tot = 0.0
    for a, b in StillSelection(intervals, "").ranges(stream, min_samples=2):
        tot += float(stream.t[b - 1] - stream.t[a]) + 1.0 / stream.rate_hz if stream.rate_hz > 0 else 0.0
    return tot


def longest_still_range(res, stream, warn=None) -> tuple[int, int]:
    """Index range of the longest still, gap-free piece of ``stream`` (for analyses that need one contiguous
    series: ``gap``, ``compensate``). ``res`` is the stream's LoadResult (its metadata gives the armed
    state). Motion is judged from the accelerometers only: these commands study drifting gyros. Without any still piece the longest segment is returned and ``warn`` (a callable) is told."""
    sel = select_still(res.imu_streams(), getattr(res, "meta", {}) or {}, use_gyro=False)
    ranges = sel.ranges(stream)
    if ranges:
        return max(ranges, key=lambda r: r[1] - r[0])
    if warn:
        warn(f"{res.source}: no still stretch found ({sel.describe()}); using the longest segment as it is")
    return stream.longest_segment()
