"""Saturation / clipping of a gyro axis: the output sits at a limit.

Two statistics per block: (a) a sample at the message's range limit (``abs_limit``: 32.767 rad/s for
int16 mrad/s) and (b) a plateau: a run of at least ``RUN`` consecutive samples exactly at the block's
largest |value|, that value far above the noise (>= 0.05 rad/s and 10 sigma0), at the same level in
``BLOCKS`` of the last ``WINDOW`` blocks (a clip level is fixed; the peak of healthy motion with noise
on top is neither flat for 5 samples nor at one exact level again and again). Cleared after
``CLEAR_BLOCKS`` blocks without either.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Mapping

from companion.health.faults import FaultEvent, Observation
from companion.health.hold import FAULT, OK, debounce

RUN = 5  # samples in a row exactly at the block's peak: healthy motion plus noise is never this flat
BLOCKS = 3  # blocks at the same plateau level within WINDOW: a clip level is fixed
WINDOW = 10  # recent blocks in which the plateau levels are compared
CLEAR_BLOCKS = 60  # blocks without a limit or a plateau that clear it (a minute of 1-s blocks)
MIN_LEVEL = 0.05  # rad/s


class SaturationDetector:
    kind = "saturation"

    def __init__(self, abs_limit: float = math.inf):
        self.abs_limit = abs_limit
        self.state = OK
        self.levels: deque = deque(maxlen=WINDOW)
        self.quiet = 0
        self.value = math.nan

    def update(self, obs: Observation) -> list[FaultEvent]:
        """One block of one axis: at the range limit, or a plateau at the same level again and again."""
        ref, st, j = obs.ref, obs.stats, obs.col
        top, top_run = float(st.top[j]), int(st.top_run[j])
        noise = 10.0 * math.sqrt(ref.sigma2) if (ref is not None and ref.ready) else 0.0
        hit = top >= 0.999 * self.abs_limit
        level = top if (top_run >= RUN and top >= max(MIN_LEVEL, noise)) else None
        self.levels.append(level)
        same = sum(1 for v in self.levels if v is not None and level is not None and abs(v - level) <= 1e-9 * max(1.0, level))
        now = hit or (level is not None and same >= BLOCKS)
        # on at once; cleared after CLEAR_BLOCKS blocks with neither the limit nor a plateau
        self.state, self.quiet, changed = debounce(self.state, self.quiet, now, 1, CLEAR_BLOCKS,
                                                   good=not (hit or level is not None))
        if changed and self.state == FAULT:
            self.value = top
        return [obs.event(self.kind, self.state, self.value)] if changed else []

    def state_dict(self) -> dict:
        return {"state": self.state, "quiet": self.quiet, "value": None if math.isnan(self.value) else self.value}

    def load_state_dict(self, d: Mapping) -> None:
        self.state, self.quiet = int(d.get("state", OK)), int(d.get("quiet", 0))
        self.value = math.nan if d.get("value") is None else float(d["value"])
