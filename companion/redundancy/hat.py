"""Allan variances of the calibrated pair differences and the three-cornered hat (numpy only).

For IMUs i, j, k with independent noise, the difference of a calibrated pair holds n_j - n_i, so its Allan
variance is A_ij = s_i + s_j (s: each IMU's own Allan variance at that cluster time), and

    s_i = (A_ij + A_ik - A_jk) / 2

per cluster time (Gray & Allan 1974; for gyro arrays Vaccaro & Zaki). Its variance, with Var A = 2 A^2 / EDF
and the covariances of the three curves that share an IMU (Cov(A_ij, A_ik) = 2 s_i^2 / EDF), is

    Var s_i = (2 / EDF) (s_i^2 + (s_i s_j + s_i s_k + s_j s_k) / 2),

so its EDF is EDF s_i^2 / (s_i^2 + (s_i s_j + s_i s_k + s_j s_k) / 2): 0.4 EDF for three equal IMUs, less for the
quietest of three. An estimate can come out <= 0 (the others dominate, or a vibration two IMUs do not share);
it is then only an upper bound.
"""

from __future__ import annotations

import numpy as np

from companion.allan.confidence import edf_simple
from companion.allan.pooled import pooled_cluster_sizes, pooled_oavar


def quantization_avar(lsb, tau, rate_hz: float) -> np.ndarray:
    """The Allan variance of the rounding of moving rate samples to ``lsb`` (white, variance lsb^2 / 12 per
    sample: N_q^2 = lsb^2 / (12 rate)); 0 for float data (lsb None or 0)."""
    if not lsb:
        return np.zeros_like(np.asarray(tau, dtype=float))
    return (float(lsb) ** 2 / 12.0) / (rate_hz * np.asarray(tau, dtype=float))


def pair_points(residual: list, rate_hz: float, axis: int, m=None):
    """(tau, avar, edf, m) of one axis of a pair's residual pieces (pooled overlapping AVAR, octave cluster
    sizes of the longest piece; EDF of white noise from the pooled count of differences)."""
    pieces = [np.asarray(r[:, axis], dtype=float) for r in residual]
    lengths = [p.shape[0] for p in pieces]
    if m is None:
        m = pooled_cluster_sizes(lengths, "octave")
    tau, avar, m, counts = pooled_oavar(pieces, rate_hz, m=m)
    edf = np.array([float(edf_simple(int(c) + 2 * int(mm), mm, 0)) for c, mm in zip(counts, m)])
    return tau, avar, np.maximum(edf, 0.5), m


def hat_share(a_ij, a_ik, a_jk, edf):
    """(s_i, its EDF, its standard deviation) per cluster time from the three pair curves (module docstring);
    the EDF uses the estimates floored at 0 (a negative share has no EDF of its own: 0)."""
    a_ij, a_ik, a_jk, edf = (np.asarray(x, dtype=float) for x in (a_ij, a_ik, a_jk, edf))
    s_i = (a_ij + a_ik - a_jk) / 2.0
    s_j = np.maximum((a_ij + a_jk - a_ik) / 2.0, 0.0)
    s_k = np.maximum((a_ik + a_jk - a_ij) / 2.0, 0.0)
    si = np.maximum(s_i, 0.0)
    cross = (si * s_j + si * s_k + s_j * s_k) / 2.0
    var = (2.0 / edf) * (si * si + cross)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.where(si > 0, edf * si * si / (si * si + cross), 0.0)
    return s_i, e, np.sqrt(var)
