"""Time base of a stream from the messages' own timestamps: rate, jitter, gaps, duplicates, resets.

Rules (applied in arrival order, never resampling, never reordering):

- **reset** (autopilot reboot): a timestamp more than ``reset_s`` = max(1 s, 10 periods) *behind* the
  newest one so far starts a new segment;
- **duplicate**: a timestamp equal to the newest one so far -> sample dropped, counted;
- **backwards**: a timestamp behind the newest one by less than ``reset_s`` -> dropped, counted;
- **rate**: ``P0`` = median of the kept intervals; the period ``P`` is the mean of the intervals
  ``<= 1.5 P0 + r`` (``r`` = timestamp resolution, 1 ms for ``time_boot_ms``), so a 400 Hz stream
  stamped in whole milliseconds (intervals of 2 and 3 ms) gets 2.5 ms, not 2 or 3;
- **gap**: an interval ``> 1.5 P + r`` (1-ms jitter is not a gap); a gap longer than
  ``split_periods`` (default 10) periods also splits the segment (Allan analysis needs contiguous
  samples), shorter gaps are only counted;
- **jitter**: rms of (interval - P) over the intervals that are not gaps;
- **duration**: sum over segments of (last - first timestamp).
"""

from __future__ import annotations

import numpy as np

from companion.samples import TimingReport

SPLIT_PERIODS = 10.0
#: timestamp resolution of the IMU messages that carry ``time_boot_ms`` (the others: 1 us, taken as 0)
MS_STAMPED = ("SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3")


def stamp_resolution(message: str) -> float:
    """The resolution of a message's timestamps in seconds (1 ms for ``time_boot_ms``, else 0)."""
    return 1e-3 if message in MS_STAMPED else 0.0


def period_of(intervals, resolution: float = 0.0) -> float:
    """The sampling period from positive timestamp intervals: ``P0`` = their median, ``P1`` = the mean of
    the intervals ``<= 1.5 P0 + r`` (``r`` = the stamps' resolution), then ``P`` = the mean of those
    ``<= max(1.5 P1, P1 + r)``: longer intervals are lost samples or gaps. A 400 Hz stream stamped in whole
    milliseconds (intervals of 2 and 3 ms, 5 ms where one was lost) gets 2.5 ms, where the median alone
    says 2 or 3 ms (500 or 333 Hz) and one pass lets the 5-ms intervals in. NaN without intervals."""
    d = np.asarray(intervals, dtype=np.float64)
    d = d[d > 0]
    if d.shape[0] == 0:
        return float("nan")
    p = float(np.median(d))
    limit = 1.5 * p + resolution
    for _ in range(2):
        normal = d[d <= limit]
        if normal.shape[0] == 0:
            break
        p = float(normal.mean())
        limit = max(1.5 * p, p + resolution)
    return p


def analyse(t: np.ndarray, resolution: float = 0.0, split_periods: float = SPLIT_PERIODS,
            rate_hz: float | None = None) -> tuple[np.ndarray, list[tuple[int, int]], TimingReport]:
    """Timing of arrival-ordered timestamps ``t`` (s).

    Returns ``(keep, segments, report)``: ``keep`` is a boolean mask of the samples kept (duplicates
    and small backward steps dropped), ``segments`` half-open ranges into the KEPT samples.
    ``rate_hz`` forces the nominal rate instead of detecting it.
    """
    t = np.asarray(t, dtype=np.float64)
    n = t.shape[0]
    rep = TimingReport()
    if n == 0:
        return np.zeros(0, dtype=bool), [], rep
    # 1. resets: a jump far behind the running maximum (threshold needs a period estimate)
    d = np.diff(t)
    pos = d[d > 0]
    p0 = float(np.median(pos)) if pos.shape[0] else 1.0
    if rate_hz:
        p0 = 1.0 / rate_hz
    reset_s = max(1.0, 10.0 * p0)
    starts = [0]
    s, w = 0, 1024
    while s < n - 1:  # search windows double in size, so the total work stays O(n)
        e = min(n, s + w)
        runmax = np.maximum.accumulate(t[s:e])
        jump = np.flatnonzero(t[s + 1:e] < runmax[:-1] - reset_s)
        if jump.shape[0]:
            s += 1 + int(jump[0])
            starts.append(s)
            w = 1024
        elif e == n:
            break
        else:
            w *= 2
    rep.resets = len(starts) - 1
    # 2. duplicates and small backward steps, per reset segment
    keep = np.ones(n, dtype=bool)
    bounds = starts + [n]
    for a, b in zip(bounds[:-1], bounds[1:]):
        seg = t[a:b]
        prev_max = np.maximum.accumulate(seg)[:-1]
        later = seg[1:]
        dup = later == prev_max
        back = later < prev_max
        rep.duplicates += int(dup.sum())
        rep.backwards += int(back.sum())
        keep[a + 1:b] = ~(dup | back)
    # indices of reset starts among kept samples
    kept_idx = np.cumsum(keep) - 1
    reset_kept = [int(kept_idx[s]) for s in starts]
    tk = t[keep]
    nk = tk.shape[0]
    dk = np.diff(tk)
    inside = np.ones(max(nk - 1, 0), dtype=bool)  # intervals that do not cross a reset
    for s in reset_kept[1:]:
        inside[s - 1] = False
    di = dk[inside]
    # 3. rate
    if rate_hz:
        period = 1.0 / rate_hz
    elif di.shape[0] and np.any(di > 0):
        period = period_of(di, resolution)
    else:
        period = float("nan")
    rep.rate_hz = 1.0 / period if period and np.isfinite(period) and period > 0 else float("nan")
    # 4. gaps and splits
    if np.isfinite(period):
        gap = inside & (dk > 1.5 * period + resolution)
        split = inside & (dk > split_periods * period + resolution)
        normal = inside & ~gap
        if normal.any():
            rep.jitter_rms = float(np.sqrt(np.mean((dk[normal] - period) ** 2)))
    else:
        gap = split = np.zeros_like(inside)
    rep.gaps = int(gap.sum())
    cuts = sorted(set(reset_kept[1:]) | set((np.flatnonzero(split) + 1).tolist()))
    edges = [0] + cuts + [nk]
    segments = [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]
    rep.duration_s = float(sum(tk[b - 1] - tk[a] for a, b in segments))
    return keep, segments, rep


#: kinds of one timestamp interval (:func:`classify_intervals`)
OK_STEP, GAP, RESET, DUPLICATE, BACKWARDS = 0, 1, 2, 3, 4


def classify_interval(dt: float, reset_s: float, gap_s: float) -> int:
    """:func:`classify_intervals` of one interval, in plain floats (the live path, one message at a time)."""
    if dt == 0.0:
        return DUPLICATE
    if dt <= -reset_s:
        return RESET
    if dt < 0.0:
        return BACKWARDS
    return GAP if dt > gap_s else OK_STEP


def classify_intervals(dt, reset_s: float, gap_s: float) -> np.ndarray:
    """Kind of each interval ``dt`` between a timestamp and the newest one before it, by the rules above:
    RESET when ``dt <= -reset_s``, DUPLICATE when 0, BACKWARDS when in (-reset_s, 0), GAP when above
    ``gap_s``, else OK_STEP. The live pipeline applies it with its fixed thresholds (``run.reset_s``,
    ``run.gap_s``) sample by sample or to a whole array at once."""
    dt = np.asarray(dt, dtype=float)
    out = np.full(dt.shape, OK_STEP, dtype=np.int8)
    out[dt > gap_s] = GAP
    out[dt < 0.0] = BACKWARDS
    out[dt <= -reset_s] = RESET
    out[dt == 0.0] = DUPLICATE
    return out
