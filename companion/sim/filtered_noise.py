"""White rate noise seen through a 2-pole Butterworth low-pass, then point-sampled or averaged at the logged rate.

What an autopilot logs (ArduPilot: INS_GYRO_FILTER run at the sensor rate, the latest value logged at 10-400 Hz;
PX4 sensor_combined: IMU_GYRO_CUTOFF, then the delta angle over each publication interval / dt), synthesised
exactly -- no inner sampling rate: the continuous filter y'' + sqrt2 w y' + w^2 y = w^2 u (w = 2 pi f_c, u white
of two-sided PSD N_in^2) with the angle z' = y is a 3-state linear system, discretised exactly at the logged
period h (Van Loan 1978: Phi = e^(A h), Q = int_0^h e^(A s) B B^T e^(A^T s) ds N_in^2). Each sample is
the state's y (``point``) or (z_k - z_(k-1)) / h (``average``).

The white level of the logged samples (the plateau of ADEV sqrt(tau)) is N_in^2 for ``average`` and
N_in^2 sum_k |H(k fs)|^2 = N_in^2 (1 + 2 sum_{k>=1} 1 / (1 + (k fs / f_c)^4)) for ``point`` (aliasing):
:func:`logged_white_level`.
"""

from __future__ import annotations

import math

import numpy as np


def logged_white_level(N_in: float, rate_hz: float, filter_hz: float, sampling: str = "point") -> float:
    """White level N of the logged samples (long-tau N^2/tau) for input density ``N_in`` (two-sided)."""
    if sampling == "average":
        return float(N_in)
    k = np.arange(1, 200001, dtype=float)
    alias = 1.0 + 2.0 * float(np.sum(1.0 / (1.0 + (k * rate_hz / filter_hz) ** 4)))
    return float(N_in) * math.sqrt(alias)


def filtered_white_noise(n: int, N_in: float, rate_hz: float, filter_hz: float, sampling: str = "point",
                         rng=None) -> np.ndarray:
    """``n`` logged rate samples (see the module docstring); stationary from the first sample."""
    from scipy.linalg import expm
    from scipy.signal import lfilter, ss2tf

    rng = np.random.default_rng(rng)
    if sampling not in ("point", "average"):
        raise ValueError("sampling must be 'point' or 'average'")
    w = 2.0 * math.pi * filter_hz
    h = 1.0 / rate_hz
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -w * w, -math.sqrt(2.0) * w]])
    B = np.array([[0.0], [0.0], [w * w]])
    M = np.zeros((6, 6))
    M[:3, :3] = -A
    M[:3, 3:] = B @ B.T * N_in**2
    M[3:, 3:] = A.T
    E = expm(M * h)
    Phi = E[3:, 3:].T
    Q = Phi @ E[:3, 3:]
    Q = 0.5 * (Q + Q.T)
    wv, U = np.linalg.eigh(Q)
    L = U * np.sqrt(np.maximum(wv, 0.0))
    burn = int(math.ceil(20.0 * rate_hz / filter_hz)) + 2
    total = n + burn + 1
    c = np.array([[1.0, 0.0, 0.0]]) if sampling == "average" else np.array([[0.0, 1.0, 0.0]])
    out = np.zeros(total)
    for i in range(3):
        # the output driven by the i-th independent noise component: a rational filter of white noise
        b, a = ss2tf(Phi, L[:, i:i + 1], c, np.zeros((1, 1)))
        out += lfilter(np.atleast_1d(np.squeeze(b)), a, rng.standard_normal(total))
    if sampling == "average":
        out = np.diff(out) / h
    else:
        out = out[1:]
    return out[burn:burn + n]
