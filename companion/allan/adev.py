"""Overlapping Allan variance of rate (frequency) data, and the choice of cluster sizes.

Functions, one per statistic, in the style of allantools; confidence intervals live in
:mod:`companion.allan.confidence`.
"""

from __future__ import annotations

import numpy as np


def cluster_sizes(n: int, spec="octave") -> np.ndarray:
    """Cluster sizes m (in samples) for ``n`` rate samples.

    ``spec``: ``"octave"`` (m = 1, 2, 4, ...), ``"decade"`` (1, 2, 4 per decade: 1, 2, 4, 10, 20, 40, ...),
    ``"all"`` (every m), ``"log:K"`` (K log-spaced sizes per decade), or an explicit sequence of m.
    Only sizes with at least one overlapping difference are kept: 1 <= m <= (n - 1) // 2 + ...
    precisely, m <= n // 2 (the phase series has n + 1 points and needs 2 m + 1 of them).
    """
    m_max = n // 2
    if m_max < 1:
        return np.zeros(0, dtype=np.int64)
    if isinstance(spec, str):
        if spec == "octave":
            m = 2 ** np.arange(int(np.floor(np.log2(m_max))) + 1)
        elif spec == "decade":
            decades = int(np.floor(np.log10(m_max))) + 1
            m = np.array([f * 10**d for d in range(decades) for f in (1, 2, 4)])
        elif spec == "all":
            m = np.arange(1, m_max + 1)
        elif spec.startswith("log:"):
            try:
                per_decade = int(spec[4:])
            except ValueError:
                raise ValueError(f"bad tau spec {spec!r}: expected log:K with K an integer") from None
            if per_decade < 1:
                raise ValueError(f"bad tau spec {spec!r}: K must be >= 1")
            count = int(np.ceil(np.log10(m_max) * per_decade)) + 1
            m = np.unique(np.round(np.logspace(0, np.log10(m_max), max(count, 1))).astype(np.int64))
        else:
            raise ValueError(f"bad tau spec {spec!r}: expected octave, decade, all, log:K or a list")
    else:
        m = np.unique(np.asarray(spec, dtype=np.int64))
    m = np.asarray(m, dtype=np.int64)
    return m[(m >= 1) & (m <= m_max)]


def phase_from_rate(y: np.ndarray, rate_hz: float) -> np.ndarray:
    """Integrate rate samples to phase (angle): x_0 = 0, x_{k+1} = x_k + y_k tau0.

    The mean is removed first (AVAR ignores a constant) so that the cumulative sum of a biased
    signal keeps its precision over millions of samples.
    """
    y = np.asarray(y, dtype=float)
    x = np.empty(y.shape[0] + 1)
    x[0] = 0.0
    np.cumsum(y - y.mean(), out=x[1:])
    x *= 1.0 / rate_hz
    return x


def oavar(y, rate_hz: float, m=None, spec="octave"):
    """Overlapping Allan variance of rate data ``y`` sampled at ``rate_hz``.

    sigma^2(tau) = 1 / (2 tau^2 (N - 2m)) sum_{i=0}^{N-2m-1} (x_{i+2m} - 2 x_{i+m} + x_i)^2,
    tau = m tau0, with x the phase (integrated rate) of N = n + 1 points (IEEE Std 1139; NIST SP 1065
    eq. (11); Riley, *Handbook of Frequency Stability Analysis*).

    Returns ``(tau, avar, m, n_terms)`` where ``n_terms = N - 2m`` is the number of overlapping
    second differences behind each estimate.
    """
    y = np.asarray(y, dtype=float)
    if m is None:
        m = cluster_sizes(y.shape[0], spec)
    m = np.asarray(m, dtype=np.int64)
    x = phase_from_rate(y, rate_hz)
    n_phase = x.shape[0]
    avar = np.empty(m.shape[0])
    n_terms = n_phase - 2 * m
    # d = x[i+2m] - 2 x[i+m] + x[i] as the difference of the lag-m differences D = x[i+m] - x[i], in two
    # preallocated buffers; squares summed with numpy's pairwise sum (no BLAS call: faster on a busy
    # machine, and more accurate than a plain dot product)
    buf_d1 = np.empty(n_phase)
    buf_d2 = np.empty(n_phase)
    for j, mj in enumerate(m):
        k = n_phase - mj
        D = buf_d1[:k]
        np.subtract(x[mj:], x[:k], out=D)
        k2 = k - mj
        d = buf_d2[:k2]
        np.subtract(D[mj:], D[:k2], out=d)
        np.multiply(d, d, out=d)
        avar[j] = d.sum()
    tau = m / rate_hz
    avar = avar / (2.0 * tau**2 * n_terms)
    return tau, avar, m, n_terms


def oadev(y, rate_hz: float, m=None, spec="octave"):
    """Overlapping Allan deviation: ``(tau, adev, m, n_terms)``; see :func:`oavar`."""
    tau, avar, m, n_terms = oavar(y, rate_hz, m=m, spec=spec)
    return tau, np.sqrt(avar), m, n_terms


def avar_nonoverlapping(y, rate_hz: float, m=None, spec="octave"):
    """Classic non-overlapping Allan variance: 1/(2(K-1)) sum (ybar_{k+1} - ybar_k)^2 over K clusters of m."""
    y = np.asarray(y, dtype=float)
    if m is None:
        m = cluster_sizes(y.shape[0], spec)
    m = np.asarray(m, dtype=np.int64)
    m = m[y.shape[0] // np.maximum(m, 1) >= 2]
    avar = np.empty(m.shape[0])
    for j, mj in enumerate(m):
        k = y.shape[0] // mj
        ybar = y[: k * mj].reshape(k, mj).mean(axis=1)
        dy = np.diff(ybar)
        avar[j] = 0.5 * np.mean(dy * dy)
    return m / rate_hz, avar, m
