"""--taus: the cluster sizes shown in the table, JSON and plot."""

from __future__ import annotations

import math

import numpy as np

from companion.allan.adev import cluster_sizes
from companion.errors import CompanionError


def parse_taus(spec: str, n: int, rate_hz: float):
    """--taus to cluster sizes m (samples) for ``n`` samples; seconds lists are rounded to whole samples."""
    spec = spec.strip()
    if spec in ("octave", "decade", "all") or spec.startswith("log:"):
        try:
            return cluster_sizes(n, spec)
        except ValueError:  # the core says "log:K"; K here is the rate random walk's name
            raise CompanionError(f"bad --taus {spec!r}: log:N takes a whole number N >= 1 of cluster times per "
                                 "decade") from None
    try:
        secs = [float(s) for s in spec.split(",") if s.strip()]
    except ValueError:
        raise CompanionError(f"bad --taus {spec!r}: expected octave, decade, all, log:N or seconds like 0.1,1,10") from None
    if not secs or any(not (s > 0 and math.isfinite(s)) for s in secs):
        raise CompanionError(f"bad --taus {spec!r}: cluster times must be positive seconds")
    return cluster_sizes(n, np.maximum(np.round(np.array(secs) * rate_hz), 1).astype(np.int64))


def taus_beyond(spec: str, n: int, rate_hz: float) -> list[float]:
    """The cluster times (s) of a --taus seconds list that a record of ``n`` samples cannot reach
    (overlapping ADEV needs m <= n/2); [] for octave/decade/all/log:N."""
    spec = spec.strip()
    if spec in ("octave", "decade", "all") or spec.startswith("log:"):
        return []
    try:
        secs = [float(x) for x in spec.split(",") if x.strip()]
    except ValueError:
        return []  # parse_taus gives the error
    return [x for x in secs if math.isfinite(x) and x > 0 and max(round(x * rate_hz), 1) > n // 2]
