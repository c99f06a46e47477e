"""The rate history of one IMU stream: blocks off its rate, switches, and the state kept for other rates.

A stream's rate changes when another client requests it at another rate or a log's rate changes: not a
sensor fault. A block whose own rate is off the stream's rate by more than RATE_CHANGE is held back from
every detector and estimator (:func:`block_off_rate`); after OFF_RATE_BLOCKS such blocks at one rate the
channel switches to it. What depends on the rate (estimators, fault references) is kept aside per rate
(:class:`RateProfile`) for when the stream returns to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.health.monitor import ImuFaults
from companion.service.blocks import MIN_INTERVALS, RATE_CHANGE
from companion.service.estimator_bank import EstimatorBank
from companion.timebase import period_of

#: consecutive blocks at one new rate, with MIN_INTERVALS intervals among them, before the channel switches
OFF_RATE_BLOCKS = 3
FEW_INTERVALS = 8  # a block with fewer intervals (a stream below 8 Hz) is off rate only when every one is
#: other rates whose estimators and references are kept for when the stream returns to them (memory: each
#: holds three estimator banks per axis)
KEPT_RATES = 4
#: rate switches of one IMU logged line by line; the later ones are counted and summed up in the summary: a
#: router that sets the stream rates every 15 s, or an autopilot that slows its telemetry streams while the
#: radio is busy, would otherwise fill the log
RATE_SWITCHES_LOGGED = 3


def block_off_rate(d: np.ndarray, rate_hz: float, resolution: float = 0.0, tol: float = RATE_CHANGE) -> float | None:
    """The rate of a block with intervals ``d`` when it is off the stream's ``rate_hz`` by more than
    ``tol`` (RATE_CHANGE, or the stream's own spread: service/blocks.py), else None. A block of a slow stream holds two or three intervals, and one late message splits
    a period into a short and a long interval (a 2 Hz telemetry stream: 0.13 + 0.87 s) that no period rule
    reads on its own: such a block is off rate only when all its intervals are off the period, the same way
    (a stream requested at another rate); the blocks held back for it cost the estimators their long taus."""
    p = period_of(d, resolution)
    if not (p > 0) or abs(math.log(p * rate_hz)) <= math.log1p(tol):
        return None
    if d.shape[0] < FEW_INTERVALS:
        k = d * rate_hz  # the intervals in periods of the stream
        if not (np.all(k < 1.0 / (1.0 + tol)) or np.all(k > 1.0 + tol)):
            return None
    return 1.0 / p


@dataclass
class RateProfile:
    """What one IMU learned at one rate: its estimators and its fault detectors with their references."""

    bank: EstimatorBank
    faults: ImuFaults


class RateTracker:
    """Off-rate blocks, the number of switches and the profiles kept for other rates."""

    def __init__(self):
        self.off_rate: list[float] = []  # block rates of the consecutive blocks off the stream's rate
        self.off_dts: list[float] = []  # their intervals (the window of the rate switched to)
        self.switches = 0
        self.kept: list[tuple[float, RateProfile]] = []

    def observe(self, t: np.ndarray, rate_hz: float, resolution: float,
                tol: float = RATE_CHANGE) -> tuple[bool, float | None]:
        """A closed block's times ``t`` at the stream's ``rate_hz``: (held back, the rate to switch to or
        None). Blocks off rate count only while they agree with each other within ``tol``."""
        d = np.diff(t)
        r = block_off_rate(d, rate_hz, resolution, tol)
        if r is None:
            self.off_rate, self.off_dts = [], []
            return False, None
        if self.off_rate and abs(math.log(r / self.off_rate[-1])) > math.log1p(tol):
            self.off_rate, self.off_dts = [], []
        self.off_rate.append(r)
        self.off_dts += d.tolist()
        if len(self.off_rate) >= OFF_RATE_BLOCKS and len(self.off_dts) >= MIN_INTERVALS:
            # the held blocks together: a slow stream's blocks hold one or two intervals each, and three
            # of them off the same way happen by chance where the intervals wander (a busy radio)
            rate = 1.0 / period_of(self.off_dts, resolution)
            if abs(math.log(rate / rate_hz)) > math.log1p(tol):
                return True, float(rate)
        return True, None

    def keep(self, rate: float, profile: RateProfile) -> None:
        """Keep ``profile`` aside for ``rate``, beside (not in place of) a kept rate within RATE_CHANGE of it:
        the stream's rate can drift between switches, and the one put aside then may hold seconds where the
        other holds minutes."""
        self.kept.append((rate, profile))
        if len(self.kept) > KEPT_RATES:
            # the rate with the least still data goes: a stream that wanders over more rates than are kept
            # (a telemetry stream the autopilot slows while the radio is busy) keeps its richest ones
            self.kept.pop(min(range(len(self.kept)), key=lambda i: self.kept[i][1].bank.fed_s))

    def take(self, new_rate: float) -> RateProfile | None:
        """The kept profile for ``new_rate``, removed from the kept ones, or None. Of the kept rates the new
        one would be no change from (``new_rate / kept - 1`` within RATE_CHANGE, the test of
        :func:`block_off_rate`), the one with the most still data, then the closest."""
        match = [(-p.bank.fed_s, abs(new_rate / r - 1.0), i) for i, (r, p) in enumerate(self.kept)
                 if abs(new_rate / r - 1.0) <= RATE_CHANGE]
        if not match:
            return None
        *_, i = min(match)
        return self.kept.pop(i)[1]

    def switched(self) -> None:
        """A switch happened: the off-rate count starts again."""
        self.off_rate, self.off_dts = [], []
        self.switches += 1

    def kept_summary(self) -> tuple[int, float]:
        """(how many other rates, their still seconds)."""
        return len(self.kept), float(sum(p.bank.fed_s for _, p in self.kept))

    def kept_banks(self) -> list[EstimatorBank]:
        return [p.bank for _, p in self.kept]
