"""Data-sufficiency limits of the offline analysis (two meanings of "too slow", named apart)."""

#: Below this rate the Allan curve starts too late for N: the analysis warns, writes no Kalibr file
#: without --force, and does not look for a filter roll-off in the data.
FIT_MIN_RATE_HZ = 10.0
#: Below this many seconds analysed there are too few clusters for a usable N (the same consequences).
FIT_MIN_SECONDS = 60.0
#: Below this rate the short-tau part of the Allan curve (Q, N) is out of reach: inspect says to log faster.
SHORT_TAU_RATE_HZ = 50.0
#: Both rate limits are applied with this tolerance: a log written at a nominal 50 Hz measures 49.6-49.9 Hz (the
#: autopilot's scheduler), and is no slower than one that measures 50.0
RATE_TOLERANCE = 0.95
#: Bias instability and rate random walk need hours of data: inspect notes a shorter longest segment.
LONG_TERMS_S = 3600.0


def fast_enough(rate_hz: float, limit_hz: float) -> bool:
    """Whether a measured rate reaches a rate limit (FIT_MIN_RATE_HZ, SHORT_TAU_RATE_HZ) within RATE_TOLERANCE;
    False for a rate that is not a number."""
    return rate_hz >= RATE_TOLERANCE * limit_hz
