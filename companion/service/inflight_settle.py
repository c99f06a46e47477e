"""The in-flight test's flight data without take-offs and landings (numpy only).

A take-off's spin-up and a touchdown shake two IMUs differently: on real logs a landing lifts a pair's figure
3x for the test's 30 s memory, and a baseline that holds one calls the quiet flight after it 0.5x
(pxf_copter_22-12-2014_41). :class:`SettledFlight` passes on a flight stretch's data only from ``settle_s``
after its start to ``settle_s`` before its newest sample; the held last ``settle_s`` reach the test once the
flight has gone on that long, and are dropped when the stretch ends (the condition turns ground after its
hold of stillness, or the vehicle disarms), so a touchdown never reaches the test. The figures reported for
the flight (:class:`companion.service.inflight_live.PairTrack`'s whole-flight accumulators) keep every sample.
"""

from __future__ import annotations

import numpy as np


class SettledFlight:
    """One pair's data for the test: :meth:`route` each block of calibrated differences, :meth:`end` when the
    vehicle disarms."""

    def __init__(self, settle_s: float):
        self.settle_s = float(settle_s)
        self.since: float | None = None  # start of the current stretch
        self.held: list[tuple[np.ndarray, np.ndarray, bool]] = []  # (t, difference, starts a segment)
        self.carry = False  # the next chunk out starts a new segment (data were left out before it)

    def route(self, t: np.ndarray, e: np.ndarray, cond: str, junction: bool) -> list[tuple[np.ndarray, bool]]:
        """The chunks of differences for the test now, each with whether it starts a new segment: a ground
        block at once (ending a flight stretch), a flight block held (:meth:`push`). ``junction``: the block
        starts a new segment (a gap, a change of condition)."""
        if cond != "flight":
            self.end()
            out, self.carry = [(e, junction or self.carry)], False
            return out
        return self.push(t, e, junction)

    def push(self, t: np.ndarray, e: np.ndarray, junction: bool) -> list[tuple[np.ndarray, bool]]:
        """Hold a flight block; return the chunks now settled: at least ``settle_s`` after the stretch's start
        and before ``t[-1]``."""
        if self.since is None:  # a stretch starts: the test has not seen its take-off, a new segment
            self.since, self.held, self.carry = float(t[0]), [], True
        self.held.append((t, e, junction))
        settled, end = self.since + self.settle_s, float(t[-1]) - self.settle_s
        out = []
        while self.held and float(self.held[0][0][0]) <= end:
            tb, eb, junction = self.held.pop(0)
            later = tb > end
            if later.any():  # the rest waits for the flight to go on
                self.held.insert(0, (tb[later], eb[later], False))
            keep = (tb >= settled) & ~later
            if keep.any():
                out.append((eb[keep], junction or self.carry))
                self.carry = False
            else:
                self.carry = self.carry or junction
        return out

    def end(self) -> None:
        """The stretch ended (ground, disarmed): drop its held last ``settle_s`` (the landing); the test's next
        data start a new segment."""
        if self.since is not None:
            self.carry = True
        self.since, self.held = None, []
