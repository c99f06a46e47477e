"""Block cutter of one IMU stream: timestamp rules, the stream's rate and blocks of ``block_s`` of message time.

One vectorised path for every caller: the live loop hands it one row, a replay or the simulator whole
arrays; the blocks, counts and rate are the same either way. Rows are ``(t, gx, gy, gz, ax, ay, az)``.

Timestamp rules (:func:`companion.sources.timestamps.classify_steps`, the rules of the offline time base with
the live thresholds ``reset_s`` and ``gap_s`` given to :func:`~companion.sources.timestamps.step_rules`): a
timestamp more than ``reset_s`` behind the last one is an autopilot reboot (the partial block is dropped);
a repeated one is a duplicate and one slightly behind goes backwards (both dropped and counted); an
interval longer than ``gap_s`` (and, once the rate is known, than GAP_PERIODS periods) is a gap (the partial
block is dropped). A block closes at the first sample with ``t - t0 >= block_s - period / 2``.

The rate is 1 / :func:`companion.sources.timestamps.period_of` of the last RATE_WINDOW intervals, taken at the
first block close with 8 intervals and re-taken at every close. Every forward interval enters the window, gaps
too: period_of starts from their median, so an occasional long gap or a burst moves it little, and a stream
whose every interval is longer than ``gap_s`` (a 1 Hz telemetry stream, intervals of 0.5 to 2 s) still gets
its rate, after which its gap rule is GAP_PERIODS periods.

A change is reported when the window's rate is off the stream's by more than the stream's tolerance
(``tol``: RATE_CHANGE, or the spread of its own intervals where that is wider, :func:`interval_spread`) and
has stayed off for SETTLE intervals, SETTLE intervals or more after the rate was last set. A telemetry
stream the autopilot slows while the radio is busy (ArduPilot's stream slow-down: intervals of 0.5 to 1.4 s
that wander from second to second) has no one period, and a window of 64 of its intervals moves by 20 %
from one minute to the next: with RATE_CHANGE alone such a stream switched 16-29 times in 20 minutes,
each switch restarting the estimators and holding blocks back. A stream asked for another rate changes by
far more than its spread and is followed by the per-block test (service/rate_tracker.py) within a few
blocks.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Iterator

import numpy as np

from companion.sources.timestamps import BACKWARD, DUPLICATE, OK, RESET, classify_steps, period_of, step_rules

RATE_CHANGE = 0.2  # relative change of the rate that restarts the estimators
MIN_INTERVALS = 8  # intervals before the rate is taken
#: once the rate is known a gap is an interval longer than ``gap_s`` and than GAP_PERIODS periods: at 2 Hz (a
#: telemetry stream at 2 Hz, a PX4 log's vehicle_imu) half the intervals are a little over 0.5 s,
#: and with ``gap_s`` alone each would be a gap that drops the block: the stream would never fill one
GAP_PERIODS = 2.5
RATE_WINDOW = 64  # intervals whose robust period is the stream's rate
SETTLE = RATE_WINDOW // 2  # intervals a rate stands before it changes, and a change stands before it is taken
#: a switch and a switch back within this factor and WANDER_INTERVALS is the stream's wander (BlockCutter.switch)
WANDER_MAX = 2.0
WANDER_INTERVALS = 4 * RATE_WINDOW
#: below this a stream is not watched: a block of samples spans minutes, a dead gyro would be named after many
#: minutes, and such a rate is more often a time column in the wrong unit than a real IMU stream
MIN_WATCH_RATE_HZ = 0.5


def interval_spread(d, resolution: float = 0.0) -> float:
    """The relative spread of a stream's intervals: their interquartile range, less two stamp resolutions
    (a 400 Hz stream stamped in whole ms has intervals of 2 and 3 ms), over their median."""
    q25, q50, q75 = np.percentile(np.asarray(d, dtype=float), [25.0, 50.0, 75.0])
    return max(0.0, float(q75 - q25) - 2.0 * resolution) / q50 if q50 > 0 else 0.0


class BlockCutter:
    """Explicit inputs (:meth:`cut` rows) and outputs (the events it yields); ``counts`` what it dropped."""

    def __init__(self, block_s: float, reset_s: float, gap_s: float, time_res: float = 0.0):
        self.block_s, self.time_res = float(block_s), time_res
        self.reset_s, self.gap_s = float(reset_s), float(gap_s)
        # the period is unknown until the first blocks: the configured thresholds stand in for it
        self.rules = step_rules(0.0, time_res, reset_s=reset_s, gap_s=gap_s)
        self.last_t: float | None = None
        self.dts: deque = deque(maxlen=RATE_WINDOW)
        self.rate_hz: float | None = None
        self.prev_rate_hz: float | None = None  # the rate before the last change
        self.too_slow_hz: float | None = None  # the rate learned when it is below MIN_WATCH_RATE_HZ
        self.tol = RATE_CHANGE  # relative change of the rate that is a change (RATE_CHANGE or the spread)
        self.tol_known = False  # the spread learned (a rate restored from the state has none yet)
        self.n_in = 0  # intervals that entered the window so far
        self.set_at = 0  # n_in when the rate was last set
        self.off_since: int | None = None  # n_in when the window's rate left the tolerance
        self.gap_t: list[float] = []  # times of the samples joined by gaps only (slower_rate)
        self.wander = 0.0  # the stream's own wander, learned from a switch and a switch back (switch)
        self._parts: list = []
        self._t0: float | None = None
        self.counts = {"samples": 0, "duplicates": 0, "backwards": 0, "resets": 0, "gaps": 0, "rate_changes": 0}

    def period(self) -> float:
        return 1.0 / self.rate_hz if self.rate_hz else (float(np.median(self.dts)) if self.dts else 0.0)

    def step_rules(self):
        """The timestamp rules at the current rate (GAP_PERIODS)."""
        # before the rate is taken, the median interval so far stands in for the period: at 2 Hz half the
        # intervals exceed a gap_s of 0.5 s by a few ms, and the first blocks would be gaps until 8 intervals are in
        period = 1.0 / self.rate_hz if self.rate_hz else (float(np.median(self.dts)) if self.dts else 0.0)
        gap = max(self.gap_s, GAP_PERIODS * period)
        if gap != self.rules.gap_s:
            self.rules = step_rules(0.0, self.time_res, reset_s=self.reset_s, gap_s=gap)
        return self.rules

    def drop(self) -> None:
        """Forget the partial block (a time discontinuity)."""
        self._parts, self._t0 = [], None

    def cut(self, rows: np.ndarray) -> Iterator[tuple]:
        """Feed rows (n, 7) in arrival order; yields, in order:

        * ``("reset", t_before, t)`` / ``("gap", t)``: a discontinuity before the next sample (block dropped);
        * ``("samples", tt)``: accepted samples that close no block (their timestamps);
        * ``("block", data, rate)``: the block closed by its last sample; ``rate`` is None, ``"first"`` when
          the rate was just taken or ``"changed"`` (``rate_hz`` holds the new value, ``prev_rate_hz`` the old).
        """
        t = rows[:, 0]
        n = t.shape[0]
        kinds = classify_steps(t, self.last_t, self.step_rules())
        i = 0
        while i < n:
            if self.last_t is not None:
                kind = kinds[i]
                if kind == RESET:
                    self.counts["resets"] += 1
                    self.drop()
                    yield ("reset", self.last_t, float(t[i]))
                elif kind == DUPLICATE or kind == BACKWARD:  # dropped
                    self.counts["duplicates" if kind == DUPLICATE else "backwards"] += 1
                    i += 1
                    continue
                elif kind != OK:  # a gap (a live gap also splits: the same here)
                    self.counts["gaps"] += 1
                    self.gap_t = (self.gap_t or [self.last_t]) + [float(t[i])]
                    self.dts.append(float(t[i] - self.last_t))  # the window's median sees it (RATE_WINDOW)
                    self.n_in += 1
                    self.drop()
                    yield ("gap", float(t[i]))
                else:
                    self.dts.append(float(t[i] - self.last_t))
                    self.n_in += 1
                    self.gap_t = []
            # the clean stretch from i: every interval within (0, gap_s]; while the rate is unknown the period
            # (the median of the intervals so far) changes with every sample: one row at a time
            if self.rate_hz is None or n - i == 1:
                end = i + 1
            else:
                bad = np.flatnonzero(kinds[i + 1:] != OK)
                end = i + 1 + (int(bad[0]) if bad.size else n - i - 1)
                if end - i > 1:
                    self.dts.extend(np.diff(t[i:end])[-self.dts.maxlen:].tolist())
                    self.n_in += end - i - 1
            self.counts["samples"] += end - i
            self.last_t = float(t[end - 1])
            rules = self.rules
            yield from self._blocks(rows, i, end)
            i = end
            if i < n and self.step_rules() is not rules:  # the rate was taken or changed: its gap rule from here
                kinds[i:] = classify_steps(t[i:], self.last_t, self.rules)

    def _blocks(self, rows: np.ndarray, i: int, end: int) -> Iterator[tuple]:
        t = rows[:, 0]
        k = i
        while k < end:
            if self._t0 is None:
                self._t0 = float(t[k])
            x = self.block_s - 0.5 * self.period()
            if end - k == 1:  # one row (the live path): the comparison itself
                j = k if float(t[k]) - self._t0 >= x else end
            else:  # first sample with t - t0 >= x (the same float operation as one row)
                j = int(np.searchsorted(t[k:end], self._t0 + x, side="left")) + k
            while j > k and t[j - 1] - self._t0 >= x:
                j -= 1
            while j < end and not (t[j] - self._t0 >= x):
                j += 1
            if j >= end:
                self._parts.append(rows[k:end])
                yield ("samples", t[k:end])
                return
            if j > k:
                yield ("samples", t[k:j])
            parts = self._parts + [rows[k:j + 1]]
            data = parts[0] if len(parts) == 1 else np.concatenate(parts)
            self._parts, self._t0 = [], None
            yield ("block", data, self._rate())
            k = j + 1

    def quiet_run(self, t: np.ndarray, check_t: float | None = None) -> int:
        """The number of leading samples of ``t`` (increasing, intervals within ``gap_s``) that close no block
        and reach no ``check_t``: 0 while the rate is unknown or when the first interval is irregular."""
        n = t.shape[0]
        if n == 0 or self.rate_hz is None or self.last_t is None:
            return 0
        if classify_steps(t[:1], self.last_t, self.step_rules())[0] != OK:
            return 0
        t0 = float(t[0]) if self._t0 is None else self._t0
        x = self.block_s - 0.5 * self.period()
        j = int(np.searchsorted(t, t0 + x, side="left"))
        while j > 0 and t[j - 1] - t0 >= x:
            j -= 1
        while j < n and not (t[j] - t0 >= x):
            j += 1
        if check_t is not None:
            j = min(j, int(np.searchsorted(t, check_t, side="left")))
        return j

    def slower_rate(self) -> float | None:
        """The rate of a stream now slower than GAP_PERIODS periods: every interval a gap, so no block closes
        and the window is never re-taken (asked for 1 Hz after 4 Hz). MIN_INTERVALS gaps in a row whose
        own rate is off the stream's by more than its tolerance give it; None otherwise."""
        if self.rate_hz is None or len(self.gap_t) <= MIN_INTERVALS:
            return None
        rate = 1.0 / period_of(np.diff(self.gap_t), self.time_res)
        return rate if math.log(self.rate_hz / rate) > math.log1p(self.tol) else None

    def switch(self, new_rate: float, intervals=None) -> None:
        """The channel switched to ``new_rate`` (service/channel.py); ``intervals``: those of the blocks held
        back at it, the window from here (None: the window is at the new rate already). A switch back to the
        rate before, within a factor WANDER_MAX and WANDER_INTERVALS of the last switch, is the stream's
        wander (a radio that slows the stream for a minute or two): the tolerance widens to cover both. A
        ground station that asks for 2 Hz, then 4 Hz and 2 Hz again within a few minutes is followed up to
        there; a change by more than WANDER_MAX (1 to 4 Hz) always."""
        old, before = self.rate_hz, self.prev_rate_hz
        if (old is not None and before is not None and self.n_in - self.set_at < WANDER_INTERVALS
                and abs(math.log(new_rate / before)) <= math.log1p(self.tol)
                and abs(math.log(new_rate / old)) <= math.log(WANDER_MAX)):
            self.wander = max(self.wander, math.exp(abs(math.log(new_rate / old))) * (1.0 + RATE_CHANGE) - 1.0)
            self.tol = max(self.tol, self.wander)
        self.prev_rate_hz, self.rate_hz = old, float(new_rate)
        if intervals is not None:
            self.dts.clear()
            self.dts.extend([float(v) for v in intervals])
        self.set_at, self.off_since, self.gap_t = self.n_in, None, []

    def _rate(self) -> str | None:
        if len(self.dts) < MIN_INTERVALS:
            return None
        rate = 1.0 / period_of(self.dts, self.time_res)
        if self.rate_hz is not None and not self.tol_known:  # a rate restored from the state: its spread now
            self.tol = max(RATE_CHANGE, self.wander, interval_spread(self.dts, self.time_res))
        self.tol_known = True
        if self.rate_hz is None:
            if rate < MIN_WATCH_RATE_HZ:  # said in the summary (service.imu_summary.too_slow_note)
                self.too_slow_hz = rate
                return None
            self.too_slow_hz = None
            self.rate_hz = rate
            self.tol = max(RATE_CHANGE, self.wander, interval_spread(self.dts, self.time_res))
            self.set_at, self.off_since = self.n_in, None
            return "first"
        if abs(math.log(rate / self.rate_hz)) <= math.log1p(self.tol):
            # at the stream's rate: its spread is learned here, never from a window that straddles a change
            self.tol = max(RATE_CHANGE, self.wander, interval_spread(self.dts, self.time_res))
            self.off_since = None
            return None
        if self.off_since is None:
            self.off_since = self.n_in
        if self.n_in - self.set_at < SETTLE or self.n_in - self.off_since < SETTLE:
            return None
        self.counts["rate_changes"] += 1
        self.switch(rate)
        return "changed"
