"""Still-segment selection for post-flight analysis: which parts of a log hold a sensor at rest.

Allan analysis of a flight log must use only the stretches where the vehicle stood still: a flight (or a
hand carrying the vehicle) puts real rotation into the gyro and turns N into junk. :func:`select_still`
decides on a common time grid of ``window_s`` windows (default 1 s; longer when even the fastest IMU stream
is slower than 8 Hz, so that a window holds 8 of its samples):

1. **armed state** from the log (DataFlash ``EV``/``ARM``, ULog ``vehicle_status``, a tlog's vehicle
   HEARTBEATs, :func:`companion.sources.tlog.armed_state`): every armed window,
   widened by ``guard_s`` on each side (motors spin up before take-off and down after landing), is out;
2. **motion** from *every* IMU stream of the log, accelerometer and gyro: per window and axis the standard
   deviation and the mean. The noise floor of each stream is the 10th percentile of its window standard
   deviations (the quietest tenth of the log; of the windows whose values vary at all, at most twice the 5th
   quietest window's for a log that is mostly flight, and at least half an LSB for quantised formats); a
   window moves when, in any IMU,

   - an axis' standard deviation exceeds ``threshold`` x its floor (4x: the spread of a 16-sample standard
     deviation is about 18 %, and the floor is a low percentile), or exceeds an absolute limit (gyro 0.03
     rad/s, accel 0.3 m/s^2: no MEMS sensor at rest is that noisy, so a log that is all flight, a boat or a
     vehicle in the hand is never called still), or
   - the accelerometer mean moves from the previous window by more than 5 x its standard error + 0.02
     m/s^2 (a slow tilt of ~0.1 deg), or the gyro mean leaves the median of the still windows by more than
     5 x its standard error + 0.005 rad/s (a slow turn); the standard error is the white-noise one or the
     scatter of the steps between neighbouring quiet windows where larger (still_windows._mean_error);

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

import math
from dataclasses import dataclass, field

import numpy as np

from companion.timespans import minus
from companion.sources.still_windows import GyroEvidence, moving_windows


#: samples of the fastest IMU stream a window holds at least (its spread then scatters by ~27 %, well inside the
#: 4x threshold over a low-percentile floor; fewer samples per window keep a slow log's still stretches longer)
WINDOW_SAMPLES = 8.0


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
        for t0, t1 in minus(self.intervals, self.excluded.get(key.instance, []) if key is not None else []):
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
        used = f"{self.still_s:.0f}" if self.still_s >= 10 or self.still_s == 0 else f"{self.still_s:.2g}"  # not "0 s"
        text = (f"{k} still segment{'s' if k != 1 else ''}, {used} s in all"
                if self.method != "all" else f"whole record (--all), {used} s")
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


@dataclass(frozen=True)
class _Span:
    """The record's time span (``t_lo``-``t_hi``) and the part selected by --start/--end (``lo``-``hi``)."""

    t_lo: float
    t_hi: float
    lo: float
    hi: float

    @property
    def outside_s(self) -> float:
        return max(0.0, (self.t_hi - self.t_lo) - max(0.0, self.hi - self.lo))


@dataclass(frozen=True)
class _Grid:
    """``nb`` windows of ``window_s`` from ``lo``; the last one ends at ``hi``."""

    lo: float
    hi: float
    window_s: float
    nb: int

    def interval(self, a: int, b: int) -> tuple[float, float]:
        """Time interval of windows ``a`` to ``b`` (exclusive)."""
        return self.lo + a * self.window_s, min(self.lo + b * self.window_s, self.hi)


@dataclass
class _InstanceGyro:
    """One IMU instance's gyro over the windows: where it moved, where it had data, and its evidence."""

    moving: np.ndarray
    has: np.ndarray
    evidence: GyroEvidence | None = None
    level: np.ndarray | None = None  # its mean left its level on some axis (about the vertical or not)


@dataclass
class _Motion:
    """Motion over the windows from every IMU stream: windows with data, windows that move (every
    accelerometer, then the gyros), and each instance's gyro."""

    has: np.ndarray
    moving: np.ndarray
    gyros: dict[int, _InstanceGyro] = field(default_factory=dict)


@dataclass
class _Kept:
    """Still runs long enough to keep, and the seconds of those too short."""

    intervals: list[tuple[float, float]]
    short_s: float
    longest_short_s: float = 0.0  # the longest still run left out as too short


def _span(imus, start: float | None, end: float | None) -> _Span:
    t_lo = min(float(s.t[0]) for s in imus)
    t_hi = max(float(s.t[-1]) for s in imus)
    lo = t_lo if start is None else max(t_lo, float(start))
    hi = t_hi if end is None else min(t_hi, float(end))
    return _Span(t_lo, t_hi, lo, hi)


def _grid(imus, span: _Span, window_s: float | None) -> _Grid:
    """Windows of 1 s, longer when even the fastest IMU stream is slower than 8 Hz (a window must hold
    ``WINDOW_SAMPLES`` samples of it); decimated per-IMU topics (1-2 Hz) then only count where they have 2 samples."""
    if window_s is None:
        rates = [s.rate_hz for s in imus if np.isfinite(s.rate_hz) and s.rate_hz > 0]
        window_s = max(1.0, WINDOW_SAMPLES / max(rates)) if rates else 1.0
    nb = max(1, int(np.ceil((span.hi - span.lo) / window_s)))
    return _Grid(span.lo, span.hi, window_s, nb)


def _window_motion(imus, grid: _Grid, threshold: float, use_gyro: bool, use_all: bool) -> _Motion:
    """Windows with data from every stream; with the selection on, the accelerometers' motion and each
    instance's gyro (streams of one instance: moving in either, the evidence merged)."""
    motion = _Motion(np.zeros(grid.nb, dtype=bool), np.zeros(grid.nb, dtype=bool))
    for s in imus:
        sm = moving_windows(s, grid.lo, grid.window_s, grid.nb, threshold, use_gyro)
        motion.has |= sm.has
        if use_all:
            continue
        motion.moving |= sm.accel
        g = motion.gyros.setdefault(s.key.instance, _InstanceGyro(np.zeros(grid.nb, dtype=bool),
                                                                  np.zeros(grid.nb, dtype=bool)))
        g.moving |= sm.gyro
        g.level = sm.level.copy() if g.level is None else g.level | sm.level
        g.has |= sm.has
        if sm.evidence is not None:
            g.evidence = sm.evidence if g.evidence is None else g.evidence.merged(sm.evidence)
    return motion


def _gyro_motion(motion: _Motion) -> dict[int, np.ndarray]:
    """Add the gyros' motion to ``motion.moving``; returns per instance the windows its gyro alone moved.

    A rotation or a vibration reaches every gyro of the airframe: where two or more IMU instances carry gyro
    data, one instance's gyro alone (every accelerometer still, another instance's gyro still) is that gyro's
    doing -- frozen at a rate, its bias drifting or stepping, noisy -- not motion: the window stays still for
    the others and is left out of that instance's own streams only, so that a faulty or warming gyro does not
    take its healthy twin's rest out of the analysis. With one instance (or streams that share one: a log's
    IMU and batch messages of the same sensor) its gyro counts alone. The other gyro is a witness only where
    it would have seen what this one shows (:meth:`GyroEvidence.would_be_seen_by`): a gyro several times
    noisier than its twin does not see a small rotation the quiet one does."""
    if not motion.gyros:
        return {}
    if len(motion.gyros) >= 2:
        # a twin can tell: a mean that leaves its level about a horizontal axis, which the accelerometer shows
        # as no tilt, is that gyro's own change where another gyro stays (alone, below); one gyro's drift about
        # a horizontal axis is not motion (see still_windows._gyro_level_test) and stays in its analysis
        for g in motion.gyros.values():
            if g.level is not None:
                g.moving = g.moving | (g.level & g.has)
    gm = np.array([g.moving for g in motion.gyros.values()])
    alone = (gm.sum(axis=0) == 1) & ~motion.moving
    seen = np.zeros(motion.moving.shape[0], dtype=bool)
    for i, gi in motion.gyros.items():
        for j, gj in motion.gyros.items():
            if j == i or gi.evidence is None or gj.evidence is None:
                continue
            seen |= gi.moving & gj.has & ~gj.moving & gi.evidence.would_be_seen_by(gj.evidence)
    alone &= seen
    motion.moving |= gm.any(axis=0) & ~alone
    return {i: mv_i & alone for i, mv_i in zip(motion.gyros, gm) if np.any(mv_i & alone)}


def _armed_windows(meta: dict, t_hi: float, grid: _Grid, guard_s: float) -> np.ndarray:
    """Windows within ``guard_s`` of an armed interval (motors spin up before take-off, down after landing)."""
    armed = np.zeros(grid.nb, dtype=bool)
    for a, b in armed_intervals(meta.get("armed") or [], t_hi):
        i0 = int(np.floor((a - guard_s - grid.lo) / grid.window_s))
        i1 = int(np.ceil((b + guard_s - grid.lo) / grid.window_s))
        armed[max(i0, 0):max(min(i1, grid.nb), 0)] = True
    return armed


def _method(use_all: bool, meta: dict) -> str:
    if use_all:
        return "all"
    if meta.get("has_armed_state"):
        return "armed state + motion"
    return "motion (no armed state in this source)"


def _kept_runs(still: np.ndarray, grid: _Grid, min_segment_s: float, use_all: bool,
               out: np.ndarray | None = None, trim_s: float = 0.0) -> _Kept:
    """Still runs of at least ``min_segment_s`` (every run with ``use_all``; a record still throughout is
    kept however short), ``trim_s`` taken off each end next to a window that is ``out``."""
    keep, short, longest = [], 0.0, 0.0
    for a, b in _runs(still):
        t0, t1 = grid.interval(a, b)
        if b == grid.nb:  # the last window includes the last sample
            t1 = float(np.nextafter(grid.hi, np.inf))
        if trim_s > 0 and out is not None:
            t0 += trim_s if a > 0 and out[a - 1] else 0.0
            t1 -= trim_s if b < grid.nb and out[b] else 0.0
            if t1 <= t0:
                continue
        if use_all or t1 - t0 >= min_segment_s or (a == 0 and b == grid.nb):
            keep.append((t0, t1))
        else:
            short += t1 - t0
            longest = max(longest, t1 - t0)
    return _Kept(keep, short, longest)


def _exclude_lone_gyros(sel: StillSelection, lone: dict[int, np.ndarray], motion: _Motion, still: np.ndarray,
                        grid: _Grid, guard: int) -> None:
    """Record in ``sel`` each instance's windows of its gyro alone (within the kept intervals), with a note."""
    keep = sel.intervals
    for i, w in sorted(lone.items()):
        cut = [grid.interval(a, b) for a, b in _runs(_dilate(w, guard) & still)]
        cut = [(a, b) for a, b in minus(keep, minus(keep, cut))]  # only what lies inside the kept intervals
        if not cut:
            continue
        sel.excluded[i] = cut
        span = f"{cut[0][0]:.0f}-{cut[-1][1]:.0f} s"
        ev = motion.gyros[i].evidence
        what = ("its gyro was frozen (every value of a window the same, where a live gyro varies)"
                if ev is not None and ev.frozen[w].mean() >= 0.9
                else "its gyro alone left its level at rest (mean or spread)")
        sel.notes.append(f"IMU instance {i}: in {sel.excluded_s(i):.0f} s (within {span}) {what} while the "
                         "accelerometers and another IMU's gyro were still: the gyro changed (its bias drifting or "
                         "stepping -- warm-up, a fault --, frozen, more noise; `companion run` judges its health), "
                         "the vehicle did not move; left out of that IMU's analysis only")


def _account(sel: StillSelection, imus, has: np.ndarray, out: np.ndarray, armed: np.ndarray, grid: _Grid) -> None:
    """The time accounting of ``sel``: samples actually present inside the kept intervals (gaps inside them
    excluded), counted on the stream that covers the most time (a batch sampler's kHz bursts have the most
    samples but cover a fraction of the time)."""
    keep = sel.intervals
    ref = max(imus, key=lambda s: (s.timing.duration_s, s.samples))
    covered = _covered(ref, keep)
    sel.still_s = covered
    sel.gap_s = float((~has).sum() * grid.window_s) + sum(b - a for a, b in keep) - covered
    sel.gap_s = max(0.0, min(sel.gap_s, grid.hi - grid.lo))
    sel.moving_s = float(out.sum() * grid.window_s)
    sel.armed_s = float((armed & has).sum() * grid.window_s)


def select_still(streams, meta: dict | None = None, *, start: float | None = None, end: float | None = None,
                 use_all: bool = False, window_s: float | None = None, guard_s: float = 3.0,
                 min_segment_s: float = 10.0, threshold: float = 4.0, use_gyro: bool = True) -> StillSelection:
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
    span = _span(imus, start, end)
    if span.hi <= span.lo:
        return StillSelection([], "all" if use_all else "none", total_s=span.t_hi - span.t_lo,
                              outside_s=span.outside_s, min_segment_s=min_segment_s,
                              notes=[f"--start/--end select nothing of the record {span.t_lo:.1f}-{span.t_hi:.1f} s"])
    grid = _grid(imus, span, window_s)
    motion = _window_motion(imus, grid, threshold, use_gyro, use_all)
    lone = _gyro_motion(motion)
    armed = np.zeros(grid.nb, dtype=bool) if use_all else _armed_windows(meta, span.t_hi, grid, guard_s)
    # the guard in whole windows, the rest of it trimmed off the still runs' ends next to motion: a 12 s window
    # of a 1.3 Hz log is not widened by 12 s for a 3 s guard
    guard = int(np.floor(guard_s / grid.window_s + 1e-9))
    out = (_dilate(motion.moving, guard) | armed) & motion.has
    still = motion.has & ~out
    kept = _kept_runs(still, grid, min_segment_s, use_all, out, guard_s - guard * grid.window_s)
    sel = StillSelection(kept.intervals, _method(use_all, meta), total_s=span.t_hi - span.t_lo,
                         min_segment_s=min_segment_s, outside_s=span.outside_s)
    _exclude_lone_gyros(sel, lone, motion, still, grid, guard)
    _account(sel, imus, motion.has, out, armed, grid)
    sel.short_s = kept.short_s
    if not kept.intervals and not use_all:
        sel.notes.append(_refusal(sel, kept.longest_short_s, armed, motion.has, start is not None or end is not None))
    return sel


def _refusal(sel: StillSelection, longest: float, armed: np.ndarray, has: np.ndarray, windowed: bool) -> str:
    """Why no still stretch was kept, and the option that works: ``--all`` analyses the record (or the
    --start/--end window) as it is; --min-still where the still stretches are only short (``longest``: the longest
    of them); --start/--end where a disarmed, still part is elsewhere in the record."""
    armed_all = bool(np.all(armed[has])) if has.any() else False
    where = "the --start/--end window" if windowed else "the record"
    if armed_all:
        why = f"the vehicle was armed throughout {where} ({sel.armed_s:.0f} s)"
    elif longest >= 1:
        why = (f"the longest still stretch of {where} is {math.floor(longest * 10) / 10:g} s "
               f"({sel.moving_s:.0f} s of flight/motion"
               + (f", {sel.armed_s:.0f} s armed" if sel.armed_s >= 0.5 else "") + ")")
    else:
        why = (f"the vehicle moved or was armed throughout {where} ({sel.moving_s:.0f} s of flight/motion"
               + (f", {sel.armed_s:.0f} s armed" if sel.armed_s >= 0.5 else "") + ")")
    fixes = ["--all analyses " + ("that window" if windowed else "the whole record") + " as it is"]
    if longest >= 1 and not armed_all:
        fixes.insert(0, f"--min-still {math.floor(longest * 10) / 10:g} keeps the longest of them")
    if not windowed and not armed_all:
        fixes.append("--start/--end --all a part you know was still")
    return f"no still stretch of at least {sel.min_segment_s:g} s: {why}; " + "; ".join(fixes)


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
