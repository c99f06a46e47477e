"""Equivalent degrees of freedom (EDF) of the overlapping Allan variance (private to the gap workflow).

Empirical formulas of Howe, Allan and Barnes as tabulated in NIST SP 1065 (Riley 2008), Table 5, for
N phase points and averaging factor m (evaluated by :func:`companion.allan.confidence.edf_simple`):

==============  ==============================================================
noise type      EDF of the overlapping AVAR
==============  ==============================================================
white PM        (N+1)(N-2m) / (2(N-m))
flicker PM      exp( sqrt( ln((N-1)/(2m)) ln((2m+1)(N-1)/4) ) )
white FM        [3(N-1)/(2m) - 2(N-2)/N] 4m^2 / (4m^2 + 5)
flicker FM      m = 1: 2(N-2) / (2.3N - 4.9);   m >= 2: 5N^2 / (4m(N + 3m))
random-walk FM  (N-2)/m [(N-1)^2 - 3m(N-1) + 4m^2] / (N-3)^2
==============  ==============================================================

For gyro *rate* data the noise types map onto the IEEE 952 terms by the AVAR slope mu (sigma^2 ~ tau^mu):
quantisation mu = -2 (white PM), white rate noise (ARW) mu = -1 (white FM), bias instability mu = 0
(flicker FM), rate random walk mu = +1 (random-walk FM). Between integer slopes ln(EDF) is interpolated
linearly in mu; slopes outside [-2, 1] are clipped (a ramp, mu = 2, uses the random-walk FM value).
The result is clipped to >= 1.
"""

from __future__ import annotations

import numpy as np

from companion.allan.confidence import edf_simple


def _edf_types(n_phase: float, m: np.ndarray) -> np.ndarray:
    """EDF for mu = -2, -1, 0, +1 (rows) at each m (columns), from :func:`companion.allan.confidence.edf_simple`."""
    m = np.asarray(m, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        # mu = -2 is white PM (angle quantisation, alpha = 2); flicker PM (alpha = 1) shares its AVAR slope but
        # has far fewer EDF: take the smaller of the two, the cautious choice for a mixed curve.
        pm = np.fmin(edf_simple(n_phase, m, 2), np.nan_to_num(edf_simple(n_phase, m, 1), nan=1.0))
        rows = [pm, edf_simple(n_phase, m, 0), edf_simple(n_phase, m, -1), edf_simple(n_phase, m, -2)]
    return np.maximum(np.nan_to_num(np.vstack(rows), nan=1.0), 1.0)


def oavar_edf(n_phase: int, m, mu) -> np.ndarray:
    """EDF of overlapping AVAR estimates at factors ``m`` given the local AVAR slopes ``mu``."""
    m = np.asarray(m, dtype=float)
    mu = np.clip(np.asarray(mu, dtype=float), -2.0, 1.0)
    table = np.log(_edf_types(n_phase, m))  # (4, len(m)) for mu = -2, -1, 0, 1
    lo = np.clip(np.floor(mu).astype(int), -2, 0)
    frac = mu - lo
    cols = np.arange(m.shape[0])
    ln_edf = (1.0 - frac) * table[lo + 2, cols] + frac * table[lo + 3, cols]
    return np.maximum(np.exp(ln_edf), 1.0)


def local_slope(tau, avar) -> np.ndarray:
    """Log-log slope of ``avar`` against ``tau`` (centred differences, one-sided at the ends)."""
    lt = np.log(np.asarray(tau, dtype=float))
    la = np.log(np.maximum(np.asarray(avar, dtype=float), 1e-300))
    if lt.shape[0] < 2:
        return np.full(lt.shape, -1.0)
    return np.gradient(la, lt)
