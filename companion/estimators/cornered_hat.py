"""Three-cornered hat: each of three sensors' own variance from the variances of their pairwise differences
(clock metrology; Allan covariance of gyro arrays, Vaccaro & Zaki), and the white-noise level of a
difference read from its Allan variance (numpy only).

With independent noises of variances v_0, v_1, v_2 (per tau, or the white-noise coefficient N^2), the
difference of i and j has V_ij = v_i + v_j, so

    v_i = (V_ij + V_ik - V_jk) / 2,        var(v_i) = (var V_ij + var V_ik + var V_jk) / 4           (1)

(the three pair estimates treated as independent: each pair's figure comes from its own difference). A
negative or unresolved v_i (below two of its sigmas) is the pair figures' scatter, not a negative noise: it
becomes a 95 % upper bound ``max(v_i, 0) + 1.96 sigma``, with the reason. With two sensors only the pair
figure V_01 exists: each sensor's variance is at most V_01 (a bound for both), split only where the ratio
v_0 / v_1 is known from elsewhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

Z95 = 1.96


@dataclass(frozen=True)
class Share:
    """One sensor's variance from the hat: ``value`` (a 95 % upper bound when ``bound``), its 1-sigma
    ``std`` and, for a bound, the ``reason``."""

    value: float
    std: float
    bound: bool = False
    reason: str = ""


def hat_arrays(v01, v02, v12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. (1) per tau on arrays of the three pair variances: (v0, v1, v2), negative values kept."""
    v01, v02, v12 = (np.asarray(v, dtype=float) for v in (v01, v02, v12))
    return 0.5 * (v01 + v02 - v12), 0.5 * (v01 + v12 - v02), 0.5 * (v02 + v12 - v01)


def hat(pairs: dict) -> dict[int, Share]:
    """Eq. (1) for three sensors from ``{(i, j): (V_ij, var V_ij)}`` (i < j, the three pairs of three
    sensors); per sensor its :class:`Share`. Missing or non-finite pair figures give no share."""
    imus = sorted({k for p in pairs for k in p})
    if len(imus) != 3 or len(pairs) != 3:
        return {}
    out = {}
    for i in imus:
        j, k = (x for x in imus if x != i)
        a, b, c = pairs[tuple(sorted((i, j)))], pairs[tuple(sorted((i, k)))], pairs[(j, k)]
        v = 0.5 * (a[0] + b[0] - c[0])
        var = 0.25 * (a[1] + b[1] + c[1])
        if not (math.isfinite(v) and math.isfinite(var)):
            continue
        s = math.sqrt(max(var, 0.0))
        if v < 2.0 * s:
            why = ("negative: the pairs' scatter exceeds this IMU's share" if v < 0
                   else "below two sigmas of the pairs' scatter")
            out[i] = Share(max(v, 0.0) + Z95 * s, s, True, why)
        else:
            out[i] = Share(v, s)
    return out


def white_level(tau: np.ndarray, avar: np.ndarray, edf: np.ndarray, tau_min: float,
                min_edf: float = 20.0) -> tuple[float, float]:
    """(N^2, its 1-sigma) of a difference from its Allan variance at the first octave ``tau >= tau_min``
    with ``edf >= min_edf``: N^2 = AVAR(tau) tau (white noise: AVAR = N^2 / tau), relative 1-sigma
    sqrt(2 / edf) (chi-square). Above the low-pass filter's time scale the white level is read free of the
    filter; well below a second the calibration's slow residue (bias wander) and its motion leakage stay
    small. (nan, nan) when no level qualifies."""
    tau, avar, edf = (np.asarray(x, dtype=float) for x in (tau, avar, edf))
    ok = np.flatnonzero((tau >= tau_min * (1 - 1e-9)) & (edf >= min_edf) & np.isfinite(avar))
    if ok.size == 0:
        return math.nan, math.nan
    k = int(ok[0])
    v = float(avar[k] * tau[k])
    return v, v * math.sqrt(2.0 / float(edf[k]))
