"""A whole log's gyro streams checked offline for the faults that make a log's numbers meaningless: a dead
axis (every sample the same, health.dead), a stuck one (frozen for a stretch a live gyro cannot hold) and a
saturated one (the output flat at its extreme, again and again). ``fleet analyze`` files such an IMU as a
flagged IMU of the ranking, not as a failed log. Pure numpy.

Stuck: the longest run of equal successive samples, against how often this gyro repeats a value by nature
(the share ``p0`` of equal successive samples outside that run: about 0 for float logs, up to 0.4 for an
int16 gyro with 0.7 LSB of noise). Under independent repeats a run of L equal samples somewhere in n has
probability about n p0^(L-1); the run is a fault when that is below ``STUCK_P`` and it lasts at least
``STUCK_MIN_S``. A gyro that repeats most of its samples (p0 >= ``MAX_P0``: quieter than its step) cannot be
told frozen from quiet and is left alone, as the run detector does (health/stuck.py). Nor is an integer
message's (RAW_IMU, SCALED_IMU*: ``lsb`` given): a gyro quieter than 1 mrad/s reads one code throughout a
still stretch (0 or its bias), which a log's moving parts make look rare (public tlogs at 1-2 Hz: 20-79 equal
samples at rest); there only a whole log of one value is named (dead or below resolution, health.dead).

Saturated: a sample at or beyond the gyro's range limit (``abs_limit``: what ``run`` takes, its
``gyro_limit``, 32.767 rad/s by default, the int16 mrad/s full scale), or at least ``PLATEAU_RUNS`` runs of
``RUN`` or more samples exactly at the axis' largest |value|, which is far from 0 (>= ``MIN_LEVEL``), the
plateau statistic of health/saturation.py over the whole log: the peak of healthy motion with noise on top is
neither flat for 5 samples nor at one exact level again and again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.health.dead import AXIS_NAMES, MIN_SAMPLES, constant_axes
from companion.health.saturation import MIN_LEVEL, RUN

STUCK_P = 1e-9  #: chance of so long a run of repeats in a healthy gyro's record below which it is a fault
STUCK_MIN_S = 1.0  #: shortest frozen stretch reported (s)
STUCK_MIN_RUN = 20  #: and in samples
MAX_P0 = 0.9  #: a gyro repeating more of its samples than this is quieter than its step: no stuck verdict
PLATEAU_RUNS = 3  #: separate flat runs at the extreme level that make a clip level
RANGE_LIMIT = 32.767  #: rad/s: the default range limit (run's gyro_limit default, int16 mrad/s full scale)


@dataclass
class AxisFault:
    axis: int  #: 0, 1, 2 for X, Y, Z
    kind: str  #: "dead", "stuck" or "saturated"
    text: str  #: one sentence


def _runs(equal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(starts, lengths) of the runs of True in a boolean array."""
    e = np.r_[False, equal, False].astype(np.int8)
    d = np.diff(e)
    starts = np.flatnonzero(d == 1)
    return starts, np.flatnonzero(d == -1) - starts


def stuck_axis(x: np.ndarray, rate_hz: float) -> tuple[int, int] | None:
    """(start sample, length) of a frozen stretch of ``x`` (see the module), or None."""
    n = x.shape[0]
    if n < MIN_SAMPLES:
        return None
    eq = np.diff(x) == 0
    starts, lengths = _runs(eq)
    if not lengths.shape[0]:
        return None
    i = int(np.argmax(lengths))
    run = int(lengths[i]) + 1  # samples in the run
    rest = eq.shape[0] - int(lengths[i])
    p0 = (int(np.count_nonzero(eq)) - int(lengths[i])) / rest if rest > 0 else 1.0
    long_enough = run >= STUCK_MIN_RUN and (not rate_hz > 0 or run / rate_hz >= STUCK_MIN_S)
    if not long_enough or p0 >= MAX_P0:
        return None
    if p0 > 0 and n * p0 ** (run - 1) >= STUCK_P:
        return None
    return int(starts[i]), run


def saturated_axis(x: np.ndarray, abs_limit: float = RANGE_LIMIT) -> tuple[float, int] | None:
    """(level, number of flat runs at it; 0 when it reached ``abs_limit``) when ``x`` clips (see the module),
    or None."""
    a = np.abs(x)
    level = float(a.max()) if a.shape[0] else 0.0
    if level >= abs_limit:
        return level, 0
    if x.shape[0] < MIN_SAMPLES or not level >= MIN_LEVEL:
        return None
    _, lengths = _runs(a == level)
    flat = int(np.count_nonzero(lengths >= RUN))
    return (level, flat) if flat >= PLATEAU_RUNS else None


def gyro_faults(gyro: np.ndarray, rate_hz: float, t: np.ndarray | None = None, lsb: float | None = None,
                label: str = "", abs_limit: float = RANGE_LIMIT) -> list[AxisFault]:
    """The dead, saturated and stuck axes of an (n, 3) gyro array in rad/s (one fault per axis, in that
    order of precedence). ``lsb``: the step of an integer message (no stuck verdict there, see the module)."""
    from companion.health.dead import dead_gyro_text

    g = np.asarray(gyro, dtype=float)
    n = g.shape[0] if g.ndim == 2 else 0
    out = []
    dead = set(constant_axes(g)) if n else set()
    for a in range(g.shape[1] if g.ndim == 2 else 0):
        x = g[:, a]
        if not np.all(np.isfinite(x[:1])):
            continue
        name = AXIS_NAMES[a]
        if a in dead:
            text = dead_gyro_text(label or "IMU", g[:, [a]], lsb).replace(": X ", f": {name} ")
            out.append(AxisFault(a, "dead", text))
            continue
        sat = saturated_axis(x, abs_limit)
        if sat is not None:
            level, runs = sat
            how = (f"in {runs} flat runs" if runs else
                   f"at or beyond the range limit {abs_limit:.4g} rad/s in {int(np.count_nonzero(np.abs(x) >= abs_limit))} "
                   "sample(s)")
            out.append(AxisFault(a, "saturated", f"gyro {name} saturated: |rate| {level:.4g} rad/s "
                                                 f"({np.degrees(level):.0f} deg/s) {how}"))
            continue
        st = stuck_axis(x, rate_hz) if not lsb else None
        if st is not None:
            i, run = st
            when = f" from {t[i]:.1f} s" if t is not None and i < t.shape[0] else ""
            dur = f"{run / rate_hz:.1f} s, " if rate_hz > 0 else ""
            out.append(AxisFault(a, "stuck", f"gyro {name} stuck at {x[i]:.6g} rad/s{when} ({dur}{run} samples)"))
    return out
