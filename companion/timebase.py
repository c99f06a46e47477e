"""The sampling period of a stream from its own timestamps (numpy only): the one period rule that the
offline timing analysis (:mod:`companion.sources.timestamps`), the live pipeline and the health checks use."""

from __future__ import annotations

import numpy as np

#: timestamp resolution of the IMU messages that carry ``time_boot_ms`` (the others: 1 us, taken as 0)
MS_STAMPED = ("SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3")


def stamp_resolution(message: str) -> float:
    """The resolution of a message's timestamps in seconds (1 ms for ``time_boot_ms``, else 0)."""
    return 1e-3 if message in MS_STAMPED else 0.0


def period_of(intervals, resolution: float = 0.0) -> float:
    """The sampling period from positive timestamp intervals: ``P0`` = their median, ``P1`` = the mean of
    the intervals within ``P0 +- (0.5 P0 + r)`` (``r`` = the stamps' resolution), then ``P`` = the mean of
    those within ``P1 +- max(0.5 P1, r)``: longer intervals are lost samples or gaps, and a late sample
    splits one period into a short and a long interval that go together (a telemetry stream at 2 Hz with
    intervals of 0.12 + 0.88 s: the short one alone would take its rate 3 % high). A 400 Hz stream stamped in whole
    milliseconds (intervals of 2 and 3 ms, 5 ms where one was lost) gets 2.5 ms, where the median alone
    says 2 or 3 ms (500 or 333 Hz) and one pass lets the 5-ms intervals in. NaN without intervals."""
    d = np.asarray(intervals, dtype=np.float64)
    if not np.all(d > 0):  # copied only where some interval is not positive (8 MB per million samples)
        d = d[d > 0]
    if d.shape[0] == 0:
        return float("nan")
    p = float(np.median(d))
    half = 0.5 * p + resolution
    for _ in range(2):
        dev = d - p
        np.abs(dev, out=dev)
        normal = d[dev <= half]
        del dev
        if normal.shape[0] == 0:
            break
        p = float(normal.mean())
        half = max(0.5 * p, resolution)
    return p
