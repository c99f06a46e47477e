"""Fault taxonomy of a gyro: the common interface of the fault detectors, their codes and block statistics.

Every detector (one module per kind: ``stuck``, ``noise``, ``bias``, ``spikes``, ``saturation``,
``resolution``, ``timing``, ``disagreement``) implements :class:`FaultDetector`, in the spirit of PX4's
DataValidator (small explicit states, named thresholds, one update):

* ``update(obs: Observation) -> list[FaultEvent]``: one block's :class:`Observation` (the block's
  ``BlockStats``, timestamps, still or not, the axis and its reference, the Allan-predicted extra variance of
  a block mean, and for a pair of IMUs the aligned samples of both); it returns the state changes
  (OK -> FAULT or FAULT -> OK) as events, empty when nothing changed (the bias detector may return two:
  a jump and a drift);
* ``state`` is ``OK`` or ``FAULT``; ``value`` the figure the report quotes (ratio, offset, percentage);
* ``state_dict()`` / ``load_state_dict()`` for the run state file.

Most detectors are a CUSUM (Page 1954) of a per-block log-likelihood ratio (LLR, nats) between a
healthy hypothesis H0 (the reference learned from still data) and a fault hypothesis H1:

    S_k = max(0, S_{k-1} + llr_k),   FAULT when S_k > h                                      (1)

A CUSUM with threshold h has an in-control average run length of about e^h blocks (Lorden's bound:
ARL0 >= e^h), and a detection delay close to h / KL(H1 || H0), the information limit for that
false-alarm rate (Lorden 1971). Once in FAULT the same recursion with -llr (evidence for healthy)
clears it when it exceeds ``h_off``. The others count consecutive bad / good blocks (:func:`debounce`).

Reported as NAMED_VALUE_FLOAT: ``IMU{i}G_FLT`` the code of the most severe active fault (``KIND_CODE``,
order ``PRIORITY``) and ``IMU{i}G_FLM`` the bitmask of every active fault (bit k set: code k active,
:func:`fault_mask`), so that faults present together are all seen. Pure numpy; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Iterable, Mapping, Protocol

import numpy as np

from companion.health.hold import FAULT, OK, debounce  # noqa: F401  (re-exported)

#: fault kind -> code sent as IMU{i}G_FLT (0: no fault) and bit in IMU{i}G_FLM. The highest-priority active
#: kind (lowest position in PRIORITY) is the code reported.
KIND_CODE = {
    "none": 0,
    "stuck": 1,
    "noise": 2,
    "bias_jump": 3,
    "bias_drift": 4,
    "spikes": 5,
    "saturation": 6,
    "rate": 7,
    "disagree": 8,
    "allan": 9,
    "resolution": 10,
    "dead": 11,
}
PRIORITY = ("stuck", "dead", "disagree", "saturation", "noise", "spikes", "resolution", "bias_jump", "bias_drift",
            "rate", "allan")
#: kinds sent as CRITICAL (MAV_SEVERITY_CRITICAL = 2); in-flight disagreement too (decided by the caller)
CRITICAL_KINDS = ("stuck",)


@dataclass
class FaultEvent:
    """One state change of one detector: what the STATUSTEXT says."""

    imu: int
    axis: str  # "gx", "gy", "gz", or "" for the whole IMU (timing)
    kind: str
    state: int  # FAULT or OK
    value: float = math.nan
    detail: str = ""  # extra words (e.g. "IMU0/IMU2" for a disagreement)
    critical: bool = False

    def text(self) -> str:
        """STATUSTEXT (<= 50 characters), e.g. ``IMU0 gyro X noise 6.1x baseline``."""
        where = f"IMU{self.imu} gyro" + (f" {self.axis[1].upper()}" if self.axis else "")
        if self.state == OK:
            return f"{where} {KIND_WORDS[self.kind]} cleared"[:50]
        v = self.value
        body = {
            "stuck": "stuck",
            "noise": f"noise {v:.1f}x baseline",
            "bias_jump": f"bias jump {v:+.2f} deg/s",
            "bias_drift": f"bias drift {v:+.2f} deg/s",
            "spikes": f"spikes {v:.2g} %",
            "saturation": f"saturated at {v:.3g} rad/s",
            "rate": self.detail or f"rate {v:.0f} Hz",
            "disagree": f"disagrees with {self.detail}",
            "allan": self.detail,
            "resolution": f"resolution lost: steps {v:.0f}x LSB",
            "dead": DEAD_WORDS.get(self.detail, DEAD_WORDS[""]),
        }[self.kind]
        return f"{where} {body}"[:50]


KIND_WORDS = {"stuck": "stuck", "noise": "noise", "bias_jump": "bias jump", "bias_drift": "bias drift",
              "spikes": "spikes", "saturation": "saturation", "rate": "timing", "disagree": "disagreement",
              "allan": "Allan terms", "resolution": "resolution loss", "dead": "zero reading"}
#: an axis reading exactly 0 in every sample (health/stuck.py): on integer messages (RAW_IMU, SCALED_IMU*:
#: int16 mrad/s) a gyro whose noise is below the 1 mrad/s step also reads 0 at rest, so the text says both;
#: a float message (HIGHRES_IMU, DataFlash, ULog) never reads exactly 0 from a live gyro, nor does a gyro
#: of a moving vehicle
DEAD_WORDS = {"": "reads 0: dead or below resolution", "float": "reads exactly 0: dead",
              "moving": "reads 0 while moving: dead"}


AXES = ("gx", "gy", "gz")


def fault_mask(kinds: Iterable[str]) -> int:
    """Bitmask of active fault kinds: bit ``KIND_CODE[kind]`` set for each (``IMU{i}G_FLM``; exact in a float32
    up to 2^24)."""
    m = 0
    for k in kinds:
        m |= 1 << KIND_CODE[k]
    return m


def mask_kinds(mask: int) -> list[str]:
    """The kinds whose bits are set in ``mask`` (inverse of :func:`fault_mask`)."""
    return [k for k, c in KIND_CODE.items() if c and int(mask) >> c & 1]


@dataclass
class Observation:
    """What a fault detector sees of one block of one IMU (the one argument of ``update``).

    * ``imu``: the IMU; ``axis``: "gx", "gy", "gz" for a per-axis detector ("" for the whole IMU);
    * ``stats``: the block's statistics (``BlockStats``, one column per axis); ``t``: its timestamps (s);
    * ``still``: the motion gate's decision for the block; ``ref``: the axis' still reference (``AxisRef``);
    * ``extra_var``: Allan-predicted variance of a block mean around the bias reference ((rad/s)^2);
    * ``y``: the block's samples (n, 3) (per-block detectors: the stuck test reads their codes);
    * pairs of IMUs: ``y`` and ``other`` the aligned samples (m, 3) of this IMU and of ``other_imu``,
      ``noise_var`` the white variance expected of their difference, ``noise_other`` the other IMU's own;
    * ``vibration``: the same IMU's accelerometer second-difference variance over its still reference (three
      axes pooled; nan before the reference or without an accelerometer): what the rest of the sensor sees;
      ``accel_quiet``: that accelerometer's second differences all stayed within ``SPIKE_K`` of their still
      scale in the block (False when unknown): no knock or jolt of the vehicle in it; ``accel_knock``: it
      moved beyond that scale for more than ``KNOCK_RUN`` samples in a row (the block's own robust scale
      before the reference exists): a knock or a touch, not an isolated glitch of the sensor.
    """

    imu: int = 0
    stats: BlockStats | None = None
    t: np.ndarray | None = None
    still: bool = True
    axis: str = ""
    ref: AxisRef | None = None
    extra_var: float = 0.0
    y: np.ndarray | None = None
    other: np.ndarray | None = None
    other_imu: int = -1
    noise_var: float | None = None
    noise_other: float | None = None
    vibration: float = math.nan
    accel_quiet: bool = False
    accel_knock: bool = False

    @property
    def col(self) -> int:
        """Column of ``axis`` in ``stats`` and in the samples."""
        return AXES.index(self.axis)

    def at(self, axis: str, ref: "AxisRef | None" = None, **kw) -> "Observation":
        """The same block seen by the detector of one axis."""
        return replace(self, axis=axis, ref=ref, **kw)

    def event(self, kind: str, state: int, value: float = math.nan, detail: str = "",
              critical: bool = False) -> "FaultEvent":
        return FaultEvent(self.imu, self.axis, kind, state, value, detail, critical)


class FaultDetector(Protocol):
    """The interface every fault detector implements (see the module docstring)."""

    kind: str
    state: int
    value: float

    def update(self, obs: Observation) -> list[FaultEvent]: ...

    def state_dict(self) -> dict: ...

    def load_state_dict(self, d: Mapping) -> None: ...


class Cusum:
    """One-sided CUSUM (1) with a reverse CUSUM that clears the fault; plain floats."""

    def __init__(self, h_on: float, h_off: float):
        self.h_on, self.h_off = float(h_on), float(h_off)
        self.state = OK
        self.s = 0.0  # evidence for the fault (while OK) or for healthy (while FAULT)

    def step(self, llr: float) -> bool:
        """Add one block's LLR (positive favours the fault); return True when the state changed."""
        if not math.isfinite(llr):
            return False
        if self.state == OK:
            self.s = max(0.0, self.s + llr)
            if self.s > self.h_on:
                self.state, self.s = FAULT, 0.0
                return True
        else:
            self.s = max(0.0, self.s - llr)
            if self.s > self.h_off:
                self.state, self.s = OK, 0.0
                return True
        return False

    def state_dict(self) -> dict:
        return {"state": self.state, "s": self.s}

    def load_state_dict(self, d: Mapping) -> None:
        self.state, self.s = int(d.get("state", OK)), float(d.get("s", 0.0))


def chi2_llr(u: float, nu: float, r1: float) -> float:
    """LLR of a variance ratio r1 against 1 for one block: u = s^2 / sigma0^2 with nu degrees of freedom.

    nu s^2 / sigma^2 ~ chi2(nu): llr = (nu / 2) * ((1 - 1 / r1) * u - ln r1).
    """
    return 0.5 * nu * ((1.0 - 1.0 / r1) * u - math.log(r1))


def gauss_mean_llr(x: float, sigma: float, delta: float) -> float:
    """Two-sided-ready LLR of a mean shift ``delta`` (same sign as wanted) for one block mean x +- sigma."""
    return (delta / (sigma * sigma)) * (x - 0.5 * delta)


# --------------------------------------------------------------------------------------------- block statistics
SPIKE_K = 6.0  # outlier threshold in robust sigmas of the second differences (see spikes.py)
LOCAL_MIN = 8  # second differences per quarter of a block before the quarter's own scale is used
#: a block's noise (v2) needs this many samples; a shorter block feeds no reference and no noise, bias,
#: spikes or rest-stuck test (a stream below 4 Hz in 1-s blocks)
MIN_NOISE_SAMPLES = 5
#: The noise test's level is learned from the reference's blocks and on until they hold NU_REF_MIN chi-square
#: degrees of freedom (white second differences; at most REF_MAX_FACTOR x ref_blocks blocks); the other tests
#: start from the reference of ref_blocks as before. A level below the truth by a factor persists in every test
#: against it: the noise test's CUSUM (noise.py) drifts up on a healthy gyro once it is 22 % low. 30 blocks of
#: 50 Hz hold 756 dof (22 % is 4.3 standard errors), 30 blocks of 10 Hz 123 (1.7): a healthy copter streamed at
#: 10 Hz was called noisy 5 times in 48 IMU-hours, at 4 Hz 3 times in 18. With 700 dof the 10 Hz level takes
#: about 3 minutes of rest; a 4 Hz one (5 samples a block, 1.5 dof) stops at the cap, 5 minutes and 370 dof (22 %
#: is 3 standard errors there).
NU_REF_MIN = 700.0
REF_MAX_FACTOR = 8
CARRY = 6  # samples of the previous block carried into a block's spike search (a spike's shape and isolation)
#: 1/efficiency of the second-difference variance: var(mean(dd^2)/6) = 3.89 sigma^4 / m for white noise
#: (autocovariances of dd: 6, -4, 1 sigma^2), i.e. nu = 2 m / 3.89 chi-square degrees of freedom.
DD_NU_PER_SAMPLE = 2.0 / (140.0 / 36.0)
#: an accelerometer beyond SPIKE_K of its scale over more than this many second differences (outliers at most
#: two samples apart: a ringing knock crosses zero) moved: a knock lasts several samples (a public PX4 log's
#: taps on a standing vehicle: 6-10 at 200 Hz, 20-40 sigma), an isolated outlier of the sensor 3 (+1, -2, +1)
KNOCK_RUN = 3
#: A reference block whose v2 is above KNOCK x the median of the reference blocks is not rest: a knock or a
#: touch the motion gate passed as still. At rest that is chance only far in the tail (chi^2 with 4 dof above
#: 8.4x its mean: 1e-6). Left out of the rest level (AxisRef.rest) that a collapse of the noise is judged
#: against; kept in the noise level that a rise is judged against (see AxisRef).
KNOCK = 10.0


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


def block_stats(y: np.ndarray, dd_scale_ref: np.ndarray | None = None, k: float = SPIKE_K,
                prev: np.ndarray | None = None) -> BlockStats:
    """Per-axis statistics of a block ``y`` of shape (n, 3) (rad/s). ``prev``: the samples just before the
    block (the previous block's last ``CARRY`` ones, contiguous in time), or None. A spike's second
    difference is centred on its sample, so the block's own first and last samples are never a centre: with
    ``prev`` the previous block's last sample and this block's first become centres here (each sample is a
    centre in exactly one block), and the carried samples give the shape and isolation tests their context.
    Only the spike search reads ``prev``; every other figure is the block's own."""
    y = np.asarray(y, dtype=float)
    n = y.shape[0]
    mean = y.mean(axis=0)
    rms = np.sqrt(np.mean(y * y, axis=0))
    top = np.max(np.abs(y), axis=0)
    at_top = np.abs(y) == top
    top_run = np.array([_longest_run(at_top[:, j]) for j in range(y.shape[1])])
    dy = np.abs(np.diff(y, axis=0)) if n > 1 else np.zeros((0, y.shape[1]))
    changes = np.count_nonzero(dy, axis=0)
    step = np.where(changes > 0, np.min(np.where(dy > 0, dy, np.inf), axis=0, initial=np.inf), np.nan)
    if n < MIN_NOISE_SAMPLES:
        z = np.zeros(y.shape[1])
        return BlockStats(n, mean, rms, np.full(y.shape[1], np.nan), z, z, z, top, top_run, changes, step,
                          spike_size=z, spike_size_solo=z)
    c0 = 0  # carried samples before the block
    if prev is not None and dd_scale_ref is not None:
        prev = np.asarray(prev, dtype=float)[-CARRY:]
        if prev.ndim == 2 and prev.shape[1] == y.shape[1] and prev.shape[0] >= 3 and np.all(np.isfinite(prev)):
            c0 = prev.shape[0]
            y = np.concatenate([prev, y])
    dd = y[2:] - 2.0 * y[1:-1] + y[:-2]
    a = np.abs(dd)
    scale = np.median(a, axis=0) / 0.6745
    floor = 0.5 * np.sqrt(np.mean(dd * dd, axis=0))  # only matters where the median is 0 (coarse rounding)
    scale = np.maximum(scale, floor if dd_scale_ref is None else np.maximum(dd_scale_ref, 1e-12))
    # local scale: the MAD of each quarter and its neighbours (vibration that starts mid-block is not a spike)
    m = a.shape[0]
    parts = np.array_split(np.arange(m), min(4, m))  # four near-equal quarters (no short remainder)
    if m % len(parts) == 0:  # equal quarters: one median call (the same values)
        qs = np.median(a.reshape(len(parts), m // len(parts), a.shape[1]), axis=1) / 0.6745
    else:
        qs = np.array([np.median(a[p], axis=0) / 0.6745 for p in parts])
    qmax = np.maximum(qs, np.maximum(np.vstack([qs[:1], qs[:-1]]), np.vstack([qs[1:], qs[-1:]])))
    local = np.repeat(qmax, [p.size for p in parts], axis=0)
    # and at least the spread rounding gives: a signal rounded to a step q carries rounding error of variance
    # q^2/12, so its second differences have sd >= q sqrt(6/12) whatever the reference says (a gyro quieter
    # than the int16 step sits on one code, then flips to the next one or two and back: noise, not spikes)
    code = math.sqrt(0.5) * np.where(np.isfinite(step), step, 0.0)
    bar = np.maximum(np.maximum(scale, local), code)
    out = a > k * bar
    # a spike is looked for against a bar it does not raise itself: in a short block (10 Hz: 8 second
    # differences) a quarter of two holds the spike's own -2A and A, so there, once the still reference
    # exists, the quarters are left out (LOCAL_MIN per quarter) and the isolation test below does their work
    # There the block's own smallest step is no floor when it is itself an outlier against the reference
    # (which holds the learned resolution, ImuFaults.dd_scale_ref): a gyro resting on one code whose only
    # change is the spike has the spike for its step.
    short = not (m - c0 >= 4 * LOCAL_MIN or dd_scale_ref is None)
    if short:
        ref = np.asarray(dd_scale_ref, dtype=float)
        bar = np.broadcast_to(np.maximum(scale, np.where((ref > 1e-9) & (code > k * ref), 0.0, code)), a.shape)
        cand = a > k * bar
    else:
        cand = out
    prev_a = np.vstack([np.zeros((1, a.shape[1])), a[:-1]])
    nxt = np.vstack([a[1:], np.zeros((1, a.shape[1]))])
    peak = cand & (a >= prev_a) & (a > nxt)
    if short:
        # without the quarters, only the whole shape of a spike inside the block counts: -2A flanked by A
        # and A of the other sign (a motion that starts at the block's end rises on one side only)
        pd = np.vstack([np.zeros((1, a.shape[1])), dd[:-1]])
        nd = np.vstack([dd[1:], np.zeros((1, a.shape[1]))])
        half_p = (pd * dd < 0) & (np.abs(pd) > 0.25 * a) & (np.abs(pd) < 0.75 * a)
        half_n = (nd * dd < 0) & (np.abs(nd) > 0.25 * a) & (np.abs(nd) < 0.75 * a)
        shape = half_p & half_n
        shape[-1] = half_p[-1]  # at the block's end the one flank inside it
        if c0 == 0:
            shape[0] = half_n[0]
        peak &= shape
    # the carried samples' own centres belong to the previous block (counted there): only context here
    if c0 > 2:
        peak[:c0 - 2] = False
    # isolated: nothing above half the peak 2-5 samples away (a spike is -2A flanked by A, then noise)
    for j, c in zip(*np.nonzero(peak)):
        around = np.concatenate([a[max(j - 5, 0):max(j - 1, 0), c], a[j + 2:j + 6, c]])
        if around.size and around.max() >= 0.5 * a[j, c]:
            peak[j, c] = False
    if short:  # the spike's second differences (its -2A, the A either side) are not noise
        out = out | peak
        out[1:] |= peak[:-1]
        out[:-1] |= peak[1:]
    spikes = np.count_nonzero(peak, axis=0)
    # the size of each spike in robust sigmas beyond the bar, ln(|dd| / (k bar)) >= 0 (spikes.py weighs it)
    size = np.where(peak, np.log(np.maximum(a / np.maximum(k * bar, 1e-300), 1.0)), 0.0)
    near = peak.copy()
    near[1:] |= peak[:-1]
    near[:-1] |= peak[1:]
    others = near.sum(axis=1, keepdims=True) - near  # peaks of the other axes within +-1 sample
    solo = peak & (others == 0)
    spikes_solo = np.count_nonzero(solo, axis=0)
    bad = out.copy()
    bad[1:] |= out[:-1]
    bad[:-1] |= out[1:]
    spike_sample = np.zeros(y.shape, dtype=bool)  # dd_j is centred on sample j + 1
    spike_sample[1:-1] = out
    # back to the block's own samples and second differences
    y, spike_sample = y[c0:], spike_sample[c0:]
    dd, keep = dd[c0:], ~bad[c0:]
    clean = ~spike_sample
    mean = np.where(clean.any(axis=0), np.sum(np.where(clean, y, 0.0), axis=0) / np.maximum(clean.sum(axis=0), 1), mean)
    m2 = keep.sum(axis=0)
    v2 = np.where(m2 > 0, np.sum(np.where(keep, dd * dd, 0.0), axis=0) / np.maximum(m2, 1) / 6.0, np.nan)
    return BlockStats(n, mean, rms, v2, m2.astype(float), spikes, spikes_solo, top, top_run, changes, step,
                      spike_size=size.sum(axis=0), spike_size_solo=np.where(solo, size, 0.0).sum(axis=0))


def _longest_run(mask: np.ndarray) -> int:
    if not mask.any():
        return 0
    m = np.concatenate(([0], mask.view(np.int8) if mask.dtype == bool else mask.astype(np.int8), [0]))
    d = np.diff(m)
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return int((ends - starts).max())


@dataclass
class AxisRef:
    """What healthy still data of one axis looks like, learned from the first ``ref_blocks`` quiet blocks.

    * ``sigma2``: white-noise variance (pooled v2), ``nu``: chi-square dof of one block's v2, the smaller of
      the white-noise figure and the one measured from the spread of v2 (coarse rounding spreads it)
    * ``mu``: mean rate (the bias at the start), ``spike_rate``: outliers per sample
    * ``rest``: the same white-noise level and dof from the blocks that are not knocks (v2 at most ``KNOCK``
      x the median), for the stuck detector. Why two: one knock among a public copter log's 30 reference
      blocks (400x the others) made the mean 15x the rest level, and after a restart the same rest read as a
      collapse of the noise (stuck). Left out of the level a noise *rise* is judged against, the roll gyro of
      a parked plane rocking in the wind (bursts 10x its rest, the accelerometer quiet, one IMU) became a
      noise fault; a rest level never above the mean only makes a collapse harder to claim.
    """

    sigma2: float = math.nan
    nu: float = math.nan
    sigma2_rest: float = math.nan
    nu_rest: float = math.nan
    mu: float = math.nan
    spike_rate: float = 0.0
    blocks: int = 0
    noise_sigma2: float = math.nan  # the noise test's level: these blocks and on to NU_REF_MIN dof
    noise_nu: float = math.nan
    _v2: list | None = None
    _mu: list | None = None
    _spk: int = 0
    _samples: int = 0
    _nu_sum: float = 0.0

    @property
    def ready(self) -> bool:
        return math.isfinite(self.sigma2)

    @property
    def noise_ready(self) -> bool:
        """The noise test's level is learned (with the reference from 50 Hz up, up to minutes later below)."""
        return math.isfinite(self.noise_sigma2)

    @property
    def rest(self) -> "RestLevel":
        """The rest level (knocks left out); the plain level for a reference saved without one."""
        if math.isfinite(self.sigma2_rest):
            return RestLevel(self.sigma2_rest, self.nu_rest)
        return RestLevel(self.sigma2, self.nu)

    def add(self, v2: float, m2: float, mean: float, spikes: int, n: int, ref_blocks: int) -> bool:
        """Add one quiet block; returns True when the reference becomes ready. Once it is, blocks still go to
        the noise test's level until that holds NU_REF_MIN dof (noise_ready)."""
        if self.noise_ready or not math.isfinite(v2):
            return False
        nu_white = DD_NU_PER_SAMPLE * max(m2, 1.0)
        self._nu_sum += nu_white
        if self._v2 is None:
            self._v2, self._mu = [], []
        self._v2.append(v2)
        if self.ready:
            if self._nu_sum >= NU_REF_MIN or len(self._v2) >= REF_MAX_FACTOR * ref_blocks:
                self.noise_sigma2, self.noise_nu = _pooled(np.asarray(self._v2), nu_white)
                self._v2 = None
            return False
        self._mu.append(mean)
        self._spk += int(spikes)
        self._samples += int(n)
        self.blocks += 1
        if self.blocks < ref_blocks:
            return False
        v = np.asarray(self._v2)
        self.sigma2, self.nu = _pooled(v, nu_white)
        med = float(np.median(v))
        rest = v[v <= KNOCK * med] if med > 0 else v
        self.sigma2_rest, self.nu_rest = _pooled(rest, nu_white) if rest.size >= 2 else (self.sigma2, self.nu)
        self.mu = float(np.mean(self._mu))
        self.spike_rate = self._spk / max(self._samples, 1)
        self._mu = None
        if self._nu_sum >= NU_REF_MIN:
            self.noise_sigma2, self.noise_nu = self.sigma2, self.nu
            self._v2 = None
        return True

    def state_dict(self) -> dict:
        return {"sigma2": _f(self.sigma2), "nu": _f(self.nu), "sigma2_rest": _f(self.sigma2_rest),
                "nu_rest": _f(self.nu_rest), "mu": _f(self.mu), "spike_rate": self.spike_rate,
                "blocks": self.blocks, "v2": self._v2, "means": self._mu, "spk": self._spk, "samples": self._samples,
                "noise_sigma2": _f(self.noise_sigma2), "noise_nu": _f(self.noise_nu), "nu_sum": self._nu_sum}

    def load_state_dict(self, d: Mapping) -> None:
        self.sigma2, self.nu, self.mu = _nan(d.get("sigma2")), _nan(d.get("nu")), _nan(d.get("mu"))
        self.sigma2_rest, self.nu_rest = _nan(d.get("sigma2_rest")), _nan(d.get("nu_rest"))
        self.spike_rate = float(d.get("spike_rate", 0.0))
        self.blocks = int(d.get("blocks", 0))
        self._nu_sum = float(d.get("nu_sum", 0.0))
        self._v2 = list(d["v2"]) if d.get("v2") is not None else None
        self._mu = list(d["means"]) if d.get("means") is not None else None
        self._spk, self._samples = int(d.get("spk", 0)), int(d.get("samples", 0))
        if "noise_sigma2" in d:
            self.noise_sigma2, self.noise_nu = _nan(d.get("noise_sigma2")), _nan(d.get("noise_nu"))
        else:  # saved before the noise level was kept apart: the reference's, as then
            self.noise_sigma2, self.noise_nu = self.sigma2, self.nu


@dataclass(frozen=True)
class RestLevel:
    """A white-noise variance and the chi-square dof of one block's v2 against it."""

    sigma2: float
    nu: float

    @property
    def ready(self) -> bool:
        return math.isfinite(self.sigma2)


def _pooled(v: np.ndarray, nu_white: float) -> tuple[float, float]:
    """The pooled variance of the reference blocks' v2 and the dof of one block's v2: the smaller of the
    white-noise figure and the one measured from the spread of v2 (coarse rounding spreads it)."""
    s2 = float(v.mean())
    if s2 > 0:
        rel = float(v.var(ddof=1)) / (s2 * s2)
        nu_emp = 2.0 / rel if rel > 0 else nu_white
        # the spread of a variance estimated from ref_blocks values is itself uncertain: keep 70 %
        nu = min(nu_white, 0.7 * nu_emp)
    else:
        nu = nu_white
    return s2, max(nu, 2.0)


def _f(x: float):
    return x if math.isfinite(x) else None


def _nan(x) -> float:
    return math.nan if x is None else float(x)
