"""White rate noise seen through an autopilot's low-pass filter and then sampled, simulated for the gap
workflow's check by simulation (order 1 or 2, point-sampled or averaged over each logged interval).

Its Allan variance (exact, with the aliasing of decimation) is :mod:`companion.allan.filtered_white`.
"""

from __future__ import annotations

import math

import numpy as np


def synthesize_filtered_white(N: float, cutoff_hz: float, rate_hz: float, n: int, rng, order: int = 2,
                              oversample: int = 8, integrate: bool = False) -> np.ndarray:
    """``n`` samples at ``rate_hz`` of white noise N through the low-pass, simulated at ``oversample`` x the
    rate (the autopilot's sensor rate) and picked every ``oversample``-th sample (no averaging: decimation).
    Noise above oversample x rate / 2 is left out (a small share for cut-offs below the log's rate)."""
    from scipy.signal import butter, sosfilt

    fs = rate_hz * oversample
    w = rng.standard_normal(n * oversample) * (N * math.sqrt(fs))
    sos = butter(order, min(cutoff_hz, 0.45 * fs), fs=fs, output="sos")
    y = sosfilt(sos, w)
    if integrate:  # the mean over each logged interval
        return y[: n * oversample].reshape(n, oversample).mean(axis=1)
    return y[oversample - 1:: oversample][:n]
