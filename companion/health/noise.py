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
"""

from __future__ import annotations

import math
from typing import Mapping

from companion.health.limits import FaultLimits, capped
from companion.health.faults import Cusum, FaultEvent, OK, Observation, chi2_llr

R1 = 1.69
H_ON = 20.0
H_OFF = 20.0
EWMA_W = 0.2  # weight of a new block in the reported ratio


class NoiseDetector:
    kind = "noise"

    def __init__(self, limits: FaultLimits | None = None):
        self.limits = limits or FaultLimits()
        self.cusum = Cusum(H_ON, H_OFF)
        self.u_avg = math.nan
        self.run: list = []
        self.value = math.nan

    @property
    def state(self) -> int:
        return self.cusum.state

    def update(self, obs: Observation) -> list[FaultEvent]:
        """One still block of one axis: the white-noise variance against the reference."""
        return [obs.event(self.kind, self.state, self.value)] if self._step(obs.ref, float(obs.stats.v2[obs.col])) else []

    def _step(self, ref, v2: float) -> bool:
        if not (ref.ready and ref.sigma2 > 0 and math.isfinite(v2)):
            return False
        u = v2 / ref.sigma2
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
        return {"cusum": self.cusum.state_dict(), "u_avg": None if math.isnan(self.u_avg) else self.u_avg}

    def load_state_dict(self, d: Mapping) -> None:
        self.cusum.load_state_dict(d.get("cusum", {}))
        self.u_avg = math.nan if d.get("u_avg") is None else float(d["u_avg"])
