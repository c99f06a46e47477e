"""Rate drop and irregular timing of one IMU stream (message time).

Per block: the rate 1 / period (:func:`companion.timebase.period_of`: the mean of the intervals no farther from
their median than half of it plus the timestamp resolution) and the jitter: the rms of each interval's distance to
the nearest whole number of periods, less the timestamp resolution ``stamp_res`` (1 ms for
``time_boot_ms``: a 400 Hz stream stamped in whole ms steps 2, 3, 2, 3 ms and is regular), over the
period (a lost message leaves an interval of exactly two periods and no jitter: losses on the link are
not a sensor fault). The reference is the median rate of the first
``REF_BLOCKS`` blocks. FAULT when, in ``HOLD`` consecutive blocks, the rate is below ``DROP`` x the
reference (the sensor itself slowed by 30 %) or the jitter is above ``JITTER`` (intervals scattered by
20 % of the period; ArduPilot's streams at 100 Hz show a few %). Cleared after ``HOLD`` good blocks. A
stream that stops altogether is the link's "stale" (HLTH 3).
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from companion.health.faults import FaultEvent, Observation
from companion.health.hold import FAULT, OK, debounce
from companion.timebase import period_of

REF_BLOCKS = 10  # blocks whose median rate is the reference
HOLD = 5  # bad (good) blocks in a row that flag (clear) it
DROP = 0.7  # the rate below this share of the reference: the sensor itself slowed by 30 %
JITTER = 0.2  # rms interval scatter over the period (ArduPilot's 100 Hz streams show a few %)
#: intervals a block needs for its jitter to be judged: below it (a telemetry stream under 10 Hz) the rms of
#: a few intervals scatters past JITTER by chance, and such a stream's times are the autopilot's choice of
#: which sample to send, not the sensor's clock; its rate drop is still judged
JITTER_MIN_INTERVALS = 10


class TimingDetector:
    kind = "rate"

    def __init__(self, stamp_res: float = 0.0):
        self.stamp_res = float(stamp_res)
        self.state = OK
        self.ref_rate = math.nan
        self._rates: list = []
        self.count = 0
        self.value = math.nan
        self.detail = ""

    def update(self, obs: Observation) -> list[FaultEvent]:
        """One block of the IMU (its timestamps ``obs.t``); the event names the whole IMU (axis "")."""
        if not self._step(np.asarray(obs.t, dtype=float)):
            return []
        return [FaultEvent(obs.imu, "", self.kind, self.state, self.value, self.detail)]

    def _step(self, t: np.ndarray) -> bool:
        if t.size < 5 or t[-1] <= t[0]:
            return False
        dt = np.diff(t)
        period = period_of(dt, self.stamp_res)
        if not period > 0:
            return False
        rate = 1.0 / period
        k = np.maximum(np.round(dt / period), 1.0)
        dev = np.maximum(np.abs(dt - k * period) - self.stamp_res, 0.0)
        jitter = float(np.sqrt(np.mean((dev / period) ** 2)))
        if math.isnan(self.ref_rate):
            self._rates.append(rate)
            if len(self._rates) >= REF_BLOCKS:
                self.ref_rate = float(np.median(self._rates))
                self._rates = []
            return False
        bad = rate < DROP * self.ref_rate or (jitter > JITTER and dt.size >= JITTER_MIN_INTERVALS)
        self.state, self.count, changed = debounce(self.state, self.count, bad, HOLD, HOLD)
        if changed and self.state == FAULT:
            self.value = rate
            self.detail = (f"rate {rate:.0f} Hz (was {self.ref_rate:.0f})" if rate < DROP * self.ref_rate
                           else f"timing irregular ({100 * jitter:.0f} % jitter)")
        return changed

    def state_dict(self) -> dict:
        return {"state": self.state, "ref_rate": None if math.isnan(self.ref_rate) else self.ref_rate,
                "count": self.count}

    def restart(self) -> None:
        """A new run restored from the state: the timing is the new run's stream's (its rate is what the
        ground station requested this time), judged afresh and said again if it is still irregular. A
        restored FAULT had no value and stayed silent: a public SITL log replayed with its own state ended
        with "FAULT: IMU0 gyro rate nan Hz" in the summary and no STATUSTEXT."""
        self.state, self.count, self.ref_rate, self._rates = OK, 0, math.nan, []
        self.value, self.detail = math.nan, ""

    def load_state_dict(self, d: Mapping) -> None:
        self.state, self.count = int(d.get("state", OK)), int(d.get("count", 0))
        self.ref_rate = math.nan if d.get("ref_rate") is None else float(d["ref_rate"])
