"""Overlapping Allan variance pooled over several contiguous segments of one sensor (numpy only).

A flight log holds several still stretches (before arming, after landing, between logging gaps); none may
be joined to another (the samples between them are missing or moving). Each segment s of n_s rate
samples contributes its own overlapping second differences of the phase x (integrated rate):

    S_s(m) = sum_{i=0}^{n_s - 2m} (x_{i+2m} - 2 x_{i+m} + x_i)^2,     c_s(m) = n_s + 1 - 2m  (if > 0)

and the pooled estimate is the count-weighted mean of the per-segment estimates

    sigma^2(tau) = sum_s S_s(m) / (2 tau^2 sum_s c_s(m)),    tau = m tau0,

i.e. every second difference that lies entirely inside one segment counts once, none crosses a gap
(Riley, *Handbook of Frequency Stability Analysis*, NIST SP 1065, sec. 5.2.4 for the single-record
case; gaps handled as in the "gap-tolerant" AVAR of Sesia et al. 2010). A cluster time is kept while at
least one segment holds 2m + 1 phase points, so tau is limited by the longest segment.

Covariance and EDF: segments are independent, so with weights w_s(m) = c_s(m) / sum_s c_s(m)

    Cov[sigma^2(m_i), sigma^2(m_j)] = sum_s w_s(m_i) w_s(m_j) Cov_s(m_i, m_j),

Cov_s from :func:`companion.allan.confidence.oavar_covariance` for the segment's length, and the EDF of
a point is 2 sigma^4 / Var, i.e. the EDF follows the pooled count of differences.
"""

from __future__ import annotations

import numpy as np

from companion.allan.adev import cluster_sizes, phase_from_rate


#: differences computed per block: 4 x 256 kB of float64 (the block and the three phase slices) stay in the cache
DIFF_BLOCK = 1 << 15


def pooled_cluster_sizes(lengths, spec="octave") -> np.ndarray:
    """Cluster sizes for segments of ``lengths`` samples: those of the longest segment."""
    return cluster_sizes(int(max(lengths)) if len(lengths) else 0, spec)


def pooled_oavar(segments, rate_hz: float, m=None, spec="octave"):
    """Pooled overlapping AVAR of rate segments (a list of 1-D arrays) at cluster sizes ``m``.

    Returns ``(tau, avar, m, counts)`` with ``counts[k]`` = sum_s c_s(m_k), the number of second
    differences behind each point. Cluster sizes no segment can hold are dropped.
    """
    segs = [np.asarray(s, dtype=float) for s in segments if np.asarray(s).shape[0] >= 2]
    lengths = [s.shape[0] for s in segs]
    if m is None:
        m = pooled_cluster_sizes(lengths, spec)
    m = np.asarray(m, dtype=np.int64)
    m = m[(m >= 1) & (m <= (max(lengths) // 2 if lengths else 0))]
    sums = np.zeros(m.shape[0])
    counts = np.zeros(m.shape[0], dtype=np.int64)
    for y in segs:
        x = phase_from_rate(y, rate_hz)  # the mean of each segment is removed: AVAR ignores a constant
        npt = x.shape[0]
        buf = np.empty(npt)  # one buffer for every m: a fresh array per m costs its page faults again
        for j, mj in enumerate(m):
            c = npt - 2 * mj
            if c < 1:
                break
            sums[j] += _second_difference_sq(x, int(mj), buf[:c])
            counts[j] += c
    tau = m / rate_hz
    with np.errstate(invalid="ignore", divide="ignore"):
        avar = sums / (2.0 * tau**2 * counts)
    return tau, avar, m, counts


def _second_difference_sq(x: np.ndarray, m: int, d: np.ndarray) -> float:
    """sum_i (x_{i+2m} - 2 x_{i+m} + x_i)^2 over the ``d.shape[0]`` differences, computed in ``d`` (in the order
    (x_{i+2m} - 2 x_{i+m}) + x_i, each step rounded as the plain expression rounds it, and summed by one dot
    product), DIFF_BLOCK differences at a time so that the three steps meet each block in the cache."""
    c = d.shape[0]
    for a in range(0, c, DIFF_BLOCK):
        b = min(a + DIFF_BLOCK, c)
        blk = d[a:b]
        np.multiply(x[m + a:m + b], 2.0, out=blk)
        np.subtract(x[2 * m + a:2 * m + b], blk, out=blk)
        np.add(blk, x[a:b], out=blk)
    return float(np.dot(d, d))


def segment_weights(lengths, m) -> np.ndarray:
    """(segments, len(m)) weights w_s(m) = c_s(m) / sum_s c_s(m), c_s = max(n_s + 1 - 2m, 0)."""
    n = np.asarray(lengths, dtype=np.int64)[:, None]
    c = np.maximum(n + 1 - 2 * np.asarray(m, dtype=np.int64)[None, :], 0).astype(float)
    tot = c.sum(axis=0)
    return c / np.where(tot > 0, tot, 1.0)


def pooled_oavar_covariance(terms, m, lengths, rate_hz: float, max_ratio: int = 256) -> np.ndarray:
    """Model covariance of the pooled estimates (see the module docstring)."""
    from companion.allan.confidence import oavar_covariance

    m = np.asarray(m, dtype=np.int64)
    w = segment_weights(lengths, m)
    cov = np.zeros((m.shape[0], m.shape[0]))
    # segments of equal length share their covariance
    for n_s in sorted(set(int(x) for x in lengths)):
        rows = [i for i, x in enumerate(lengths) if int(x) == n_s]
        ok = np.flatnonzero(n_s + 1 - 2 * m > 0)
        if ok.shape[0] == 0:
            continue
        c_s = oavar_covariance(terms, m[ok], n_s, rate_hz, max_ratio=max_ratio)
        ww = np.zeros((m.shape[0], m.shape[0]))
        for r in rows:
            ww[np.ix_(ok, ok)] += np.outer(w[r, ok], w[r, ok])
        cov[np.ix_(ok, ok)] += ww[np.ix_(ok, ok)] * c_s
    return cov


def pooled_edf(terms, m, lengths, rate_hz: float) -> np.ndarray:
    """EDF of each pooled point, 2 sigma^4 / Var, for noise made of ``terms``."""
    from companion.allan.terms import avar_model

    m = np.asarray(m, dtype=np.int64)
    var = np.array([pooled_oavar_covariance(terms, [mi], lengths, rate_hz)[0, 0] for mi in m])
    avar = avar_model(list(terms), m / rate_hz)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(var > 0, 2.0 * avar**2 / np.where(var > 0, var, 1.0), np.inf)
