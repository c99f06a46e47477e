"""Time base of a stream from the messages' own timestamps: rate, jitter, gaps, duplicates, resets.

Rules (applied in arrival order, never resampling, never reordering):

- **reset** (autopilot reboot): a timestamp more than ``reset_s`` = max(1 s, 10 periods) *behind* the
  newest one so far starts a new segment;
- **duplicate**: a timestamp equal to the newest one so far -> sample dropped, counted;
- **backwards**: a timestamp behind the newest one by less than ``reset_s`` -> dropped, counted;
- **rate**: ``P0`` = median of the kept intervals; the period ``P`` is the mean of the intervals
  within ``P0 +- (0.5 P0 + r)`` (``r`` = timestamp resolution, 1 ms for ``time_boot_ms``), so a 400 Hz
  stream stamped in whole milliseconds (intervals of 2 and 3 ms) gets 2.5 ms, not 2 or 3, and a late
  message's short and long intervals (0.12 + 0.88 s at 2 Hz) are both left out;
- **gap**: an interval ``> 1.5 P + r`` (1-ms jitter is not a gap); a gap longer than
  ``split_periods`` (default 10) periods also splits the segment (Allan analysis needs contiguous
  samples), shorter gaps are only counted;
- **jitter**: rms of (interval - P) over the intervals that are not gaps;
- **duration**: sum over segments of (last - first timestamp).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.samples import TimingReport
from companion.timebase import MS_STAMPED, period_of, stamp_resolution  # noqa: F401 (re-export)

#: a gap longer than this many periods splits the segment (Allan analysis needs contiguous samples)
SPLIT_PERIODS = 10.0


@dataclass(frozen=True)
class StepRules:
    """The thresholds of the rules above for a stream of period ``period`` s (see :func:`step_rules`)."""

    period: float
    resolution: float
    reset_s: float  # a step back by more than this starts a new segment (reboot)
    gap_s: float  # a step forward by more than this is a gap (counted)
    split_s: float  # a step forward by more than this also splits the segment


def step_rules(period: float, resolution: float = 0.0, split_periods: float = SPLIT_PERIODS, *,
               reset_s: float | None = None, gap_s: float | None = None) -> StepRules:
    """The timestamp rules (reset, gap, split thresholds) for sampling period ``period`` and stamp resolution
    ``resolution``: the one definition the offline analysis (:func:`analyse`) and the live block cutter
    (``service/blocks.py``) share. The live cutter does not know the period when the first samples arrive,
    so it passes its configured thresholds (``run.reset_s``, ``run.gap_s``) instead of the period-derived
    ones; a gap then also counts as a split (it drops the partial block either way)."""
    reset = max(1.0, 10.0 * period) if reset_s is None else float(reset_s)
    gap = 1.5 * period + resolution if gap_s is None else float(gap_s)
    split = split_periods * period + resolution if gap_s is None else gap
    return StepRules(period, resolution, reset, gap, split)


#: step kinds of :func:`classify_steps`
OK, DUPLICATE, BACKWARD, RESET, GAP, SPLIT = range(6)


def classify_steps(t, newest: float | None, rules: StepRules) -> np.ndarray:
    """The kind of every timestamp of ``t`` (s, arrival order) under the rules above, vectorised: ``OK``,
    ``DUPLICATE`` / ``BACKWARD`` (the sample is dropped), ``RESET`` (a new segment starts with it), ``GAP``
    (kept, a gap before it), ``SPLIT`` (kept, a gap long enough to split the segment). Each is compared with
    the newest kept timestamp before it; ``newest`` is that of the samples before ``t`` (None: ``t[0]`` is
    the first of the stream, OK). A live caller passes one sample (a one-row call) or a block; the counts
    over a whole stream equal :func:`analyse`'s with the same period."""
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if t.shape[0] == 1 and newest is not None:  # one live sample: the same rules in plain floats (8x faster)
        d = float(t[0]) - float(newest)
        k = (RESET if d < -rules.reset_s else DUPLICATE if d == 0.0 else BACKWARD if d < 0.0
             else SPLIT if d > rules.split_s else GAP if d > rules.gap_s else OK)
        return np.array([k], dtype=np.int8)
    kind = np.zeros(t.shape[0], dtype=np.int8)
    start = 0
    prev = -np.inf if newest is None else float(newest)
    while start < t.shape[0]:
        seg = t[start:]
        pm = np.maximum.accumulate(np.r_[prev, seg])[:-1]  # newest kept timestamp before each sample
        jump = np.flatnonzero(seg < pm - rules.reset_s)
        stop = int(jump[0]) if jump.shape[0] else seg.shape[0]
        d = seg[:stop] - pm[:stop]
        k = kind[start:start + stop]
        k[d > rules.gap_s] = GAP
        k[d > rules.split_s] = SPLIT
        k[d < 0] = BACKWARD
        k[d == 0] = DUPLICATE
        if stop == seg.shape[0]:
            break
        kind[start + stop] = RESET
        prev = float(seg[stop])
        start += stop + 1
    if newest is None and kind.shape[0]:
        kind[0] = OK
    return kind


def _reset_starts(t: np.ndarray, reset_s: float) -> list[int]:
    """Indices where a reset segment starts (0 first): a timestamp more than ``reset_s`` behind the running
    maximum. The search windows double in size, so the total work stays O(n)."""
    n = t.shape[0]
    starts = [0]
    s, w = 0, 1024
    while s < n - 1:
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
    return starts


def _drop_steps_back(t: np.ndarray, starts: list[int], rep: TimingReport) -> np.ndarray:
    """Mask of the samples kept: per reset segment, duplicates and small backward steps (behind the newest
    timestamp so far) are dropped and counted in ``rep``."""
    n = t.shape[0]
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
    return keep


def _period(di: np.ndarray, resolution: float, rate_hz: float | None) -> float:
    """The sampling period from the kept intervals that do not cross a reset (``rate_hz`` forces it)."""
    if rate_hz:
        return 1.0 / rate_hz
    if di.shape[0] and np.any(di > 0):
        return period_of(di, resolution)
    return float("nan")


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
    # 1. resets: a jump far behind the running maximum (the threshold needs a first period estimate)
    d = np.diff(t)
    pos = d[d > 0]
    p0 = float(np.median(pos)) if pos.shape[0] else 1.0
    del pos  # 8 MB per million samples, not needed past here
    if rate_hz:
        p0 = 1.0 / rate_hz
    starts = _reset_starts(t, step_rules(p0, resolution, split_periods).reset_s)
    rep.resets = len(starts) - 1
    # 2. duplicates and small backward steps, per reset segment
    keep = _drop_steps_back(t, starts, rep)
    if keep.all():  # the usual case: no copies of the timestamps (a 2.8 h, 100 Hz log holds 8 MB of them)
        reset_kept, tk, dk = list(starts), t, d
    else:
        kept_idx = np.cumsum(keep) - 1
        reset_kept = [int(kept_idx[s]) for s in starts]  # reset starts among the kept samples
        tk = t[keep]
        dk = np.diff(tk)
    nk = tk.shape[0]
    inside = np.ones(max(nk - 1, 0), dtype=bool)  # intervals that do not cross a reset
    for s in reset_kept[1:]:
        inside[s - 1] = False
    # 3. rate
    period = _period(dk if inside.all() else dk[inside], resolution, rate_hz)
    rep.rate_hz = 1.0 / period if period and np.isfinite(period) and period > 0 else float("nan")
    # 4. gaps and splits
    if np.isfinite(period):
        rules = step_rules(period, resolution, split_periods)
        gap = inside & (dk > rules.gap_s)
        split = inside & (dk > rules.split_s)
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
