"""The IMUs of one vehicle on one time grid: the slower stream's own instants, the faster streams linearly
interpolated there, cut into contiguous pieces inside the condition's intervals (numpy only).

Linear interpolation at a fixed fractional offset is a two-tap FIR filter of gain 1 at 0 Hz: it bends the
Allan curve only at the first cluster times and leaves the white-noise level N (the low-frequency PSD)
unchanged; the fit leaves those cluster times out (:data:`companion.redundancy.fit_points.ROLLOFF_TAU0`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: a step between two samples longer than this many nominal periods is a gap (no interpolation across it)
GAP_PERIODS = 2.5
#: pieces shorter than this many grid samples carry no Allan point of use and are dropped: the fit's first
#: cluster time is 8 periods (fit_points.ROLLOFF_TAU0), whose overlapping AVAR needs 2 x 8 + 1 samples (the
#: flight of a 2-Hz telemetry stream can come in runs of 5-15 s between quiet stretches)
MIN_PIECE = 17


@dataclass
class ImuTrack:
    """One IMU's gyro: times ``t`` (n,) s on the vehicle's clock, ``gyro`` (n, 3) rad/s, its nominal rate,
    the low-pass cut-off of the logged data (Hz, None: unknown) and its LSB (rad/s, None: float data)."""

    t: np.ndarray
    gyro: np.ndarray
    rate_hz: float
    filter_hz: float | None = None
    lsb: float | None = None
    label: str = ""


@dataclass
class Aligned:
    """The tracks on one grid: ``pieces[p][i]`` is track i's (n_p, 3) gyro on piece p; ``rate_hz`` the grid's
    nominal rate; ``reference`` the index of the track whose instants are the grid; ``seconds`` the time
    covered."""

    pieces: list
    rate_hz: float
    reference: int
    seconds: float

    def track(self, i: int) -> list:
        """Track i's pieces, (n_p, 3) each."""
        return [p[i] for p in self.pieces]


def _inside(t: np.ndarray, intervals) -> np.ndarray:
    ok = np.zeros(t.shape[0], dtype=bool)
    for a, b in intervals:
        ok |= (t >= a) & (t <= b)
    return ok


def _interp_valid(tq: np.ndarray, tr: ImuTrack):
    """Track ``tr`` linearly interpolated at ``tq``, and where that is valid (both neighbours exist and are
    no further apart than GAP_PERIODS nominal periods)."""
    t = np.asarray(tr.t, dtype=float)
    if t.shape[0] < 2:
        return np.full((tq.shape[0], 3), np.nan), np.zeros(tq.shape[0], dtype=bool)
    k = np.searchsorted(t, tq, side="right")
    ok = (k > 0) & (k < t.shape[0])
    kk = np.clip(k, 1, max(t.shape[0] - 1, 1))
    step = t[kk] - t[kk - 1]
    ok &= step <= GAP_PERIODS / tr.rate_hz
    out = np.empty((tq.shape[0], 3))
    for j in range(3):
        out[:, j] = np.interp(tq, t, tr.gyro[:, j])
    return out, ok


def _runs(ok: np.ndarray, t: np.ndarray, period: float) -> list[tuple[int, int]]:
    """Index ranges [a, b) of consecutive valid samples with no time gap inside."""
    brk = np.ones(t.shape[0], dtype=bool)
    brk[1:] = (np.diff(t) > GAP_PERIODS * period) | ~ok[1:] | ~ok[:-1]
    starts = np.flatnonzero(brk)
    out = []
    for a, b in zip(starts, list(starts[1:]) + [t.shape[0]]):
        a = a if ok[a] else a + 1
        if b - a >= MIN_PIECE and ok[a:b].all():
            out.append((int(a), int(b)))
    return out


def align(tracks: list[ImuTrack], intervals) -> Aligned:
    """Every track at the slowest track's instants inside ``intervals`` (a list of (t0, t1), s), in gap-free
    pieces of at least MIN_PIECE samples. Ties of rate: the first track's instants."""
    rates = [float(tr.rate_hz) for tr in tracks]
    ref = int(np.argmin(rates))
    rt = tracks[ref]
    t = np.asarray(rt.t, dtype=float)
    finite = np.all(np.isfinite(rt.gyro), axis=1) & np.isfinite(t)
    ok = _inside(t, intervals) & finite
    cols = []
    for i, tr in enumerate(tracks):
        if i == ref:
            cols.append(np.asarray(rt.gyro, dtype=float))
            continue
        y, v = _interp_valid(t, tr)
        ok &= v & np.all(np.isfinite(y), axis=1)
        cols.append(y)
    period = 1.0 / rates[ref]
    pieces = [[c[a:b] for c in cols] for a, b in _runs(ok, t, period)]
    secs = float(sum(p[0].shape[0] for p in pieces)) * period
    return Aligned(pieces, rates[ref], ref, secs)
