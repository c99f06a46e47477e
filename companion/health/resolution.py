"""Resolution loss of a gyro axis: the output moves in steps larger than the LSB it had.

Statistic per block: the smallest non-zero step |y_k - y_{k-1}| (``BlockStats.step``) and the number of
changes. The reference LSB is that step when it is the same in every reference block (quantised data,
e.g. 1 mrad/s for int16 mrad/s); float data has no LSB and is not tested. A block with at least
``MIN_CHANGES`` changes whose smallest step is >= 1.9 LSB is suspect: with healthy rounded noise of std
s LSB a step of exactly one LSB among ~95 differences is missing with probability < 0.07 per block even
at s = 20 (and < 1e-6 at s = 4), so ``HOLD`` = 10 suspect blocks in a row flag it; 10 good ones clear it.
Still blocks only (in motion the differences are large and a one-LSB step is rare anyway).
"""

from __future__ import annotations

import math
from typing import Mapping

from companion.health.faults import FaultEvent, Observation
from companion.health.hold import FAULT, OK, debounce

MIN_CHANGES = 20  # changes a block needs before its smallest step says anything (see above)
HOLD = 10  # suspect (good) blocks in a row that flag (clear) it: a healthy miss is < 0.07 per block
REF_BLOCKS = 10  # still blocks whose common smallest step is the reference LSB


class ResolutionDetector:
    kind = "resolution"

    def __init__(self):
        self.state = OK
        self.lsb = math.nan  # 0: not quantised
        self._steps: list = []
        self.count = 0
        self.value = math.nan

    def update(self, obs: Observation) -> list[FaultEvent]:
        """One still block of one axis: its smallest step against the reference LSB."""
        st, j = obs.stats, obs.col
        step = float(st.step[j])
        return [obs.event(self.kind, self.state, self.value)] if self._step(step, int(st.changes[j])) else []

    def _step(self, step: float, changes: int) -> bool:
        if changes < MIN_CHANGES or not math.isfinite(step) or step <= 0:
            return False
        if math.isnan(self.lsb):
            self._steps.append(step)
            if len(self._steps) >= REF_BLOCKS:
                lo, hi = min(self._steps), max(self._steps)
                self.lsb = lo if hi - lo <= 1e-6 * hi else 0.0
                self._steps = []
            return False
        if self.lsb <= 0:
            return False
        self.state, self.count, changed = debounce(self.state, self.count, step >= 1.9 * self.lsb, HOLD, HOLD)
        if changed and self.state == FAULT:
            self.value = step / self.lsb
        return changed

    def state_dict(self) -> dict:
        return {"state": self.state, "lsb": None if math.isnan(self.lsb) else self.lsb, "count": self.count}

    def load_state_dict(self, d: Mapping) -> None:
        self.state, self.count = int(d.get("state", OK)), int(d.get("count", 0))
        self.lsb = math.nan if d.get("lsb") is None else float(d["lsb"])
