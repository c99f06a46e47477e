"""Spikes / glitches of a gyro axis: isolated outliers, counted and named as spikes (not as noise).

Statistic: the number c of isolated outliers per block, |dd| > 6 robust sigmas of the second differences
(block_stats.block_stats: one count per spike at its centre, where a spike of amplitude A gives dd = -2A;
the robust sigma is the larger of the block's MAD and the still reference, so vibration in flight raises
the bar and a quiet block uses the healthy noise). Healthy Gaussian noise gives 2e-9 per sample; the
reference rate measured on still data is used when higher (floor 1e-5 per sample). A heavy tail is thus
measured as an outlier rate against the baseline's (the kurtosis question asked the robust way: the
sample kurtosis of a block is dominated by one value and has no usable tail). Poisson CUSUM:

    llr = c ln(lambda1 / lambda0) - (lambda1 - lambda0) n,    lambda1 = 1e-3 per sample (0.1 %)

h = 12: three spikes close together flag it (0.2 % of samples at 100 Hz: about 15 s). On a still block
whose accelerometer stayed quiet a spike's size adds to its count (ALPHA0, ALPHA1 below): two spikes whose
|dd| exceeds ~40 robust sigmas flag it (a 0.3 rad/s glitch on a still gyro is hundreds), one never does
(at a 10 Hz log rate 0.2-1 % of the samples is a spike every 10-50 s: the third came up to two minutes
after the fault). Outside still
blocks only spikes on one axis alone count (a landing shock moves every axis at once), and they are
weighed against the outlier rate of the vehicle's own motion, not the still one: flight vibration and
handling knocks are heavy-tailed (0.04-1.9 % of 50 Hz samples beyond 6 robust sigmas in healthy copter
flights, benchmarks/bench_reallogs.py). In motion lambda0 is the larger of the rate learned on moving
blocks and ``LAMBDA0_MOTION`` (1 %), lambda1 five times that, and the evidence needs ``MOTION_HOLD``
blocks: glitches of a few tenths of a percent are judged once the vehicle is still again.
"""

from __future__ import annotations

import math
from typing import Mapping

from companion.health.faults import Cusum, FaultEvent, Observation

LAMBDA1 = 1e-3  # outliers per sample under H1
LAMBDA0_FLOOR = 1e-5  # outliers per sample under H0 at least (healthy Gaussian noise: 2e-9)
H_ON = 12.0  # nats: three spikes close together flag it
H_OFF = 12.0  # nats of evidence for healthy that clear it
RATE_TAU_BLOCKS = 30.0  # blocks of the EWMA of the outlier rate the report quotes (the spikes %)
LAMBDA0_MOTION = 1e-2  # outliers per sample a moving vehicle may show (heavy-tailed vibration)
MOTION_RATIO = 5.0  # lambda1 / lambda0 in motion: only a rate well above the vehicle's own counts
MOTION_HOLD = 5  # blocks of evidence in motion: short glitches are judged once the vehicle is still again
MOTION_TAU_BLOCKS = 60.0  # blocks of the EWMA of the moving outlier rate
#: A still spike's size, u = ln(|dd| / bar) >= 0 (bar: SPIKE_K robust sigmas, block_stats.block_stats): healthy
#: outliers beyond the bar are taken to fall off as z^-ALPHA0 (a Pareto tail: heavier than the copter flights'
#: 2.4-3.6 measured on real logs, far heavier than Gaussian), a glitch's size spreads over decades up to full
#: scale (z^-ALPHA1). The ratio of the two densities, ln(ALPHA1 / ALPHA0) + (ALPHA0 - ALPHA1) u, is added to
#: the rate evidence where positive (u > 0.92: beyond 15 sigmas), only while the accelerometer stayed quiet
#: (a knock or jolt of the vehicle moves both; a gyro glitch only the gyro), and a spike's whole evidence is
#: at most SPIKE_LLR_MAX: two spikes are needed, one is never a fault.
ALPHA0 = 2.0  # tail exponent of healthy outliers (above)
ALPHA1 = 0.5  # tail exponent of a glitch's size (above)
SPIKE_LLR_MAX = 0.6 * H_ON  # one spike's evidence at most: two are needed, one is never a fault


class SpikeDetector:
    kind = "spikes"

    def __init__(self):
        self.cusum = Cusum(H_ON, H_OFF)
        self.rate = 0.0  # running outlier rate (per sample)
        self.motion_rate = 0.0  # outlier rate of moving blocks (per sample)
        self.run = [0, 0]  # outliers and samples since the evidence started (what the report quotes)
        self.value = math.nan

    @property
    def state(self) -> int:
        return self.cusum.state

    def update(self, obs: Observation) -> list[FaultEvent]:
        """One block of one axis: every outlier when still, else only those on this axis alone (a shock
        moves every axis)."""
        st, j = obs.stats, obs.col
        # a knock on a standing vehicle (the accelerometer moved for several samples) moves the gyro as the
        # vehicle's motion does: its spikes are weighed as in motion (taps on a standing PX4 vehicle reach 20-40
        # robust sigmas on two gyro axes and the accelerometer at once: no gyro glitch)
        still = obs.still and not obs.accel_knock
        count = int(st.spikes[j] if still else st.spikes_solo[j])
        size = st.spike_size[j] if st.spike_size is not None else 0.0
        changed = self._step(obs.ref, count, st.n, still, float(size), obs.accel_quiet)
        return [obs.event(self.kind, self.state, self.value)] if changed else []

    def _step(self, ref, count: int, n: int, still: bool = True, size: float = 0.0, quiet: bool = False) -> bool:
        """``size``: the sum of the block's spike sizes u = ln(|dd| / bar), weighed on still blocks whose
        accelerometer stayed ``quiet`` (ALPHA0, ALPHA1 above)."""
        if n <= 0:
            return False
        w = 1.0 / RATE_TAU_BLOCKS
        self.rate = (1 - w) * self.rate + w * count / n
        if still:
            lam0 = max(ref.spike_rate if ref.ready else 0.0, LAMBDA0_FLOOR)
            per = math.log(LAMBDA1 / lam0)
            extra = max((ALPHA0 - ALPHA1) * size + count * math.log(ALPHA1 / ALPHA0), 0.0) if quiet else 0.0
            llr = min(count * per + extra, count * max(SPIKE_LLR_MAX, per)) - (LAMBDA1 - lam0) * n
        else:
            lam0 = max(self.motion_rate, LAMBDA0_MOTION)
            lam1 = MOTION_RATIO * lam0
            llr = min(count * math.log(lam1 / lam0) - (lam1 - lam0) * n, H_ON / MOTION_HOLD)
            if self.cusum.state == 0 and self.cusum.s == 0.0:
                self.motion_rate += (count / n - self.motion_rate) / MOTION_TAU_BLOCKS
        if self.cusum.s == 0.0:
            self.run = [0, 0]
        self.run[0] += int(count)
        self.run[1] += int(n)
        changed = self.cusum.step(llr)
        # the run starts at a spike: leave that one out (a Poisson rate counted from an event is biased)
        self.value = 100.0 * (max(self.run[0] - 1, 1) / self.run[1] if self.run[1] else self.rate)
        if changed and self.cusum.state == 0:
            self.value = 100.0 * self.rate
        return changed

    def state_dict(self) -> dict:
        return {"cusum": self.cusum.state_dict(), "rate": self.rate, "motion_rate": self.motion_rate}

    def load_state_dict(self, d: Mapping) -> None:
        self.cusum.load_state_dict(d.get("cusum", {}))
        self.rate = float(d.get("rate", 0.0))
        self.motion_rate = float(d.get("motion_rate", 0.0))
