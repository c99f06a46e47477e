"""A gyro axis clipped at a range limit, sample by sample, for streams too slow for the block test.

The block test (health/saturation.py) looks for RUN (5) samples in a row at one block's peak, at one level
in several blocks: a telemetry stream at 1-4 Hz has one to four samples in a block and never shows it
(a sample at the message's own limit, 32.767 rad/s, it names at any rate, but not in a block held back
for a rate change: this test names that one too, at its sample). A clip leaves another mark
that needs no consecutive samples: the axis piles up at one exact |value|, the largest of its recent
samples, while the values just below it stay sparse. Over the last ``WINDOW`` samples of an axis:

* at each sample, ``top`` = its |value|; ``at`` = the samples at exactly +-top since the last one beyond
  it (a clip that begins mid-window: the larger values before it do not count), in ``visits`` apart by a
  sample more than ``BAND`` (5 % of top, 0.01 rad/s at least) below it; ``near`` = the most samples of the
  whole window at any one value within BAND below top;
* the axis is named when ``at >= NEED`` (4) in 2 visits or more, ``at >= RATIO * near`` (2), and
  top >= ``MIN_LEVEL`` (0.05 rad/s, far above a gyro's noise: a bias at rest is not a clip).

Healthy motion reaches its largest value once; samples one telemetry period apart (>= ``MIN_SPACING_S``)
hit the same exact value at the top of a window only where the rate holds still (a steady turn): in one
visit (a gyro quieter than its step, SITL, reads one value throughout a steady turn: one visit is never
enough, and a clip held through one manoeuvre only is named at its next one), and its neighbouring values are
as frequent (``near``: a yaw of 0.05 rad/s held for a minute in
a real tlog read 55 mrad/s four times, 53 and 54 twice, 50 eight times). The neighbourhood is judged value by
value, not as a whole: a vehicle spinning near its clip level (a compass-calibration dance at 5 rad/s) puts
many samples within 5 % below it, each at its own value. A clip puts every sample beyond the limit at the limit.
The samples needed are those that reach the limit: NEED of them within WINDOW samples, at any rate; a
vehicle that stays below the limit (at rest, a gentle cruise) shows no clip, as it shows no saturation.
It clears when a sample goes beyond the named level by more than BAND (the limit is gone), or after
``CLEAR`` samples without one at the level.

Streams faster than 1 / MIN_SPACING_S (20 Hz) are left to the block test: neighbouring samples of a smooth
peak can repeat the top value there. Pure numpy; the caller (service/frozen_hook.py) hands each IMU's
samples in message-time order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from companion.health.faults import FaultEvent
from companion.health.hold import FAULT, OK

AXES = ("gx", "gy", "gz")
WINDOW = 60  # samples of an axis judged together
NEED = 4  # samples at the window's top |value| that name a clip
RATIO = 2.0  # ... at least this many times the samples just below it
BAND = 0.05  # relative: "just below" is within 5 % of the top
BAND_MIN = 0.01  # rad/s, and at least this (10 steps of RAW_IMU: a steady turn's values within 1-3 steps)
MIN_LEVEL = 0.05  # rad/s: a clip level far above any gyro's noise and bias at rest
CLEAR = 2 * WINDOW  # samples without one at the named level that clear it
MIN_SPACING_S = 0.05  # median interval below which a stream is left to the block test (above 20 Hz)


@dataclass
class ClipAxis:
    state: int = OK
    level: float = math.nan
    quiet: int = 0  # samples since the last one at the named level


@dataclass
class ClipTrack:
    g: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # the last WINDOW - 1 samples
    last_t: float = -math.inf
    axes: list = field(default_factory=lambda: [ClipAxis() for _ in AXES])
    spacing: list = field(default_factory=list)  # recent intervals (the stream's spacing)


def _median(xs: list) -> float:
    """np.median of a short list of floats without NaN (the same value), at a tenth of its cost."""
    s = sorted(xs)
    mid = len(s) // 2
    return s[mid] if len(s) % 2 else (s[mid - 1] + s[mid]) / 2.0


class ClipWatch:
    """Every IMU of one vehicle: :meth:`add` samples, :meth:`take` the ``saturation`` events they brought."""

    def __init__(self, limit: float = math.inf):
        self.limit = float(limit)  # rad/s: the range limit of the message (int16 mrad/s: 32.767)
        self.imus: dict[int, ClipTrack] = {}
        self.pending: list[tuple[float, FaultEvent]] = []

    def take(self) -> list[tuple[float, FaultEvent]]:
        """The events since the last call, in time order."""
        out, self.pending = sorted(self.pending, key=lambda te: te[0]), []
        return out

    def add(self, imu: int, t: np.ndarray, gyro: np.ndarray) -> None:
        """Samples of ``imu`` (increasing times; older ones are left out); the state changes they bring wait
        in :meth:`take`, each with the message time of the sample that decided it."""
        tr = self.imus.setdefault(imu, ClipTrack())
        t = np.asarray(t, dtype=float).reshape(-1)
        g = np.asarray(gyro, dtype=float).reshape(-1, 3)
        if t.size and t[0] < tr.last_t - 1.0:  # a reboot: the time starts again
            self.imus[imu] = tr = ClipTrack()
        if t.size == 1:  # the live loop's one row a call: plain floats (numpy's per-call cost is most of it)
            t0 = float(t[0])
            if not t0 > tr.last_t:
                return
            tr.spacing.append(t0 - tr.last_t)
        else:
            keep = t > np.maximum.accumulate(np.concatenate(([tr.last_t], t[:-1])))
            t, g = t[keep], g[keep]
            if t.size == 0:
                return
            tr.spacing.extend(np.diff(np.concatenate(([tr.last_t], t)))[-64:].tolist())
        del tr.spacing[:-64]
        tr.last_t = float(t[-1])
        if _median(tr.spacing) < MIN_SPACING_S:  # a fast stream: the block test sees its plateaus
            tr.g = np.zeros((0, 3))
            return
        hit = np.abs(g) >= 0.999 * self.limit  # a sample at the limit, even in a block held back
        for k, j in zip(*np.nonzero(hit)):
            st = tr.axes[j]
            if st.state == OK:
                st.state, st.level, st.quiet = FAULT, float(abs(g[k, j])), 0
                self.pending.append((float(t[k]), FaultEvent(imu, AXES[j], "saturation", FAULT, st.level,
                                                             critical=True)))
        allg = np.concatenate([tr.g, g])
        tr.g = allg[-(WINDOW - 1):]
        m = g.shape[0]
        first = allg.shape[0] - m
        for j, ax in enumerate(AXES):
            a = np.abs(allg[:, j])
            for k in range(m):
                win = a[max(0, first + k - WINDOW + 1):first + k + 1]
                ev = self._step(imu, tr.axes[j], ax, win, float(a[first + k]))
                if ev is not None:
                    self.pending.append((float(t[k]), ev))

    @staticmethod
    def _step(imu: int, st: ClipAxis, ax: str, win: np.ndarray, v: float) -> FaultEvent | None:
        if st.state == FAULT:
            if v > st.level * (1.0 + BAND):
                st.state = OK
            else:
                st.quiet = 0 if v == st.level else st.quiet + 1
                if st.quiet >= CLEAR:
                    st.state = OK
            return FaultEvent(imu, ax, "saturation", OK, st.level) if st.state == OK else None
        top = v
        if top < MIN_LEVEL:
            return None
        above = np.flatnonzero(win > top)
        stretch = win[above[-1] + 1:] if above.size else win  # since the last sample beyond this value
        if stretch.size < NEED:
            return None
        hit = stretch == top
        at = int(np.count_nonzero(hit))
        if at < NEED:
            return None
        band = max(BAND * top, BAND_MIN)
        # a clip is left and reached again: visits to the level apart by a sample well below it
        below = np.cumsum(stretch < top - band)[hit]
        visits = 1 + int(np.count_nonzero(np.diff(below) > 0))
        if visits < 2:  # one stay at a value is a steady turn as much as a clip (a gyro quieter than its step)
            return None
        # the most samples at one other value just below, over the whole window (a steady turn, a biased
        # gyro at rest: as many at the neighbouring values as at the top)
        _, counts = np.unique(win[(win < top) & (win >= top - band)], return_counts=True)
        near = int(counts.max()) if counts.size else 0
        if at >= RATIO * near:  # (at >= NEED: above)
            st.state, st.level, st.quiet = FAULT, top, 0
            return FaultEvent(imu, ax, "saturation", FAULT, top, critical=True)
        return None

    def level(self, imu: int, axis: str) -> float:
        """The level an axis this test holds was named at (rad/s)."""
        return self.imus[imu].axes[AXES.index(axis)].level

    def active(self, imu: int) -> list[tuple[str, str]]:
        tr = self.imus.get(imu)
        return [] if tr is None else [("saturation", ax) for ax, s in zip(AXES, tr.axes) if s.state == FAULT]
