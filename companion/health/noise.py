"""Noise jump of a gyro axis (1.3x to 100x the white noise std), tested on still blocks.

Statistic: u = v2 / sigma0^2 (second-difference white-noise variance over the reference, spikes left
out: those are spikes.py's). CUSUM (faults eq. (1)) of the chi-square LLR of a variance rise by
``r1`` = 1.69 (a 1.3x std):

    llr = (nu / 2) * ((1 - 1 / 1.69) u - ln 1.69)

Per 100-sample block (nu ~ 50) this drifts by -2.9 nats under H0 and +4.1 nats under a 1.3x std, so
h = 20 flags a 1.3x jump after about 5 blocks, 2x after 1-2, 3x and more after one. The information
limit (faults: h / KL per block, KL = nu/2 (r - 1 - ln r)) is printed beside the measured delay by
benchmarks/bench_faults.py. The test runs on *quiet* blocks only (disarmed, accelerometer quiet, IMUs
agreeing: the motion gate of service/motion_gate.py, which never looks at this axis' own noise), after the
settling time; in flight a noisy gyro is seen by disagreement.py when a second IMU exists.

Quantisation. The variance of a rounded gyro is not its noise's: with white noise of std sigma below about
half an LSB, round(b + noise) has a variance that depends on where the bias b sits between two codes (at a
code's centre the output rarely leaves it, at a boundary it flips between two codes half of the time): for
sigma = 0.3 LSB from 0.095 to 0.25 LSB^2, a factor 2.6 in variance (1.6 in std) with no change of the gyro
at all, as the bias wanders (temperature, Gauss-Markov) across the code grid. A plane's 10 Hz gyro with
0.3 LSB of noise raised `noise 1.6x baseline` that way. So the reference is the largest variance the
rounding can give for the gyro's noise: from the reference variance s0^2 (in LSB^2), the largest
underlying sigma consistent with it (the one whose most favourable offset gives s0^2) and the largest
variance of that sigma over all offsets, V0 = max_b var(round(b + sigma_hi e)) >= s0^2
(:func:`quantized_ceiling`); u = v2 / V0. Above about 0.6 LSB the offset no longer matters
(Sheppard: sigma^2 + LSB^2 / 12 within 1e-4) and V0 = s0^2. The LSB is the smallest non-zero step of the
still blocks (float logs: far below the noise, so no change). Autopilot low-pass filters only make the
samples smoother than white noise of the same second-difference variance, so the white model is the
larger spread (conservative). The ceiling is what is used where the offset cannot be placed (below).

Reference per offset. The ceiling costs the noise test most of its power on such a gyro: at 10 Hz a block has
8 second differences, and against the worst offset's variance a doubled noise gives u = 1.7-2.5 where the
variance at the bias' own offset gives up to 5 (20-50 blocks for h = 20 on the realistic plane). Where the
still samples sit on a code grid (every sample y[0] + k LSB within GRID_TOL; the grid's phase is the
samples', so a calibration offset is allowed), the offset is seen in the block mean:

* the reference blocks (the 30 AxisRef learns from) give the underlying sigma (LSB): the one whose expected
  v2, summed over the blocks' own offsets, matches theirs, each block's expected v2 the *smallest* the
  rounding gives within its offset's uncertainty (so sigma errs high: :func:`fit_offset_model`), and the
  share of dof kept, NU_KEEP = 0.7 (less when the blocks spread more than the model predicts);
* the offset of each block is followed by a Kalman filter of the block means (a random walk of diffusion q,
  its upper 2-sigma bound from the reference blocks' pairs up to 10 apart, with their full covariance:
  :func:`bias_diffusion`); each block mean varies by the model's variance at its offset over n (times
  var / v2 where a low-pass makes successive samples alike), and the filter's variance grows with the time
  since the last placed block (after a flight: about one block's);
* a block is compared with the *largest* expected v2 within OFFSET_Z = 1 standard error of that offset,
  widened by the lean of a rounded mean towards its code (up to e^(-2 pi^2 sigma^2) / pi LSB, 0.14 at
  0.2 LSB: a 10-sample mean near a code's centre says the bias is nearer the centre than it is), with the
  smallest dof there: nu = NU_KEEP 2 V^2 / var(v2), var(v2) from the rounded noise's variance and fourth
  cumulant (:func:`v2_var`; a block at a code's centre holds a few excursions, 1.5 dof where white noise
  gives 4.1, on a boundary a near-binary flip, 8.8).

So a healthy block is never compared with less than the rounding gives at any offset the data allow, and the
model's own sigma is its upper reading. Taking the offset as exact instead (no window, no lean, no
tracking) flags healthy gyros once the bias leaves the code centre the reference was learned at (tests/
test_noise_quantized.py: a healthy plane read as `noise 1.6x baseline`). The ceiling stays where the offset cannot be
placed: samples off a grid (float logs), fewer than MIN_PLACED reference blocks on it, a sigma above 0.75
LSB (the offset no longer matters), or samples far from independent (the reference's sample variance over
1.5 times its v2: the rover's 5 Hz low-pass at 50 Hz, where the rounding of independent samples is not the
model).
"""

from __future__ import annotations

import functools
import math
from typing import Mapping

import numpy as np

from companion.health.evidence_rules import FaultLimits, capped
from companion.health.faults import Cusum, FaultEvent, Observation, chi2_llr
from companion.health.hold import OK

R1 = 1.69  # variance ratio the CUSUM is tuned to: a 1.3x noise std
H_ON = 20.0  # nats: ARL0 >= e^20 quiet blocks per axis
H_OFF = 20.0  # nats of evidence for healthy that clear it
EWMA_W = 0.2  # weight of a new block in the reported ratio
_OFFSETS = np.linspace(0.0, 0.5, 11)  # bias offsets from a code's centre, in LSB (the variance is even and 1-periodic)


def quantized_moments(sigma: float, offsets=_OFFSETS) -> tuple[np.ndarray, np.ndarray]:
    """Variance and fourth cumulant (LSB^2, LSB^4) of round(b + sigma e), e standard normal, for each offset b
    (LSB) in ``offsets``: exact Gaussian rounding probabilities of the codes within 8 sigma."""
    b = np.asarray(offsets, float)[:, None]
    if sigma <= 0.0:
        z = np.zeros(b.shape[0])
        return z, z
    kmax = int(math.ceil(0.5 + 8.0 * sigma + float(np.max(np.abs(b))))) + 1
    k = np.arange(-kmax, kmax + 1, dtype=float)[None, :]
    p = _phi((k + 0.5 - b) / sigma) - _phi((k - 0.5 - b) / sigma)
    m1 = np.sum(p * k, axis=1, keepdims=True)
    c = k - m1
    var = np.maximum(np.sum(p * c * c, axis=1), 0.0)
    return var, np.sum(p * c ** 4, axis=1) - 3.0 * var * var


def quantized_var(sigma: float, offsets=_OFFSETS) -> np.ndarray:
    """Variance (LSB^2) of round(b + sigma e), e standard normal, for each offset b (LSB) in ``offsets``."""
    return quantized_moments(sigma, offsets)[0]


def v2_var(var, kappa4, m):
    """Variance of a block's v2 = sum(dd^2) / (6 m) over m second differences of m + 2 independent samples of
    variance ``var`` and fourth cumulant ``kappa4`` (any distribution: rounded noise is far from normal).

    With dd_k = a . z (a = 1, -2, 1), cov(dd_j^2, dd_k^2) = kappa4 sum_p a_jp^2 a_kp^2 + 2 var^2 (a_j . a_k)^2:
    summed over the block, kappa4 (36 (n - 4) + 52) + 2 var^2 (70 m - 36), over (6 m)^2. Normal noise
    (kappa4 = 0) gives 3.89 var^2 / m, block_stats.DD_NU_PER_SAMPLE."""
    m = np.maximum(np.asarray(m, float), 3.0)
    return (kappa4 * (36.0 * m - 20.0) + 2.0 * var * var * (70.0 * m - 36.0)) / (36.0 * m * m)


def _phi(x: np.ndarray) -> np.ndarray:
    return 0.5 * _erfc(-np.asarray(x) / math.sqrt(2.0))


_erfc = np.vectorize(math.erfc, otypes=[float])


@functools.lru_cache(maxsize=1024)
def quantized_ceiling(s0_lsb: float) -> float:
    """V0 / s0^2 >= 1: the largest variance the rounding can give to a gyro whose rounded variance was s0^2
    (LSB^2) at some bias offset, over its own variance (see the module docstring). Remembered: a 40-step
    bisection, asked with the same reference at every block and every Allan check."""
    if not (s0_lsb > 0.0 and math.isfinite(s0_lsb)) or s0_lsb > 0.75:
        return 1.0
    v0 = s0_lsb * s0_lsb
    lo, hi = 0.0, s0_lsb + 1.0  # var_min(sigma) is increasing; var_min(s0 + 1) > s0^2
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if float(quantized_var(mid).min()) < v0:
            lo = mid
        else:
            hi = mid
    return max(1.0, float(quantized_var(hi).max()) / v0)


# the offset model (module docstring, "Reference per offset")
GRID_TOL = 0.01  # LSB: the samples of a block placed on the code grid lie within this of it
WHITE_MAX = 1.5  # the reference's sample variance over its v2 at most this: samples about independent (the
#                  model's rounding of independent samples; a low-pass spreads the samples beyond v2)
MIN_PLACED = 20  # reference blocks placed on the grid before the per-offset reference is used
Z_SIGMA = 0.0  # the underlying noise raised by this many sigma of the reference's evidence: 0, at its estimate
#               (the reference's own uncertainty enters as the dof kept, NU_KEEP, instead)
NU_KEEP = 0.7  # the share of the model's dof kept when the reference's v2 are as dispersed as it predicts
OFFSET_Z = 1.0  # standard errors of a block's offset estimate within which its true offset is sought
_SPAN = np.linspace(-1.0, 1.0, 21)
_TABLE = np.linspace(0.0, 0.5, 51)  # offsets (LSB) the healthy moments are tabulated on


def place(y: np.ndarray | None, mean: float, v2: float, lsb: float) -> tuple[float, float]:
    """The bias' offset from the nearest code (LSB, in [0, 1)) of a block of one axis' samples ``y`` on a
    code grid of step ``lsb``, and the variance of the sample part of its estimate (LSB^2) before the model's
    floor (:meth:`OffsetModel.moments`); (nan, nan) when the samples are not on one grid. The codes are
    y[0] + k lsb (a calibration offset moves the grid: its phase is the samples', not 0). A low-pass makes
    successive samples alike: the block mean then varies by var / n times var / v2 (at least 1)."""
    if y is None or not (lsb > 0.0 and math.isfinite(lsb)) or y.shape[0] < 5 or not math.isfinite(mean):
        return math.nan, math.nan
    r = (y - y[0]) / lsb
    if not np.all(np.abs(r - np.round(r)) < GRID_TOL):
        return math.nan, math.nan
    b = ((mean - float(y[0])) / lsb) % 1.0
    var = float(np.var(r))
    return b, var / y.shape[0] * max(1.0, var / max(v2 / (lsb * lsb), 1e-12))


class OffsetModel:
    """The healthy v2 of a rounded gyro at each bias offset, from the reference blocks (module docstring)."""

    def __init__(self, sigma: float, dof_keep: float, sigma_hat: float = math.nan):
        self.sigma, self.dof_keep, self.sigma_hat = float(sigma), float(dof_keep), float(sigma_hat)
        self.var, self.k4 = quantized_moments(self.sigma, _TABLE)
        self.lean = math.exp(-2.0 * math.pi ** 2 * self.sigma ** 2) / math.pi

    def moments(self, b: float, sb2: float, m: float, n: int, worst: int = 1, floor: bool = True) -> tuple[float, float]:
        """Healthy v2 (LSB^2) and its chi-square dof for a block whose offset was placed at ``b`` (LSB) with
        sample variance ``sb2`` of that estimate: the largest expected v2 (``worst`` = 1; the smallest with
        -1, for the reference's fit) over the offsets within OFFSET_Z standard errors of ``b``, and the
        smallest dof there. The error is at least the model's own variance over n (a block resting on one
        code places its bias no better than the noise does) plus the bias of a rounded mean (it leans to the
        nearest code by up to e^(-2 pi^2 sigma^2) / pi)."""
        v, nu = self.window(np.array([b]), np.array([sb2]), np.array([m]), np.array([n]), worst, floor)
        return float(v[0]), float(nu[0])

    def window(self, b, sb2, m, n, worst: int = 1, floor: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`moments` of many blocks at once (arrays)."""
        v_b = np.interp(_fold(b), _TABLE, self.var)
        s = np.sqrt(np.maximum(sb2, v_b / np.maximum(n, 1)) if floor else sb2) + self.lean
        d = _fold(b[:, None] + OFFSET_Z * s[:, None] * _SPAN[None, :])
        v, k4 = np.interp(d, _TABLE, self.var), np.interp(d, _TABLE, self.k4)
        nu = 2.0 * v * v / np.maximum(v2_var(v, k4, m[:, None]), 1e-30)
        return (v.max(axis=1) if worst > 0 else v.min(axis=1)), self.dof_keep * nu.min(axis=1)


def bias_diffusion(track, z: float = 2.0, max_lag: int = 10) -> float:
    """Upper z-sigma bound of the bias' diffusion q (LSB^2/s) from the reference blocks' ``(t, offset, r)``
    (time s, offset LSB unfolded, variance of that offset's estimate). Blocks i < j (up to ``max_lag`` apart)
    differ by q (t_j - t_i) + r_i + r_j in mean square: q by weighted least squares over those pairs (weights
    1 / that mean square^2: a squared difference varies by 2 mean square^2), its standard error from the
    pairs' full covariance (they share blocks and stretches of the walk). Long lags see the motion above
    the blocks' own placement error. nan with fewer than 10 blocks (then no tracking)."""
    tr = np.asarray([x for x in track if all(math.isfinite(v) for v in x)], float)
    if tr.shape[0] < 10:
        return math.nan
    t, a, r = tr.T
    i, j = np.triu_indices(tr.shape[0], 1)
    keep = (j - i <= max_lag) & (t[j] > t[i])
    i, j = i[keep], j[keep]
    if i.size < 10:
        return math.nan
    dt, d2, rr = t[j] - t[i], (a[j] - a[i]) ** 2, r[i] + r[j]
    q = max(float(np.sum(d2 - rr) / np.sum(dt)), 0.0)
    for _ in range(3):  # reweighted: the mean square of each pair at the current q
        w = 1.0 / np.maximum(q * dt + rr, 1e-9) ** 2
        q = max(float(np.sum(w * dt * (d2 - rr)) / np.sum(w * dt * dt)), 0.0)
    # the pairs' squared differences are correlated (shared blocks, overlapping stretches of the walk): for
    # normal differences cov(d_p^2, d_p'^2) = 2 cov(d_p, d_p')^2, with cov(d_p, d_p') = q (overlap of their
    # time spans) + the shared blocks' r with signs; evaluated again at the first bound (the spread grows with q)
    w = dt / np.maximum(q * dt + rr, 1e-9) ** 2
    overlap = np.maximum(np.minimum(t[j][:, None], t[j][None, :]) - np.maximum(t[i][:, None], t[i][None, :]), 0.0)
    shared = (r[j][:, None] * ((j[:, None] == j[None, :]).astype(float) - (j[:, None] == i[None, :]))
              + r[i][:, None] * ((i[:, None] == i[None, :]).astype(float) - (i[:, None] == j[None, :])))
    bound = q
    for _ in range(2):  # once at q, once at that first bound
        c = bound * overlap + shared
        bound = q + z * math.sqrt(float(w @ (2.0 * c * c) @ w)) / float(np.sum(w * dt))
    return bound


def _block_time(obs) -> float:
    """The time (s) of a block's last sample, nan when the block carries no times."""
    return float(obs.t[-1]) if obs.t is not None and len(obs.t) else math.nan


def _fold(b):
    """Distance (LSB) of an offset from the nearest code: the moments are even and 1-periodic in it."""
    return np.abs(np.asarray(b, float) - np.round(b))


def fit_offset_model(blocks, z: float = Z_SIGMA) -> OffsetModel | None:
    """The per-offset reference from the reference blocks ``(v2, m2, n, b, sb2)`` (LSB units, placed): the
    underlying sigma whose expected v2 summed over the blocks' own offsets matches theirs (bisection: the
    rounded variance grows with sigma at every offset), raised to the upper ``z``-sigma bound of that sum
    when ``z`` > 0 (the default Z_SIGMA = 0 keeps the estimate), and the share of dof kept (NU_KEEP, less when the blocks spread more than predicted). None when the
    noise is above 0.75 LSB (the offset does not matter there: the plain reference is used)."""
    bl = np.asarray([r for r in blocks if all(math.isfinite(x) for x in r)], float)
    if bl.shape[0] < MIN_PLACED:
        return None
    v2, m, n, b, sb2 = bl.T

    def expected(sigma):
        mean, nu = OffsetModel(sigma, 1.0).window(b, sb2, m, n, worst=-1)
        return mean, 2.0 * mean * mean / nu

    def solve(target):
        lo, hi = 0.0, 2.0
        if expected(hi)[0].sum() < target:
            return math.inf
        for _ in range(20):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if expected(mid)[0].sum() < target else (lo, mid)
        return hi

    total = float(v2.sum())
    sigma_hat = solve(total)
    if not sigma_hat <= 0.75:
        return None
    mean, var = expected(sigma_hat)
    q = float(np.sum((v2 - mean) ** 2) / np.sum(var))  # dispersion of the blocks over the model's
    sigma_hi = solve(total + z * math.sqrt(max(q, 1.0) * float(np.sum(var))))
    if not sigma_hi <= 0.75:
        return None
    return OffsetModel(sigma_hi, min(1.0, NU_KEEP / max(q, 1e-9)), sigma_hat)


class NoiseDetector:
    kind = "noise"

    def __init__(self, limits: FaultLimits | None = None):
        self.limits = limits or FaultLimits()
        self.cusum = Cusum(H_ON, H_OFF)
        self.u_avg = math.nan
        self.run: list = []
        self.value = math.nan
        self.lsb = math.inf  # smallest non-zero step of the still blocks (the gyro's resolution, or finer)
        self.learned: list = []  # the reference blocks: (v2, m2, n, mean - y[0], step) with y[0] nan off-grid
        self.model: OffsetModel | None = None
        self._built = False
        self.white = math.nan  # the reference's sample variance over its v2 (1: independent samples)
        self.q = math.nan  # the bias' diffusion (LSB^2/s) between still blocks, upper bound (bias_diffusion)
        self.track: list | None = None  # [offset (LSB, unfolded), its variance, time (s)] of the last block

    @property
    def state(self) -> int:
        return self.cusum.state

    def learn(self, obs: Observation) -> None:
        """One reference block of the axis (the blocks axis_ref.AxisRef learns from): kept for the per-offset
        reference (its v2, where its bias sat between two codes, its resolution)."""
        j, st = obs.col, obs.stats
        v2, step = float(st.v2[j]), float(st.step[j]) if st.step is not None else math.nan
        if not math.isfinite(v2) or len(self.learned) >= 4 * MIN_PLACED:
            return
        y = None if obs.y is None else np.asarray(obs.y, float)[:, j]
        dm = math.nan
        if y is not None and (np.all(y == y[0]) or (math.isfinite(step) and step > 0.0
                                                     and math.isfinite(place(y, float(st.mean[j]), v2, step)[0]))):
            dm = float(st.mean[j]) - float(y[0])  # a block on one code is on any grid
        var = float(np.var(y)) if y is not None else math.nan
        y0 = float(y[0]) if y is not None else math.nan
        t = _block_time(obs)
        self.learned.append((v2, float(st.m2[j]), int(st.n), dm, step, var, y0, t))
        if math.isfinite(step) and step > 0.0:
            self.lsb = min(self.lsb, step)

    def _build(self) -> None:
        """The per-offset reference once, at the first block after the reference (the LSB known by then)."""
        self._built = True
        if not math.isfinite(self.lsb):
            return
        rows, track = [], []
        for v2, m2, n, dm, step, var, y0, t in self.learned:
            k = step / self.lsb if math.isfinite(step) else 0.0  # no step: one code
            if not (math.isfinite(dm) and abs(k - round(k)) < GRID_TOL):  # its grid is not the LSB's
                continue
            v2l, varl = v2 / self.lsb ** 2, var / self.lsb ** 2
            infl = max(1.0, varl / max(v2l, 1e-12))  # a low-pass: successive samples alike
            rows.append((v2l, m2, n, (dm / self.lsb) % 1.0, varl / n * infl))
            track.append((t, dm / self.lsb + round(y0 / self.lsb), infl / n))
        spread = [x[5] for x in self.learned if math.isfinite(x[3])]
        self.white = float(np.sum(spread) / max(sum(x[0] for x in self.learned if math.isfinite(x[3])), 1e-300))
        if not self.white <= WHITE_MAX:  # low-passed samples: the rounding's variance is not the iid one's
            return
        self.model = fit_offset_model(rows)
        if self.model is None:
            return
        # the variance of each reference block's mean from the model at its offset (a block resting on one
        # code has no sample spread, yet its mean places the bias no better than the rounded noise does)
        track = [(t, a, float(np.interp(_fold(a), _TABLE, self.model.var)) * f) for t, a, f in track]
        self.q = bias_diffusion(track)
        if math.isfinite(self.q):  # the filter starts from the reference's blocks
            for t, a, r in track:
                if math.isfinite(t):
                    self._follow(a, r, t)

    def update(self, obs: Observation) -> list[FaultEvent]:
        """One still block of one axis: the white-noise variance against the reference."""
        step = float(obs.stats.step[obs.col]) if obs.stats.step is not None else math.nan
        if math.isfinite(step) and step > 0.0 and self.cusum.state == OK:
            self.lsb = min(self.lsb, step)
        if not self._built and obs.ref is not None and obs.ref.noise_ready:
            self._build()
        return [obs.event(self.kind, self.state, self.value)] if self._step(obs) else []

    def reference_var(self, sigma2: float) -> float:
        """The healthy variance a block is compared with: the reference's, raised to the largest the rounding
        can give at any bias offset (quantized_ceiling) when the noise is below about 0.75 LSB."""
        if not math.isfinite(self.lsb):
            return sigma2
        return sigma2 * quantized_ceiling(math.sqrt(sigma2) / self.lsb)

    def expected(self, obs: Observation) -> tuple[float, float]:
        """(healthy v2, chi-square dof) for this block: at the block's own offset where the per-offset
        reference exists and the block's samples sit on the code grid, else the ceiling and the reference's dof."""
        ref, j = obs.ref, obs.col
        v2 = float(obs.stats.v2[j])
        if self.model is not None and obs.y is not None:
            y = np.asarray(obs.y, float)[:, j]
            b, sb2 = place(y, float(obs.stats.mean[j]), v2, self.lsb)
            if math.isfinite(b):
                # the mean varies by the rounded noise's variance at that offset over n (at least)
                floor = float(np.interp(_fold(b), _TABLE, self.model.var)) / y.shape[0]
                a = (float(obs.stats.mean[j]) - float(y[0])) / self.lsb + round(float(y[0]) / self.lsb)
                t = _block_time(obs)
                b, sb2, tracked = self._follow(a, max(sb2, floor), t)
                mean, nu = self.model.moments(b, sb2, float(obs.stats.m2[j]), y.shape[0], floor=not tracked)
                return mean * self.lsb * self.lsb, nu
            self.track = None
        return self.reference_var(ref.noise_sigma2), ref.noise_nu

    def _follow(self, a: float, r: float, t: float) -> tuple[float, float, bool]:
        """The bias' offset (LSB, unfolded) and its variance from this block's mean ``a`` (variance ``r``) and
        the blocks before it: a Kalman filter of a random walk of diffusion ``q`` (learned from the reference,
        its upper bound), its variance growing with the time since the last placed block (a flight between
        them: about the block alone). ``t``: the block's time (s). Without times or a learned diffusion, the
        block alone."""
        if not (math.isfinite(t) and math.isfinite(self.q)):
            self.track = None
            return a, r, False
        if self.track is None or not t > self.track[2]:
            self.track = [a, r, t]
            return a, r, True
        beta, p, t0 = self.track
        p += self.q * (t - t0)
        k = p / (p + r)
        self.track = [beta + k * (a - beta), p * r / (p + r), t]
        return self.track[0], self.track[1], True

    def _step(self, obs: Observation) -> bool:
        ref, v2 = obs.ref, float(obs.stats.v2[obs.col])
        if not (ref.noise_ready and ref.noise_sigma2 > 0 and math.isfinite(v2)):
            return False
        v0, nu = self.expected(obs)
        u = v2 / v0
        if self.cusum.state == OK and self.cusum.s == 0.0:
            self.run = []
        self.run.append(u)
        self.u_avg = u if not math.isfinite(self.u_avg) else (1 - EWMA_W) * self.u_avg + EWMA_W * u
        # one knock (a block of a standing vehicle bumped) is not a noise change: at least
        # ``noise_hold_blocks`` blocks of evidence
        changed = self.cusum.step(capped(chi2_llr(u, nu, R1), H_ON, self.limits.noise_hold_blocks))
        if changed and self.cusum.state != OK:  # the ratio quoted: the last blocks of the evidence
            self.u_avg = self.run[-1]  # the block that decided (earlier ones may predate the jump)
        self.value = math.sqrt(max(self.u_avg, 0.0))
        return changed

    def state_dict(self) -> dict:
        return {"cusum": self.cusum.state_dict(), "u_avg": None if math.isnan(self.u_avg) else self.u_avg,
                "lsb": self.lsb if math.isfinite(self.lsb) else None,
                "learned": [[None if not math.isfinite(x) else x for x in r] for r in self.learned]}

    def load_state_dict(self, d: Mapping) -> None:
        self.cusum.load_state_dict(d.get("cusum", {}))
        self.u_avg = math.nan if d.get("u_avg") is None else float(d["u_avg"])
        self.lsb = math.inf if d.get("lsb") is None else float(d["lsb"])
        self.learned = [tuple(math.nan if x is None else float(x) for x in r) for r in d.get("learned") or []]
        self.model, self._built = None, False  # rebuilt from the learned blocks at the next block
