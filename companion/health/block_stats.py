"""Per-block statistics of one IMU's gyro (the figures every fault detector reads; numpy only).

A block is one second or so of samples ``y`` (n, 3), rad/s. The white-noise figure is the variance of the
second differences dd_k = y_k - 2 y_{k-1} + y_{k-2} over 6 (for white noise var(dd) = 6 sigma^2), which smooth
motion barely enters; isolated outliers of dd (spikes) are counted and left out of it. The spike search runs in
named steps: the robust bar (:func:`_noise_bar`), the candidate peaks and their shape (:func:`_peaks`), their
isolation (:func:`_keep_isolated`), then the clean figures (:func:`_clean_figures`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SPIKE_K = 6.0  #: outlier threshold in robust sigmas of the second differences (see spikes.py)
LOCAL_MIN = 8  #: second differences per quarter of a block before the quarter's own scale is used
#: a block's noise (v2) needs this many samples; a shorter block feeds no reference and no noise, bias,
#: spikes or rest-stuck test (a stream below 4 Hz in 1-s blocks)
MIN_NOISE_SAMPLES = 5
CARRY = 6  #: samples of the previous block carried into a block's spike search (a spike's shape and isolation)
#: 1/efficiency of the second-difference variance: var(mean(dd^2)/6) = 3.89 sigma^4 / m for white noise
#: (autocovariances of dd: 6, -4, 1 sigma^2), i.e. nu = 2 m / 3.89 chi-square degrees of freedom.
DD_NU_PER_SAMPLE = 2.0 / (140.0 / 36.0)
MAD_TO_SIGMA = 0.6745  #: median |x| of a zero-mean normal over its sd: a MAD read as a robust sigma
ISOLATION = 0.5  #: a spike is isolated when nothing 2-5 samples away reaches this share of its |dd|
#: a half-spike flank: the neighbouring dd of opposite sign within these shares of the peak (ideal: A vs 2A)
FLANK_LO, FLANK_HI = 0.25, 0.75


@dataclass
class BlockStats:
    """Statistics of one block of one IMU (arrays of shape (3,), one per gyro axis).

    * ``n``: samples; ``mean``: block mean without the spike samples (rad/s); ``rms``: root mean square
    * ``v2``: white-noise variance from the second differences dd_k = y_k - 2 y_{k-1} + y_{k-2}, with the
      outliers (and their neighbours) left out: v2 = mean(dd^2) / 6. Smooth motion (a hand turning the
      vehicle, below ~2 Hz) barely enters (its second difference is (2 pi f / fs)^2 times its amplitude).
    * ``m2``: number of second differences used for v2 (chi-square dof nu = DD_NU_PER_SAMPLE * m2)
    * ``spikes``: isolated outliers |dd| > SPIKE_K robust sigmas (one count per spike: the local maximum);
      ``spikes_solo``: those not coinciding (+-1 sample) with one on another axis (a shock moves every axis)
    * ``top``: max |y|; ``top_run``: longest run of consecutive samples at exactly +-top
    * ``temperature``: mean IMU temperature of the block (degC; nan when the source has none)
    * ``changes``: number of consecutive samples that differ (0: every value equal); ``step``: the
      smallest non-zero |y_k - y_{k-1}| (nan without change)
    """

    n: int
    mean: np.ndarray
    rms: np.ndarray
    v2: np.ndarray
    m2: np.ndarray
    spikes: np.ndarray
    spikes_solo: np.ndarray
    top: np.ndarray
    top_run: np.ndarray
    changes: np.ndarray
    step: np.ndarray
    temperature: float = math.nan  # the block's mean IMU temperature (degC) where the source has it
    spike_size: np.ndarray | None = None  # sum over the spikes of ln(|dd| / bar) (spikes.py)
    spike_size_solo: np.ndarray | None = None  # the same over ``spikes_solo``



@dataclass
class _Plain:
    """The figures of a block that need no spike search."""

    n: int
    mean: np.ndarray
    rms: np.ndarray
    top: np.ndarray
    top_run: np.ndarray
    changes: np.ndarray
    step: np.ndarray


@dataclass
class _SpikeSearch:
    """The spike search over the block with its carried samples in front (``c0`` of them)."""

    dd: np.ndarray  # second differences, (m, 3)
    a: np.ndarray  # |dd|
    bar: np.ndarray  # the robust scale each |dd| was judged against (times k: the threshold)
    out: np.ndarray  # |dd| beyond k bar (and, in a short block, every second difference of a spike)
    peak: np.ndarray  # the spikes: isolated local maxima of the outliers, centred on sample j + 1
    c0: int


def block_stats(y: np.ndarray, dd_scale_ref: np.ndarray | None = None, k: float = SPIKE_K,
                prev: np.ndarray | None = None) -> BlockStats:
    """Per-axis statistics of a block ``y`` of shape (n, 3) (rad/s). ``prev``: the samples just before the
    block (the previous block's last ``CARRY`` ones, contiguous in time), or None. A spike's second
    difference is centred on its sample, so the block's own first and last samples are never a centre: with
    ``prev`` the previous block's last sample and this block's first become centres here (each sample is a
    centre in exactly one block), and the carried samples give the shape and isolation tests their context.
    Only the spike search reads ``prev``; every other figure is the block's own."""
    y = np.asarray(y, dtype=float)
    p = _plain_figures(y)
    if p.n < MIN_NOISE_SAMPLES:
        z = np.zeros(y.shape[1])
        return BlockStats(p.n, p.mean, p.rms, np.full(y.shape[1], np.nan), z, z, z, p.top, p.top_run, p.changes,
                          p.step, spike_size=z, spike_size_solo=z)
    ext, c0 = _with_carry(y, prev, dd_scale_ref)
    sp = _search_spikes(ext, c0, p.step, dd_scale_ref, k)
    spikes = np.count_nonzero(sp.peak, axis=0)
    # the size of each spike in robust sigmas beyond the bar, ln(|dd| / (k bar)) >= 0 (spikes.py weighs it)
    size = np.where(sp.peak, np.log(np.maximum(sp.a / np.maximum(k * sp.bar, 1e-300), 1.0)), 0.0)
    solo = _solo(sp.peak)
    mean, m2, v2 = _clean_figures(ext, sp, p.mean)
    return BlockStats(p.n, mean, p.rms, v2, m2.astype(float), spikes, np.count_nonzero(solo, axis=0), p.top,
                      p.top_run, p.changes, p.step, spike_size=size.sum(axis=0),
                      spike_size_solo=np.where(solo, size, 0.0).sum(axis=0))


def _plain_figures(y: np.ndarray) -> _Plain:
    n = y.shape[0]
    top = np.max(np.abs(y), axis=0)
    at_top = np.abs(y) == top
    dy = np.abs(np.diff(y, axis=0)) if n > 1 else np.zeros((0, y.shape[1]))
    changes = np.count_nonzero(dy, axis=0)
    step = np.where(changes > 0, np.min(np.where(dy > 0, dy, np.inf), axis=0, initial=np.inf), np.nan)
    return _Plain(n, y.mean(axis=0), np.sqrt(np.mean(y * y, axis=0)), top,
                  np.array([_longest_run(at_top[:, j]) for j in range(y.shape[1])]), changes, step)


def _with_carry(y: np.ndarray, prev, dd_scale_ref) -> tuple[np.ndarray, int]:
    """The block with the previous block's last samples in front (with a reference only: before it, a block's
    spikes are judged on their own), and how many were put there."""
    if prev is not None and dd_scale_ref is not None:
        prev = np.asarray(prev, dtype=float)[-CARRY:]
        if prev.ndim == 2 and prev.shape[1] == y.shape[1] and prev.shape[0] >= 3 and np.all(np.isfinite(prev)):
            return np.concatenate([prev, y]), prev.shape[0]
    return y, 0


def _search_spikes(y: np.ndarray, c0: int, step: np.ndarray, dd_scale_ref, k: float) -> _SpikeSearch:
    dd = y[2:] - 2.0 * y[1:-1] + y[:-2]
    a = np.abs(dd)
    nb = _noise_bar(a, dd, step, dd_scale_ref)
    bar = nb.bar
    out = a > k * bar
    # a spike is looked for against a bar it does not raise itself: in a short block (10 Hz: 8 second
    # differences) a quarter of two holds the spike's own -2A and A, so there, once the still reference
    # exists, the quarters are left out (LOCAL_MIN per quarter) and the isolation test does their work.
    # There the block's own smallest step is no floor when it is itself an outlier against the reference
    # (which holds the learned resolution, ImuFaults.dd_scale_ref): a gyro resting on one code whose only
    # change is the spike has the spike for its step.
    short = not (a.shape[0] - c0 >= 4 * LOCAL_MIN or dd_scale_ref is None)
    if short:
        ref = np.asarray(dd_scale_ref, dtype=float)
        bar = np.broadcast_to(np.maximum(nb.scale, np.where((ref > 1e-9) & (nb.code > k * ref), 0.0, nb.code)), a.shape)
        cand = a > k * bar
    else:
        cand = out
    peak = _peaks(cand, a, dd, short, c0)
    _keep_isolated(peak, a)
    if short:  # the spike's second differences (its -2A, the A either side) are not noise
        out = out | peak
        out[1:] |= peak[:-1]
        out[:-1] |= peak[1:]
    return _SpikeSearch(dd, a, bar, out, peak, c0)


@dataclass
class _NoiseBar:
    """The scales the second differences are judged against (robust sigmas, per axis or per difference)."""

    scale: np.ndarray  # the block's MAD, at least the reference's (or half the block's rms before one)
    bar: np.ndarray  # per second difference: the largest of scale, the local scale and the rounding's floor
    code: np.ndarray  # the rounding's floor: sd of the second differences of a signal rounded to its step


def _noise_bar(a: np.ndarray, dd: np.ndarray, step: np.ndarray, dd_scale_ref) -> _NoiseBar:
    """The bar of the second differences: the larger of the block's MAD (at least the reference's, or half the
    block's rms before a reference), the local MAD of each quarter and its neighbours (vibration that starts
    mid-block is not a spike) and what rounding gives."""
    scale = np.median(a, axis=0) / MAD_TO_SIGMA
    floor = 0.5 * np.sqrt(np.mean(dd * dd, axis=0))  # only matters where the median is 0 (coarse rounding)
    scale = np.maximum(scale, floor if dd_scale_ref is None else np.maximum(dd_scale_ref, 1e-12))
    m = a.shape[0]
    parts = np.array_split(np.arange(m), min(4, m))  # four near-equal quarters (no short remainder)
    if m % len(parts) == 0:  # equal quarters: one median call (the same values)
        qs = np.median(a.reshape(len(parts), m // len(parts), a.shape[1]), axis=1) / MAD_TO_SIGMA
    else:
        qs = np.array([np.median(a[p], axis=0) / MAD_TO_SIGMA for p in parts])
    qmax = np.maximum(qs, np.maximum(np.vstack([qs[:1], qs[:-1]]), np.vstack([qs[1:], qs[-1:]])))
    local = np.repeat(qmax, [p.size for p in parts], axis=0)
    # a signal rounded to a step q carries rounding error of variance q^2/12, so its second differences have
    # sd >= q sqrt(6/12) whatever the reference says (a gyro quieter than the int16 step sits on one code, then
    # flips to the next one or two and back: noise, not spikes)
    code = math.sqrt(0.5) * np.where(np.isfinite(step), step, 0.0)
    return _NoiseBar(scale, np.maximum(np.maximum(scale, local), code), code)


def _peaks(cand: np.ndarray, a: np.ndarray, dd: np.ndarray, short: bool, c0: int) -> np.ndarray:
    """Local maxima of the candidate outliers; in a short block only the whole shape of a spike inside the
    block counts: -2A flanked by A and A of the other sign (a motion that starts at the block's end rises on
    one side only). The carried samples' own centres belong to the previous block (counted there)."""
    prev_a = np.vstack([np.zeros((1, a.shape[1])), a[:-1]])
    nxt = np.vstack([a[1:], np.zeros((1, a.shape[1]))])
    peak = cand & (a >= prev_a) & (a > nxt)
    if short:
        pd = np.vstack([np.zeros((1, a.shape[1])), dd[:-1]])
        nd = np.vstack([dd[1:], np.zeros((1, a.shape[1]))])
        half_p = (pd * dd < 0) & (np.abs(pd) > FLANK_LO * a) & (np.abs(pd) < FLANK_HI * a)
        half_n = (nd * dd < 0) & (np.abs(nd) > FLANK_LO * a) & (np.abs(nd) < FLANK_HI * a)
        shape = half_p & half_n
        shape[-1] = half_p[-1]  # at the block's end the one flank inside it
        if c0 == 0:
            shape[0] = half_n[0]
        peak &= shape
    if c0 > 2:
        peak[:c0 - 2] = False
    return peak


def _keep_isolated(peak: np.ndarray, a: np.ndarray) -> None:
    """Drop (in place) the peaks with anything above ``ISOLATION`` of them 2-5 samples away: a spike is -2A
    flanked by A, then noise."""
    for j, c in zip(*np.nonzero(peak)):
        around = np.concatenate([a[max(j - 5, 0):max(j - 1, 0), c], a[j + 2:j + 6, c]])
        if around.size and around.max() >= ISOLATION * a[j, c]:
            peak[j, c] = False


def _solo(peak: np.ndarray) -> np.ndarray:
    """The spikes not coinciding (+-1 sample) with one on another axis (a shock moves every axis)."""
    near = peak.copy()
    near[1:] |= peak[:-1]
    near[:-1] |= peak[1:]
    others = near.sum(axis=1, keepdims=True) - near
    return peak & (others == 0)


def _clean_figures(y: np.ndarray, sp: _SpikeSearch, mean: np.ndarray):
    """(mean without the spike samples, second differences used, v2) over the block's own samples: the
    outliers and their neighbouring second differences left out of v2."""
    bad = sp.out.copy()
    bad[1:] |= sp.out[:-1]
    bad[:-1] |= sp.out[1:]
    spike_sample = np.zeros(y.shape, dtype=bool)  # dd_j is centred on sample j + 1
    spike_sample[1:-1] = sp.out
    c0 = sp.c0
    y, spike_sample = y[c0:], spike_sample[c0:]
    dd, keep = sp.dd[c0:], ~bad[c0:]
    clean = ~spike_sample
    mean = np.where(clean.any(axis=0), np.sum(np.where(clean, y, 0.0), axis=0) / np.maximum(clean.sum(axis=0), 1), mean)
    m2 = keep.sum(axis=0)
    v2 = np.where(m2 > 0, np.sum(np.where(keep, dd * dd, 0.0), axis=0) / np.maximum(m2, 1) / 6.0, np.nan)
    return mean, m2, v2


def _longest_run(mask: np.ndarray) -> int:
    if not mask.any():
        return 0
    m = np.concatenate(([0], mask.view(np.int8) if mask.dtype == bool else mask.astype(np.int8), [0]))
    d = np.diff(m)
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return int((ends - starts).max())

