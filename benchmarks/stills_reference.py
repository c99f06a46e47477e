"""An independent reference of where a log stood still and disarmed, to judge `analyze`'s still selection.

The rule is deliberately simple and shares no code with :mod:`companion.sources.still`:

* the log's time is cut into blocks of ``BLOCK_S`` seconds, longer where the slowest IMU stream would hold fewer
  than ``BLOCK_SAMPLES`` samples in one (a 1 Hz stream: 8 s blocks);
* per block, IMU stream and axis: the standard deviation of the gyro and of the accelerometer, and the gyro's
  block mean; an axis' quiet level is the median of its quietest fifth of blocks (at least half the format's
  LSB);
* a block is **still** when, in every IMU stream that has 3+ samples in it, every axis' spread is within ``K_STILL``
  x the quiet level (and below 0.03 rad/s and 0.3 m/s^2: a boat or a hand is never at rest) and no gyro axis'
  mean is more than ``TURN_RAD_S`` from its median over the still blocks;
  it is **moving** when an accelerometer's spread exceeds ``K_MOVING`` x its level or 0.5 m/s^2, or the gyros of two
  IMU instances (the only one, where there is one) exceed it or 0.05 rad/s, or their mean is that far off (between
  still and moving: undecided, counted in neither);
* armed time (the log's armed transitions, as the readers decode them: tlog HEARTBEAT base_mode, DataFlash
  ``EV``/``ARM``, ULog ``vehicle_status``) is moving;
* still, disarmed runs of at least ``MIN_RUN_S`` are the reference still time.

Times are seconds of the log's own clock; intervals are half-open ``[a, b)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BLOCK_S = 1.0  #: block length where every stream is fast enough
BLOCK_SAMPLES = 8  #: the slowest stream's samples per block at least
K_STILL = 4.0  #: a spread within this many times the quiet level is rest
K_MOVING = 10.0  #: a spread beyond this many times the quiet level is motion
TURN_RAD_S = 0.05  #: a gyro mean this far from its level at rest is a turn (about 3 deg/s)
REST_GYRO, REST_ACCEL = 0.03, 0.3  #: rad/s, m/s^2: no spread at rest is larger (a boat, a hand, an engine)
LOUD_GYRO, LOUD_ACCEL = 0.05, 0.5  #: rad/s, m/s^2: a spread this large is motion whatever the quiet level
MIN_RUN_S = 10.0  #: analyze's default shortest still stretch


@dataclass
class Reference:
    """Still and moving intervals of one log by the simple rule above."""

    still: list[tuple[float, float]]
    moving: list[tuple[float, float]]
    block_s: float

    @property
    def still_s(self) -> float:
        return length(self.still)

    @property
    def longest_s(self) -> float:
        return max((b - a for a, b in self.still), default=0.0)


def length(iv) -> float:
    return float(sum(b - a for a, b in iv))


def intersect(x, y) -> list[tuple[float, float]]:
    """Intersection of two lists of sorted, disjoint intervals."""
    out, i, j = [], 0, 0
    while i < len(x) and j < len(y):
        a, b = max(x[i][0], y[j][0]), min(x[i][1], y[j][1])
        if a < b:
            out.append((a, b))
        if x[i][1] < y[j][1]:
            i += 1
        else:
            j += 1
    return out


def union(iv) -> list[tuple[float, float]]:
    out = []
    for a, b in sorted(iv):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def _runs(mask) -> list[tuple[int, int]]:
    d = np.diff(np.r_[0, np.asarray(mask, dtype=np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def _block_stats(t, v, edges):
    """Per block: sample count, per-axis std and per-axis mean of ``v`` (n, 3)."""
    idx = np.searchsorted(t, edges)
    nb = edges.shape[0] - 1
    cnt = np.diff(idx)
    sd = np.full((nb, 3), np.nan)
    mean = np.full((nb, 3), np.nan)
    for k in range(nb):
        if cnt[k] >= 3:
            x = v[idx[k]:idx[k + 1]]
            sd[k] = np.std(x, axis=0, ddof=1)
            mean[k] = x.mean(axis=0)
    return cnt, sd, mean


def _level(sd, lsb) -> np.ndarray:
    """Per axis, the median spread of the quietest fifth of blocks (at least half an LSB)."""
    out = np.full(sd.shape[1], np.inf)
    for j in range(sd.shape[1]):
        c = np.sort(sd[np.isfinite(sd[:, j]), j])
        if c.size:
            out[j] = max(float(np.median(c[: max(1, c.size // 5)])), 0.5 * (lsb or 0.0), 1e-9)
    return out


def armed_spans(transitions, t_end: float) -> list[tuple[float, float]]:
    out, on = [], None
    for t, armed in sorted(transitions or []):
        if armed and on is None:
            on = float(t)
        elif not armed and on is not None:
            out.append((on, float(t)))
            on = None
    if on is not None:
        out.append((on, max(on, float(t_end))))
    return out


def reference(streams, meta: dict) -> Reference:
    """The reference of a log from its IMU streams (``ImuStream``: t, gyro, accel, lsb) and armed transitions."""
    imus = [s for s in streams if s.is_imu and s.t.shape[0] >= 3]
    if not imus:
        return Reference([], [], BLOCK_S)
    t0 = min(float(s.t[0]) for s in imus)
    t1 = max(float(s.t[-1]) for s in imus)
    rates = []
    for s in imus:
        d = np.diff(s.t)
        d = d[d > 0]
        if d.size:
            rates.append(1.0 / float(np.median(d)))
    block = max(BLOCK_S, BLOCK_SAMPLES / min(rates)) if rates else BLOCK_S
    nb = max(1, int(np.ceil((t1 - t0) / block)))
    edges = t0 + block * np.arange(nb + 1)
    edges[-1] = np.nextafter(max(edges[-1], t1), np.inf)
    still = np.ones(nb, dtype=bool)
    moving = np.zeros(nb, dtype=bool)  # an accelerometer's spread, or armed
    gyro_loud: dict[int, np.ndarray] = {}  # per IMU instance: its gyro's spread or turn
    seen = np.zeros(nb, dtype=bool)
    for s in imus:
        gcnt, gsd, gmean = _block_stats(s.t, s.gyro, edges)
        _, asd, _ = _block_stats(s.t, s.accel, edges)
        ok = gcnt >= 3
        seen |= ok
        lg, la = _level(gsd, s.gyro_lsb), _level(asd, s.accel_lsb)
        with np.errstate(invalid="ignore"):
            quiet = (np.all(gsd <= np.minimum(K_STILL * lg, REST_GYRO), axis=1)
                     & np.all(asd <= np.minimum(K_STILL * la, REST_ACCEL), axis=1))
            gloud = np.any(gsd > np.minimum(K_MOVING * lg, LOUD_GYRO), axis=1)
            aloud = np.any(asd > np.minimum(K_MOVING * la, LOUD_ACCEL), axis=1)
        base = ok & quiet
        ref = np.nanmedian(gmean[base], axis=0) if base.any() else np.nanmedian(gmean[ok], axis=0)
        with np.errstate(invalid="ignore"):
            turn = np.nan_to_num(np.max(np.abs(gmean - ref), axis=1)) > TURN_RAD_S
        still &= ~ok | (quiet & ~turn)
        moving |= ok & aloud
        g = gyro_loud.setdefault(s.key.instance, np.zeros(nb, dtype=bool))
        g |= ok & (gloud | turn)
    # a rotation reaches every gyro: one gyro alone (of two or more instances) is that gyro's change, not motion
    if gyro_loud:
        count = np.sum(list(gyro_loud.values()), axis=0)
        moving |= count >= min(2, len(gyro_loud))
    still &= seen
    armed = np.zeros(nb, dtype=bool)
    for a, b in armed_spans((meta or {}).get("armed"), t1):
        armed |= (edges[1:] > a) & (edges[:-1] < b)
    still &= ~armed
    moving |= armed & seen
    runs = [(float(edges[a]), float(min(edges[b], t1))) for a, b in _runs(still)]
    return Reference([r for r in runs if r[1] - r[0] >= MIN_RUN_S],
                     [(float(edges[a]), float(edges[b])) for a, b in _runs(moving)], block)
