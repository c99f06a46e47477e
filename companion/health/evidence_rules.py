"""Practical limits of the fault detectors: magnitude floors, and the evidence rules that keep real data healthy.

The statistical tests (CUSUMs of per-block LLRs, faults.py) answer "is this block different from the
reference?". On real autopilot data the answer is often yes without any fault: bias wanders by tenths of
a deg/s (vibration, temperature, small real motion of a standing rover), the noise falls when an engine
stops, two healthy IMUs differ by a few deg/s in fast manoeuvres (each filtered and sampled at its own
time, their scale factors differ by percents). A fault must therefore be both *significant* and *large*:

* ``FaultLimits`` holds the floors (a user's "this much is a fault"), configurable under ``run: faults:``;
* ``floored_mean_llr``: a mean-shift LLR whose allowance is tied to the floor, so that a shift below
  the floor never accumulates evidence, whatever the noise;
* ``wander_var``: the wander of still-block means measured on the vehicle itself (robust, from the
  successive differences and the spread of the recent means), used beside the Allan-predicted wander;
* ``allan_wander_var``: what the gyro's own Allan terms predict for the mean of a block against a
  reference averaged over the previous T seconds;
* ``p_equal_codes`` / ``equal_codes_llr``: how often a healthy quantised gyro repeats its code, and the
  evidence of a block's repeated codes against it (stuck = frozen values, never a variance drop alone).

Pure numpy/math; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Mapping, Sequence

import numpy as np

DEG = math.pi / 180.0


@dataclass
class FaultLimits:
    """Floors of the fault detectors, in datasheet units (deg/s) as a user writes them.

    * ``bias_jump_dps``: a step of the still bias smaller than this is wander, not a fault. 1 deg/s is
      10x the warm-up of a cold MEMS gyro and above the bias wander seen on standing rovers (1 s means
      +-0.4 deg/s with a motor running; an uncalibrated MPU wandering 0.8 deg/s over 20 s,
      benchmarks/bench_reallogs.py); an EKF absorbs a bias of this size (PX4 EKF2_GYR_B_LIM: 8.6 deg/s).
    * ``bias_drift_dps``: the still bias may move this far from the reference of the start before it
      is a drift: 1 deg/s (an uncalibrated MPU-6000 moves by about 0.25 deg/s per 10 degC).
    * ``disagree_dps``: two IMUs' 1 s mean rates may differ by this much plus ``disagree_rel`` of the
      rms rate: ArduPilot's gyro consistency check uses 5 deg/s (pre-arm, AP_Arming), DroneKit-LA 5.73
      deg/s for 0.5 s; in fast manoeuvres healthy pairs differ by up to ~10 % of the rate (each IMU sampled
      and filtered at its own time, percent-level scale factors).
    * ``bias_temp_dps_per_k``: the largest bias-temperature slope the bias tests accept as explaining a
      still-bias change where the log carries the IMU temperature (companion.health.bias_temperature): 0.1 deg/s/K,
      the MPU-6000's datasheet bound (+-20 deg/s over -40..85 degC); typical parts are 0.01-0.05 deg/s/K.
      0 turns the temperature model off.
    * ``noise_hold_blocks`` / ``bias_hold_blocks`` / ``disagree_hold_blocks``: the least number of blocks
      of evidence before a noise, bias or disagreement fault: one knock or one violent second is not a
      fault (the per-block LLR is capped at h / hold).
    """

    bias_jump_dps: float = 1.0
    bias_drift_dps: float = 1.0
    disagree_dps: float = 5.0
    disagree_rel: float = 0.1
    bias_temp_dps_per_k: float = 0.1
    noise_hold_blocks: int = 3
    bias_hold_blocks: int = 5
    disagree_hold_blocks: int = 3

    @property
    def bias_jump(self) -> float:
        return self.bias_jump_dps * DEG

    @property
    def bias_drift(self) -> float:
        return self.bias_drift_dps * DEG

    @property
    def bias_temp(self) -> float:
        """rad/s per K."""
        return self.bias_temp_dps_per_k * DEG

    @property
    def disagree(self) -> float:
        return self.disagree_dps * DEG

    @classmethod
    def from_mapping(cls, cfg: Mapping | None) -> "FaultLimits":
        out = cls()
        names = {f.name: f.type for f in fields(cls)}
        for k, v in dict(cfg or {}).items():
            if k not in names:
                raise ValueError(f"run.faults: unknown key {k!r}")
            val = int(v) if k.endswith("_blocks") else float(v)
            if not val >= 0:
                raise ValueError(f"run.faults: {k} must be >= 0, got {v!r}")
            setattr(out, k, val)
        return out


def capped(llr: float, h: float, hold: int) -> float:
    """A block's LLR capped at h / hold: at least ``hold`` blocks of evidence before h is crossed."""
    if hold <= 1 or not math.isfinite(llr):
        return llr
    return min(llr, h / hold)


def floored_mean_llr(x: float, sigma: float, floor: float, delta_min: float = 0.0) -> float:
    """LLR of a mean shift of at least ``floor`` for one block mean x +- sigma (x signed towards the
    shift tested). Tuned to delta = max(floor, delta_min); the allowance is 3/4 of the floor (the
    textbook delta/2 when there is no floor), so a shift below 0.75 floor drifts the CUSUM down and a
    shift at the floor still accumulates (0.25 floor per block, scaled by delta / sigma^2)."""
    delta = max(floor, delta_min)
    allowance = max(0.75 * floor, 0.5 * delta_min)
    return (delta / (sigma * sigma)) * (x - allowance)


def allan_wander_var(B: float | None, K: float | None, T: float) -> float:
    """Variance of a still-block mean around a reference that averages the previous ``T`` seconds,
    predicted by the Allan terms: flicker (bias instability B, rad/s) contributes its Allan plateau
    (2 ln2 / pi) B^2 = 0.44 B^2 (the two-sample variance of averages at any tau above the corner); a
    rate random walk K (rad/s/sqrt(s)) makes the bias a Wiener process b(t) = K W(t): the block mean (a
    short average at t) minus the reference (an average over [t - T, t]) is K (W(t) - mean of W over the
    window), whose variance is K^2 T / 3 (integral of (T - s)^2 / T^2 ds over [0, T] = T / 3). So
    sigma_b(T) = K sqrt(T / 3): the wander the bias tests must allow for."""
    v = 0.0
    if B is not None and math.isfinite(B):
        v += (2.0 * math.log(2.0) / math.pi) * B * B
    if K is not None and math.isfinite(K):
        v += K * K * T / 3.0
    return v


def wander_var(means: Sequence[float], min_blocks: int = 10) -> float:
    """Wander of the still-block means measured on the vehicle: the larger of the robust variance of
    successive differences / 2 (block-to-block) and the variance of the recent means themselves (slow
    wander within the window; not a robust spread: a slow excursion of tens of blocks is exactly the
    wander to allow for, and the caller measures it only while nothing is flagged). 0 with fewer than
    ``min_blocks``."""
    x = np.asarray([m for m in means if math.isfinite(m)], dtype=float)
    if x.size < min_blocks:
        return 0.0
    d = np.diff(x)
    mad_d = float(np.median(np.abs(d - np.median(d)))) / 0.6745
    return max(0.5 * mad_d * mad_d, float(np.var(x)))


_PHI0 = 1.0 / math.sqrt(2.0 * math.pi)


def p_equal_codes(sigma_lsb: float) -> float:
    """Probability that two successive samples of a healthy gyro give the same code, when the white
    noise per sample is ``sigma_lsb`` LSB: with a uniform offset within the LSB, the codes are equal with
    probability max(0, 1 - |D|) for a difference D ~ N(0, s^2), s = sqrt(2) sigma, whose mean is
    (2 Phi(1/s) - 1) - 2 s (phi(0) - phi(1/s)). Noise well below the LSB: about 1 (a quiet gyro repeats
    its code by nature); 0.7 LSB: 0.37; 4 LSB: 0.07. A low-pass filter makes successive samples closer,
    so the white sigma from second differences (which the filter lowers less than the first difference)
    gives a prediction on the cautious side."""
    if not sigma_lsb > 0:
        return 1.0
    s = math.sqrt(2.0) * sigma_lsb
    z = 1.0 / s
    p_in = math.erf(z / math.sqrt(2.0))
    phi_z = _PHI0 * math.exp(-0.5 * z * z)
    return min(max(p_in - 2.0 * s * (_PHI0 - phi_z), 0.0), 1.0)


def _kl_bern(p: float, q: float) -> float:
    p = min(max(p, 1e-12), 1 - 1e-12)
    q = min(max(q, 1e-12), 1 - 1e-12)
    return p * math.log(p / q) + (1 - p) * math.log((1 - p) / (1 - q))


def equal_codes_llr(equal: int, pairs: int, p0: float, p_min: float = 1e-4) -> float:
    """Evidence (nats) of a block's ``equal`` repeated codes among ``pairs`` successive pairs against the
    healthy rate ``p0``: the generalised LLR pairs * KL(p_hat || p0), positive when codes repeat more
    often than the noise-to-LSB ratio predicts, negative (the same size) when less often: a block whose
    codes keep changing is evidence against a frozen gyro however small its variance."""
    if pairs <= 0:
        return 0.0
    p0 = min(max(p0, p_min), 1.0 - 1e-6)
    p_hat = equal / pairs
    kl = pairs * _kl_bern(p_hat, p0)
    return kl if p_hat > p0 else -kl
