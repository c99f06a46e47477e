"""Synthetic redundant-IMU flights with exact truth for the redundancy tests: a common body rate (slow
manoeuvres and vibration lines, analytic, so a time offset is exact), each IMU's own mounting matrix, time
offset and white noise of known N."""

from __future__ import annotations

import numpy as np

RATE = 200.0


def body_rate(t: np.ndarray, rng_seed: int = 7) -> np.ndarray:
    """(n, 3) rad/s: sums of sinusoids at 0.05-2 Hz (manoeuvres) and 23-61 Hz lines (vibration)."""
    r = np.random.default_rng(rng_seed)
    out = np.zeros((t.shape[0], 3))
    for j in range(3):
        for f, a in [(r.uniform(0.05, 0.3), 0.5), (r.uniform(0.3, 2.0), 0.3), (r.uniform(23, 31), 0.05),
                     (r.uniform(47, 61), 0.03)]:
            out[:, j] += a * np.sin(2 * np.pi * f * t + r.uniform(0, 2 * np.pi))
    return out


def flight(seed: int, n_true, seconds: float = 300.0, offsets=None, spread: float = 0.005):
    """(t, [gyro_i (n, 3)], mountings) of len(n_true) IMUs with white noise N_i (rad/s/sqrt(Hz))."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE)) / RATE
    offsets = [0.0] * len(n_true) if offsets is None else offsets
    gyros, mounts = [], []
    for i, n in enumerate(n_true):
        c = np.eye(3) + rng.uniform(-spread, spread, (3, 3))
        w = body_rate(t + offsets[i])
        gyros.append(w @ c.T + rng.normal(0, 0.01, 3) + rng.normal(0.0, n * np.sqrt(RATE), (t.shape[0], 3)))
        mounts.append(c)
    return t, gyros, mounts
