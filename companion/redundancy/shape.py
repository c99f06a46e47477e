"""The Allan-variance shape of white noise through known low-pass filters at the logged rate (numpy and
scipy only): each IMU's samples are filtered with the other IMUs' filters, so that every IMU's noise went
through the same cascade; the Allan points are then divided by the cascade's shape and the white-noise level
is read from the shortest cluster times on, where most of the record's degrees of freedom are.

For a rate series of sample period tau0 with two-sided PSD S(f) the overlapping Allan variance at m samples is

    sigma^2(m) = (2 / m^2) int_0^{fs/2} 2 S(f) sin^4(pi f m tau0) / sin^2(pi f tau0) df   (fs = 1 / tau0),

so the shape of white noise through the cascade H is the ratio of that integral with S |H|^2 to the one with S
(IEEE Std 1139 / NIST SP 1065 transfer function of the Allan variance, discrete form).
"""

from __future__ import annotations

import numpy as np

#: a cut-off at or above this fraction of the rate cannot be run at the logged rate
MAX_FILTER_FRACTION = 0.45
#: frequency points of the integral
GRID = 1 << 14


def cascade_ba(filters, rate_hz: float) -> list:
    """(b, a) of each 2-pole Butterworth low-pass of ``filters`` (Hz) at ``rate_hz`` (bilinear, pre-warped as
    ArduPilot's LowPassFilter2p)."""
    from scipy import signal

    return [signal.butter(2, f, fs=rate_hz) for f in filters]


def usable(filters, rate_hz: float) -> bool:
    """Whether every filter is known and runs at the logged rate."""
    return bool(filters) and all(f and 0 < f < MAX_FILTER_FRACTION * rate_hz for f in filters)


def avar_shape(filters, rate_hz: float, m) -> np.ndarray:
    """Allan variance of white noise through the cascade of ``filters`` over that of plain white noise, at
    cluster sizes ``m`` (1 at long cluster times)."""
    from scipy import signal

    m = np.asarray(m, dtype=float)
    f = (np.arange(GRID) + 0.5) / GRID * 0.5  # cycles per sample, (0, 1/2)
    h2 = np.ones_like(f)
    for b, a in cascade_ba(filters, rate_hz):
        _, h = signal.freqz(b, a, worN=2 * np.pi * f)
        h2 *= np.abs(h) ** 2
    out = np.empty(m.shape[0])
    s2 = np.sin(np.pi * f) ** 2
    for k, mm in enumerate(m):
        kern = np.sin(np.pi * f * mm) ** 4 / s2
        out[k] = float(np.sum(kern * h2) / np.sum(kern))
    return out


def equalize(pieces_per_track: list, filters, rate_hz: float) -> list:
    """Each track's pieces filtered with every other track's filter (state started at the first value), so
    that all tracks went through the same cascade."""
    from scipy import signal

    bas = cascade_ba(filters, rate_hz)
    out = []
    for i, pieces in enumerate(pieces_per_track):
        res = []
        for x in pieces:
            y = np.asarray(x, dtype=float)
            for j, (b, a) in enumerate(bas):
                if j != i:
                    zi = signal.lfilter_zi(b, a)[:, None] * y[0][None, :]
                    y = signal.lfilter(b, a, y, axis=0, zi=zi)[0]
            res.append(y)
        out.append(res)
    return out
