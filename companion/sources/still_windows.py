"""Per-window motion tests of one IMU stream for the still selection (:mod:`companion.sources.still`).

The log's time is cut into windows of ``window_s``; per window and axis the standard deviation and the mean
of the samples. The noise floor of an axis is the 10th percentile of its window standard deviations (see
:func:`noise_floor`); a window moves when an axis' standard deviation exceeds ``threshold`` x its floor or an
absolute limit, when the accelerometer mean steps from the previous window, or when the gyro mean leaves
its level at rest (the median of the still windows) by more than its standard error allows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: rad/s: no gyro at rest is this noisy (a MEMS gyro at 1-8 kHz unfiltered: 2-10 mrad/s), so a log that is all
#: flight, a boat on the water or a vehicle held in the hand is never still
ABS_GYRO_STD = 0.03
ABS_ACCEL_STD = 0.3  #: m/s^2: the accelerometer's counterpart of ABS_GYRO_STD
ACC_MEAN_STEP = 0.02  #: m/s^2: about a 0.1 deg tilt between windows is motion
GYRO_MEAN_OFFSET = 0.005  #: rad/s: a 0.3 deg/s turn away from the level at rest is motion
FLOOR_QUIETEST = 5  #: the floor is at most twice the 5th quietest window's spread (see noise_floor)
MEAN_SIGMAS = 5.0  #: a mean moves by more than this many standard errors (plus the offsets above) to count
STANDARD_G = 9.80665  #: m/s^2
MIN_PAIRS = 10  #: neighbouring quiet windows needed to read the scatter of the means from the data


@dataclass
class GyroEvidence:
    """Per window, what one gyro showed: frozen (identical values), the largest |mean - level at rest| and
    standard deviation over the axes (rad/s), and the limits those are tested against."""

    frozen: np.ndarray
    dev: np.ndarray
    sd: np.ndarray
    dev_lim: np.ndarray
    sd_lim: float

    def merged(self, other: GyroEvidence) -> GyroEvidence:
        """Two streams of one IMU instance: the larger excursion, the smaller limit, frozen in either."""
        return GyroEvidence(self.frozen | other.frozen, np.maximum(self.dev, other.dev),
                            np.maximum(self.sd, other.sd), np.minimum(self.dev_lim, other.dev_lim),
                            min(self.sd_lim, other.sd_lim))

    def would_be_seen_by(self, witness: GyroEvidence) -> np.ndarray:
        """Windows where ``witness`` would have seen what this gyro shows: the excursion (mean or spread) at
        least twice the witness's limit, or this gyro frozen."""
        return (self.dev > 2.0 * witness.dev_lim) | (self.sd > 2.0 * witness.sd_lim) | self.frozen


@dataclass
class StreamMotion:
    """Per window of one stream: moving by its accelerometer, moving by its gyro, has data (2+ samples),
    the gyro evidence (None without gyro tests), and where the gyro's mean left its level on any axis."""

    accel: np.ndarray
    gyro: np.ndarray
    has: np.ndarray
    evidence: GyroEvidence | None = None
    level: np.ndarray | None = None  # the gyro mean left its level on any axis (a turn, or the gyro's own change)

    def __post_init__(self):
        if self.level is None:
            self.level = np.zeros_like(self.gyro)


def bin_stats(b: np.ndarray, v: np.ndarray, nb: int):
    """Per-bin count, mean and std of the columns of ``v`` (NaN where a bin has < 2 samples)."""
    cnt = np.bincount(b, minlength=nb).astype(float)
    mean = np.full((nb, v.shape[1]), np.nan)
    std = np.full((nb, v.shape[1]), np.nan)
    ok = cnt >= 2
    # samples in time order (the usual case): each bin is one run of rows, its extremes one reduceat per axis
    ordered = b.shape[0] > 0 and bool(np.all(b[1:] >= b[:-1]))
    if ordered:
        starts = np.flatnonzero(np.r_[True, b[1:] != b[:-1]])
        bins = b[starts]
    for j in range(v.shape[1]):
        x = v[:, j]
        # a typical value subtracted before the sums (their rounding), from every few-thousandth sample: the
        # median of the whole column costs more than the rest of the window statistics
        ref = float(np.nanmedian(x[:: max(1, x.shape[0] // 4096)])) if x.shape[0] else 0.0
        ref = ref if np.isfinite(ref) else 0.0
        s1 = np.bincount(b, weights=x - ref, minlength=nb)
        s2 = np.bincount(b, weights=(x - ref) ** 2, minlength=nb)
        mu = np.where(ok, s1 / np.maximum(cnt, 1), np.nan)
        var = np.where(ok, (s2 - cnt * mu**2) / np.maximum(cnt - 1, 1), np.nan)
        # a bin whose values are all equal (a frozen sensor) has std exactly 0, not the rounding residue of
        # the sums: a residue of 1e-10 would be the quietest spread of the axis and set its noise floor, and
        # every window of the axis at rest would then be called motion
        lo_v = np.full(nb, np.inf)
        hi_v = np.full(nb, -np.inf)
        if ordered:
            lo_v[bins] = np.minimum.reduceat(x, starts)
            hi_v[bins] = np.maximum.reduceat(x, starts)
        else:
            np.minimum.at(lo_v, b, x)
            np.maximum.at(hi_v, b, x)
        var = np.where(hi_v > lo_v, var, np.where(ok, 0.0, np.nan))
        mean[:, j] = mu + ref
        std[:, j] = np.sqrt(np.maximum(var, 0))
    return cnt, mean, std


def noise_floor(std: np.ndarray) -> float:
    """The noise floor of one axis from its window standard deviations: the 10th percentile of the windows
    whose values vary at all (a quantised sensor at rest can show windows of identical values, std 0), or
    twice the ``FLOOR_QUIETEST``-th quietest where that is lower: a log that is mostly flight holds its rest
    in fewer than a tenth of its windows, and its 10th percentile is then the flight's (or the engine's on the
    ground) level. Twice the 5th quietest of 16-sample windows at rest is their level or more (the 5th of
    thousands is about 0.5x it), so a long rest log keeps its 10th percentile. A floor taken from the median
    spread instead lets engine vibration on the ground in as still."""
    c = np.sort(std[std > 0])
    if c.size == 0:
        return 0.0
    return float(min(np.percentile(c, 10), 2.0 * c[min(FLOOR_QUIETEST, c.size) - 1]))


def _gyro_level_test(mean, std, cnt, good, mv, floor0, floor, sd_lim, lsb,
                     down: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, GyroEvidence]:
    """The gyro's windows that turn (leave its level at rest about the vertical) or are frozen, those whose mean
    leaves the level on any axis, and the evidence of every window.

    A window of identical values is a frozen gyro, whatever value it holds, where a live one varies at rest
    (a float message; an integer one whose noise floor is half a step or more -- a gyro quieter than the step
    reads one code at rest): never still, and never part of the level at rest the means are tested against
    (a gyro frozen at a rate for most of a log would otherwise set that level). An axis that never varies is
    dead throughout: ``health.dead`` names it, it says nothing of motion.

    ``down``: per window the unit vector of the same IMU's accelerometer mean (NaN where unknown or not
    gravity). A turn the accelerometer cannot see is one about that vector (a yaw); a rate about a horizontal
    axis tilts the vehicle and the accelerometer's step test sees it, so where ``down`` is known only the mean's
    component along it is tested here: a gyro whose bias drifts about its horizontal axes (a rover's MPU-9250 by
    18 mrad/s over minutes on a bench, its accelerometer steady to 0.01 m/s^2) is not turning."""
    se = _mean_error(mean, cnt, good & ~mv, floor)
    varies = (floor0 > 0) & (np.full(floor0.shape, not lsb) | (floor0 >= 0.5 * (lsb or 0.0)))
    frozen = good & np.any((std == 0) & varies, axis=1)
    base = good & ~mv & ~frozen
    ref = np.nanmedian(mean[base], axis=0) if np.any(base) else np.nanmedian(mean[good], axis=0)
    dev, dev_lim = np.abs(mean - ref), MEAN_SIGMAS * se + GYRO_MEAN_OFFSET
    moved = np.any(dev > dev_lim, axis=1)
    level = moved | frozen
    if down is not None:
        known = np.all(np.isfinite(down), axis=1)
        d = np.where(known[:, None], down, 0.0)
        along = np.abs(np.sum((mean - ref) * d, axis=1))
        along_lim = MEAN_SIGMAS * np.sqrt(np.sum((se * d) ** 2, axis=1)) + GYRO_MEAN_OFFSET
        moved = np.where(known, along > along_lim, moved)
    moved |= frozen
    evidence = GyroEvidence(frozen, np.nan_to_num(np.nanmax(dev, axis=1, initial=0.0)),
                            np.nan_to_num(np.nanmax(std, axis=1, initial=0.0)),
                            np.nanmax(dev_lim, axis=1, initial=0.0), float(np.max(sd_lim)))
    return moved, level, evidence


def _mean_error(mean, cnt, quiet, floor) -> np.ndarray:
    """Per window and axis, the standard error of the window mean at rest: ``floor`` / sqrt(count) for white noise,
    or the scatter of the steps between neighbouring quiet windows where that is larger.

    Real sensors at rest are not white at the window's scale (a 1 s mean of an MPU-6000 on a rover's bench
    wanders by 3-7 mrad/s where its white noise allows 1; a 1 Hz telemetry stream samples a filtered signal): the
    white-noise error then calls every other window a turn or a tilt and cuts a quiet log into pieces shorter than
    the shortest still stretch. The steps' scatter is read robustly (1.4826 x their median absolute value, / sqrt 2
    for a difference of two means) over the pairs of neighbouring windows whose spread is at rest, so a few tilts
    or a drift do not widen it; with fewer than ``MIN_PAIRS`` such pairs the white-noise error stands."""
    se = floor / np.sqrt(np.maximum(cnt, 1))[:, None]
    pair = quiet[1:] & quiet[:-1]
    if pair.sum() < MIN_PAIRS:
        return se
    step = np.abs(np.diff(mean, axis=0))[pair]
    emp = 1.4826 * np.median(step, axis=0) / np.sqrt(2.0)
    # the scatter of an n-sample mean: scaled to each window's count from the pairs' typical count
    n_ref = float(np.median(cnt[1:][pair]))
    return np.maximum(se, emp[None, :] * np.sqrt(n_ref / np.maximum(cnt, 1))[:, None])


def _accel_step_test(mean, cnt, good, floor, loud) -> np.ndarray:
    """Windows whose accelerometer mean steps from the previous (or to the next) window by more than
    ``MEAN_SIGMAS`` standard errors (:func:`_mean_error`) + ``ACC_MEAN_STEP``: a slow tilt. A step next to a window
    already moving by its spread (``loud``) is that window's: its quiet neighbour is not marked for it."""
    se = _mean_error(mean, cnt, good & ~loud, floor)
    step = np.abs(np.diff(mean, axis=0))
    lim = MEAN_SIGMAS * np.sqrt(se[1:] ** 2 + se[:-1] ** 2) + ACC_MEAN_STEP
    jump = np.any(step > lim, axis=1) & good[1:] & good[:-1] & ~loud[1:] & ~loud[:-1]
    mv = np.zeros(mean.shape[0], dtype=bool)
    mv[1:] |= jump
    mv[:-1] |= jump
    return mv


def _gravity_direction(mean: np.ndarray, good: np.ndarray) -> np.ndarray:
    """Per window the unit vector of the accelerometer mean where it is gravity (its norm within 30 % of g), NaN
    elsewhere."""
    norm = np.linalg.norm(mean, axis=1)
    ok = good & np.isfinite(norm) & (np.abs(norm - STANDARD_G) < 0.3 * STANDARD_G)
    out = np.full(mean.shape, np.nan)
    out[ok] = mean[ok] / norm[ok, None]
    return out


def moving_windows(stream, t0: float, window_s: float, nb: int, threshold: float,
                   use_gyro: bool = True) -> StreamMotion:
    """The motion tests of one IMU stream over ``nb`` windows of ``window_s`` from ``t0`` (module docstring)."""
    b = np.floor((stream.t - t0) / window_s).astype(np.int64)
    inside = (b >= 0) & (b < nb)
    # every sample inside (the usual case): the stream's own arrays, not copies (48 MB for 1 M samples)
    inside = slice(None) if inside.all() else inside
    b = b[inside]
    out = StreamMotion(np.zeros(nb, dtype=bool), np.zeros(nb, dtype=bool), np.bincount(b, minlength=nb) >= 2)
    down = None  # the accelerometer's direction per window, for the gyro's level test
    for kind, v, abs_std, lsb in (("accel", stream.accel[inside], ABS_ACCEL_STD, stream.accel_lsb),
                                  ("gyro", stream.gyro[inside], ABS_GYRO_STD, stream.gyro_lsb)):
        if v.shape[0] == 0 or not np.all(np.isfinite(v[:, 0])) or (kind == "gyro" and not use_gyro):
            continue
        cnt, mean, std = bin_stats(b, v, nb)
        good = out.has & np.all(np.isfinite(std), axis=1)
        if good.sum() < 3:
            continue
        floor0 = np.array([noise_floor(c) for c in std[good].T])
        floor = np.maximum(floor0, 0.5 * (lsb or 0.0))
        floor = np.maximum(floor, 1e-12)
        with np.errstate(invalid="ignore"):
            sd_lim = np.minimum(threshold * floor, abs_std)
            mv = np.any(std > sd_lim, axis=1)
            if kind == "accel":
                mv |= _accel_step_test(mean, cnt, good, floor, mv)
                out.accel |= mv & good
                down = _gravity_direction(mean, good)
            else:
                moved, level, out.evidence = _gyro_level_test(mean, std, cnt, good, mv, floor0, floor, sd_lim,
                                                              lsb, down)
                out.gyro |= (mv | moved) & good
                out.level |= level & good
    return out
