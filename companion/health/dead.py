"""A dead gyro: an axis whose every sample is the same value (exactly 0 when the sensor is absent or never
started, a constant when its output froze before the log began).

Nothing can be estimated from such an axis and no motion gate can be trusted on it, so every command
names it first: ``inspect`` in its notes, ``analyze`` before any word on the still selection (a dead gyro
of a rover logged only while armed would otherwise be refused as "armed throughout" without a word about
the gyro), ``fleet`` as the log's error, ``run`` as ``dead`` (health/stuck.py: equal values, exactly 0).
On an integer message (RAW_IMU, SCALED_IMU*: int16 mrad/s) exactly 0 at rest is also what a gyro quieter
than the 1 mrad/s step gives (ArduPilot SITL), so the sentence names both. Pure numpy.
"""

from __future__ import annotations

import numpy as np

AXIS_NAMES = ("X", "Y", "Z")
MIN_SAMPLES = 20  # a handful of equal samples may be a short log of a quiet coarse gyro


def constant_axes(gyro: np.ndarray, min_samples: int = MIN_SAMPLES) -> list[int]:
    """The axes (0..2) of an (n, 3) gyro array whose every sample equals the first (n >= ``min_samples``)."""
    g = np.asarray(gyro, dtype=float)
    if g.ndim != 2 or g.shape[0] < min_samples:
        return []
    return [a for a in range(g.shape[1]) if np.all(g[:, a] == g[0, a])]


def dead_gyro_text(label: str, gyro: np.ndarray, lsb: float | None = None) -> str | None:
    """One sentence naming the dead axes of a stream, or None: e.g. ``IMU[0] ...: gyro dead: X, Y, Z exactly 0
    in all 8578 samples``. ``lsb``: the step of an integer message (RAW_IMU, SCALED_IMU*: 1 mrad/s), where a
    gyro quieter than one step also reads 0 at rest (ArduPilot SITL): then both causes are named."""
    axes = constant_axes(gyro)
    if not axes:
        return None
    g = np.asarray(gyro, dtype=float)
    vals = {float(g[0, a]) for a in axes}
    names = ", ".join(AXIS_NAMES[a] for a in axes)
    if lsb and vals == {0.0}:
        return (f"{label}: gyro dead or below resolution: {names} exactly 0 in all {g.shape[0]} samples (the "
                f"message's step is {lsb * 1e3:.3g} mrad/s = {np.degrees(lsb):.3g} deg/s: a gyro quieter than that "
                "reads 0 at rest; HIGHRES_IMU carries float rad/s): nothing can be estimated from it")
    what = "exactly 0" if vals == {0.0} else "constant (" + ", ".join(f"{v:.6g}" for v in sorted(vals)) + " rad/s)"
    return (f"{label}: gyro dead: {names} {what} in all {g.shape[0]} samples "
            "(sensor absent, not started or frozen): nothing can be estimated from it")
