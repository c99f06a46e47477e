"""One axis' blocks for the noise test's unit tests (health/noise.py), shared by tests/health/test_noise_quantized.py and
tests/health/test_noise_reference.py."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np


def one_axis_stats(y):
    """The BlockStats fields the noise test reads, for one axis (gx) of one block."""
    dd = y[2:] - 2.0 * y[1:-1] + y[:-2]
    dy = np.abs(np.diff(y))
    step = float(dy[dy > 0].min()) if np.any(dy > 0) else math.nan
    return SimpleNamespace(n=y.size, v2=np.array([np.mean(dd * dd) / 6.0]), m2=np.array([float(dd.size)]),
                           mean=np.array([y.mean()]), step=np.array([step]))


def learn_or_test(ref, det, obs) -> bool | None:
    """One block: to the reference ``ref`` and the detector's learned blocks until the noise test's level is
    ready (None), then to the detector: True when it went to FAULT on this block."""
    st = obs.stats
    if not ref.noise_ready:
        det.learn(obs)
        ref.add(float(st.v2[0]), float(st.m2[0]), float(st.mean[0]), 0, st.n, 30)
        return None
    return bool(det.update(obs)) and det.state == 1
