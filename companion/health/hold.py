"""The hold (debounce) rule shared by the counting detectors: a state changes only after a run of blocks.

PX4-style hysteresis with explicit counts: resolution.py and timing_faults.py (``HOLD`` both ways),
saturation.py (on at once, off after ``CLEAR_BLOCKS``), bias.py's drift (off after ``DRIFT_HOLD``) and
degradation.py's test (``hold_on`` / ``hold_off`` checks). Plain ints; no numpy.
"""

from __future__ import annotations

OK = 0
FAULT = 1


def debounce(state: int, count: int, bad: bool, hold_on: int, hold_off: int,
             good: bool | None = None) -> tuple[int, int, bool]:
    """Hysteresis shared by the counting detectors: while OK count consecutive ``bad`` blocks, FAULT after
    ``hold_on``; while FAULT count consecutive ``good`` ones (default ``not bad``), OK after ``hold_off``.
    Returns (state, count, changed); the count restarts at 0 on every change."""
    if state == OK:
        count = count + 1 if bad else 0
        if count >= hold_on:
            return FAULT, 0, True
    else:
        count = count + 1 if (not bad if good is None else good) else 0
        if count >= hold_off:
            return OK, 0, True
    return state, count, False
