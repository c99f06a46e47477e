"""Noise jump of a gyro axis (1.3x to 100x the white noise std), tested on still blocks.

Statistic: u = v2 / sigma0^2 (second-difference white-noise variance over the reference, spikes left
out: those are spikes.py's). CUSUM (faults eq. (1)) of the chi-square LLR of a variance rise by
``r1`` = 1.69 (a 1.3x std):

    llr = (nu / 2) * ((1 - 1 / 1.69) u - ln 1.69)

Per 100-sample block (nu ~ 50) this drifts by -2.9 nats under H0 and +4.1 nats under a 1.3x std, so
h = 20 flags a 1.3x jump after about 5 blocks, 2x after 1-2, 3x and more after one. The information
limit (faults: h / KL per block, KL = nu/2 (r - 1 - ln r)) is printed beside the measured delay by
benchmarks/bench_faults.py. The test runs on *quiet* blocks only (disarmed, accelerometer quiet, IMUs
agreeing: the motion gate of service/motion.py, which never looks at this axis' own noise), after the
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
larger spread (conservative).
"""

from __future__ import annotations

import functools
import math
from typing import Mapping

import numpy as np

from companion.health.limits import FaultLimits, capped
from companion.health.faults import Cusum, FaultEvent, OK, Observation, chi2_llr

R1 = 1.69
H_ON = 20.0
H_OFF = 20.0
EWMA_W = 0.2  # weight of a new block in the reported ratio
_OFFSETS = np.linspace(0.0, 0.5, 11)  # bias offsets from a code's centre, in LSB (the variance is even and 1-periodic)


def quantized_var(sigma: float, offsets=_OFFSETS) -> np.ndarray:
    """Variance (LSB^2) of round(b + sigma e), e standard normal, for each offset b (LSB) in ``offsets``."""
    b = np.asarray(offsets, float)[:, None]
    if sigma <= 0.0:
        return np.zeros(b.shape[0])
    kmax = int(math.ceil(0.5 + 8.0 * sigma)) + 1
    k = np.arange(-kmax, kmax + 1, dtype=float)[None, :]
    cdf = _phi((k + 0.5 - b) / sigma) - _phi((k - 0.5 - b) / sigma)
    m1 = np.sum(cdf * k, axis=1)
    return np.maximum(np.sum(cdf * k * k, axis=1) - m1 * m1, 0.0)


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


class NoiseDetector:
    kind = "noise"

    def __init__(self, limits: FaultLimits | None = None):
        self.limits = limits or FaultLimits()
        self.cusum = Cusum(H_ON, H_OFF)
        self.u_avg = math.nan
        self.run: list = []
        self.value = math.nan
        self.lsb = math.inf  # smallest non-zero step of the still blocks (the gyro's resolution, or finer)

    @property
    def state(self) -> int:
        return self.cusum.state

    def update(self, obs: Observation) -> list[FaultEvent]:
        """One still block of one axis: the white-noise variance against the reference."""
        step = float(obs.stats.step[obs.col]) if obs.stats.step is not None else math.nan
        if math.isfinite(step) and step > 0.0 and self.cusum.state == OK:
            self.lsb = min(self.lsb, step)
        return [obs.event(self.kind, self.state, self.value)] if self._step(obs.ref, float(obs.stats.v2[obs.col])) else []

    def reference_var(self, sigma2: float) -> float:
        """The healthy variance a block is compared with: the reference's, raised to the largest the rounding
        can give at any bias offset (quantized_ceiling) when the noise is below about 0.75 LSB."""
        if not math.isfinite(self.lsb):
            return sigma2
        return sigma2 * quantized_ceiling(math.sqrt(sigma2) / self.lsb)

    def _step(self, ref, v2: float) -> bool:
        if not (ref.ready and ref.sigma2 > 0 and math.isfinite(v2)):
            return False
        u = v2 / self.reference_var(ref.sigma2)
        if self.cusum.state == OK and self.cusum.s == 0.0:
            self.run = []
        self.run.append(u)
        self.u_avg = u if not math.isfinite(self.u_avg) else (1 - EWMA_W) * self.u_avg + EWMA_W * u
        # one knock (a block of a standing vehicle bumped) is not a noise change: at least
        # ``noise_hold_blocks`` blocks of evidence
        changed = self.cusum.step(capped(chi2_llr(u, ref.nu, R1), H_ON, self.limits.noise_hold_blocks))
        if changed and self.cusum.state != OK:  # the ratio quoted: the last blocks of the evidence
            self.u_avg = self.run[-1]  # the block that decided (earlier ones may predate the jump)
        self.value = math.sqrt(max(self.u_avg, 0.0))
        return changed

    def state_dict(self) -> dict:
        return {"cusum": self.cusum.state_dict(), "u_avg": None if math.isnan(self.u_avg) else self.u_avg,
                "lsb": self.lsb if math.isfinite(self.lsb) else None}

    def load_state_dict(self, d: Mapping) -> None:
        self.cusum.load_state_dict(d.get("cusum", {}))
        self.u_avg = math.nan if d.get("u_avg") is None else float(d["u_avg"])
        self.lsb = math.inf if d.get("lsb") is None else float(d["lsb"])
