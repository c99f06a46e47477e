"""Stuck (frozen) gyro axis: the output repeats its value (codes) and its variance collapses.

Statistic: u = v2 / sigma0^2, the block's white-noise variance from second differences (faults.BlockStats)
over the reference sigma0^2 learned from still data; nu v2 / sigma^2 ~ chi2(nu) (nu from the reference,
smaller under coarse rounding, faults.AxisRef). The CUSUM (faults eq. (1)) of the LLR of a variance
collapse by ``r1`` = 1/10

    llr = (nu / 2) * (ln 10 - 9 u)

is positive only while u < ln(10) / 9 = 0.256. A frozen output (u = 0) gives nu/2 * 2.30 = 58 nats per
100-sample block against h = 20: flagged after one block; a frozen value with dither of std d is caught
while d^2 < 0.256 sigma0^2 (d < 0.5 sigma0). Motion only adds variance, so this runs on every block
(still, handled, armed, flying). Figure: benchmarks/bench_faults.py (stuck delay 1-2 s, 0 false alarms in
100 h including 0.7 LSB int16 rounding, where healthy blocks never came below u = 0.4).

A variance drop alone is no evidence of a frozen gyro: a plane's gyro whose noise falls 5x when the engine
stops keeps giving distinct values (150 distinct 10 Hz samples in 15 s, benchmarks/bench_reallogs.py). So
the per-block evidence is the smaller of the variance LLR and the evidence of repeated codes
(limits.equal_codes_llr): the number of successive equal samples against the rate p0 a healthy gyro
repeats its code by nature, predicted from its noise-to-LSB ratio (limits.p_equal_codes: 0.37 at 0.7 LSB
of white noise, so a healthy coarse gyro's runs of equal codes are not a fault; about 0 for float logs,
whose codes always change). The LSB is the smallest non-zero step seen on the axis. A frozen value
(every code equal) gives ~ n ln(1 / p0) nats: flagged in one block.

Before a reference exists (the first seconds of still data) the PX4-like rule applies: ``equal_blocks``
consecutive blocks of at least 50 samples with every value equal (no change at all).

Exactly 0 is named for what it is (kind ``dead``, its own code): a float message (HIGHRES_IMU, DataFlash,
ULog) never reads exactly 0.0 from a live gyro, so that is a dead (absent, never started) sensor. On an
integer message (RAW_IMU, SCALED_IMU*: int16 mrad/s, ``coded_lsb``) a gyro whose noise is below the
1 mrad/s step (0.057 deg/s; ArduPilot SITL, a quiet MEMS part) also reads 0 on every axis at rest: the
plain truth is "dead or below resolution" (WARNING; HIGHRES_IMU carries float rad/s). It becomes
"reads 0 while moving: dead" (CRITICAL) when the motion gate (accelerometer, other IMUs) sees the vehicle
move while the axis still reads 0. An axis that changed codes in motion is alive; at rest again it reads 0
by resolution, so it is named again only after ``ZERO_ALIVE_BLOCKS`` blocks of zeros (one per landing or
handling otherwise). A value frozen at 0 after a learned reference showed codes changing at rest is
``stuck``, as a frozen non-zero value is.
"""

from __future__ import annotations

import math
from typing import Mapping

from companion.health.faults import FAULT, OK, Cusum, FaultEvent, Observation, chi2_llr
from companion.health.limits import equal_codes_llr, p_equal_codes

R1 = 0.1  # variance collapse the CUSUM is tuned to
H_ON = 20.0  # nats: ARL0 >= e^20 = 5e8 blocks (1 s) = 15 years per axis
H_OFF = 10.0
EQUAL_BLOCKS = 2  # blocks with no change at all (>= 100 equal values at 100 Hz), PX4's rule doubled
ZERO_ALIVE_BLOCKS = 60  # integer-coded zeros of an axis seen alive (changing in motion): "for long" = 1 min


class StuckDetector:
    """``coded_lsb``: the message's resolution (rad/s) for integer messages (RAW_IMU, SCALED_IMU*), None for
    float messages; it only decides how an axis reading exactly 0 is named."""

    def __init__(self, coded_lsb: float | None = None):
        self.coded_lsb = coded_lsb
        self.kind = "stuck"  # the kind named for the current fault: "stuck", or "dead" (exactly 0)
        self.detail = ""  # of a "dead" fault: "" (integer message, at rest), "float", "moving"
        self.alive = False  # the axis changed codes in a moving block (a live gyro; its zeros at rest are resolution)
        self.cusum = Cusum(H_ON, H_OFF)
        self.equal_run = 0
        self.value = math.nan
        self.lsb = math.inf  # smallest non-zero step seen (the sensor's resolution, or finer)
        self.quantised = False  # a healthy block repeated a code: the data are quantised near the noise level

    @property
    def state(self) -> int:
        return self.cusum.state

    def update(self, obs: Observation) -> list[FaultEvent]:
        """One block of one axis (any motion state); the state change, if any (critical, except an integer
        axis reading 0 at rest), or the escalation of such an axis to "dead" when it reads 0 in motion."""
        st, j = obs.stats, obs.col
        zero = int(st.changes[j]) == 0 and float(st.top[j]) == 0.0 and st.n >= 2
        if not self._step(obs):
            if (self.state == FAULT and self.kind == "dead" and self.detail == "" and zero and not obs.still):
                self.detail = "moving"
                return [obs.event("dead", FAULT, detail="moving", critical=True)]
            return []
        if self.state == FAULT:
            self.kind, self.detail = "stuck", ""
            if zero and (self.coded_lsb is None or not (obs.ref is not None and obs.ref.ready)):
                self.kind = "dead"
                self.detail = "float" if self.coded_lsb is None else ("" if obs.still else "moving")
            return [obs.event(self.kind, FAULT, detail=self.detail,
                              critical=not (self.kind == "dead" and self.detail == ""))]
        kind, detail = self.kind, self.detail
        self.kind, self.detail = "stuck", ""
        return [obs.event(kind, OK, detail=detail, critical=True)]

    def _step(self, obs: Observation) -> bool:
        j, st, ref = obs.col, obs.stats, obs.ref
        v2, changes, n = float(st.v2[j]), int(st.changes[j]), st.n
        self.equal_run = self.equal_run + 1 if (changes == 0 and n >= 50) else 0
        if not obs.still and n >= 2 and changes >= (n - 1) // 2:
            self.alive = True
        # an integer axis seen alive reads 0 at rest by resolution: named again only after a long run
        zero_coded = self.coded_lsb is not None and changes == 0 and float(st.top[j]) == 0.0
        equal_blocks = ZERO_ALIVE_BLOCKS if (zero_coded and self.alive) else EQUAL_BLOCKS
        step = float(st.step[j])
        if ref.ready and ref.sigma2 > 0 and math.isfinite(v2):
            u = v2 / ref.sigma2
            self.value = u
            llr = chi2_llr(u, ref.nu, R1)
            # frozen values, not just a quiet gyro: the codes must repeat more than the noise explains.
            # Differences far below the resolution count as repeats (a frozen value with a little dither):
            # the block's repeat rate is at least what its own white noise would give at that resolution.
            # (only for data seen to repeat codes when healthy: the smallest step of a float log is no resolution)
            if math.isfinite(self.lsb):
                p0 = p_equal_codes(math.sqrt(ref.sigma2) / self.lsb)
                pairs = n - 1
                p_hat = (pairs - changes) / max(pairs, 1)
                if self.quantised:
                    p_hat = max(p_hat, p_equal_codes(math.sqrt(max(v2, 0.0)) / self.lsb))
                llr = min(llr, equal_codes_llr(int(round(p_hat * pairs)), pairs, p0))
            else:
                llr = min(llr, 0.0)
            if llr <= 0.0 and self.cusum.state == OK and math.isfinite(step) and step > 0:
                self.lsb = min(self.lsb, step)  # the resolution, learned from blocks without evidence
                self.quantised = self.quantised or changes < n - 1
            if self.equal_run >= equal_blocks and self.cusum.state == OK:
                llr = max(llr, 2.0 * H_ON)
            return self.cusum.step(llr)
        # no reference yet: only the equal-values rule
        if self.cusum.state == OK and self.equal_run >= equal_blocks:
            self.cusum.state, self.cusum.s = FAULT, 0.0
            return True
        if self.cusum.state == FAULT and changes > 0.5 * n:
            self.cusum.state, self.cusum.s = OK, 0.0
            return True
        return False

    def state_dict(self) -> dict:
        return {"cusum": self.cusum.state_dict(), "equal_run": self.equal_run,
                "lsb": self.lsb if math.isfinite(self.lsb) else None, "quantised": self.quantised,
                "kind": self.kind, "detail": self.detail, "alive": self.alive}

    def load_state_dict(self, d: Mapping) -> None:
        self.cusum.load_state_dict(d.get("cusum", {}))
        self.equal_run = int(d.get("equal_run", 0))
        self.lsb = math.inf if d.get("lsb") is None else float(d["lsb"])
        self.quantised = bool(d.get("quantised", False))
        self.kind = "dead" if d.get("kind") == "dead" else "stuck"
        self.detail = str(d.get("detail", ""))
        self.alive = bool(d.get("alive", False))
