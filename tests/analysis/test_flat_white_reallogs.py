"""The reported N against the flat white level of real logs, the level derived independently of the analysis:
allantools' overlapping ADEV of the samples the analysis used, Greenhall's EDF for white FM noise, the log's
own low-pass filter's roll-off from its impulse response (tests/analysis/test_flat_white_chain.py), and the
flat-region rule of the issue-49 target (a maximal run of cluster times with EDF >= 100 on which
ADEV*sqrt(tau) is flat within its noise -- a constant not rejected at 99 % by chi^2 with the correlation of
neighbouring overlapping estimates -- spanning >= 2x). Skipped without the shared data (COMPANION_SHARED)."""

import math
import os
from pathlib import Path

import numpy as np
import pytest

from tests.analysis.test_flat_white_chain import SENSOR_HZ, _truth

SHARED = Path(os.environ.get("COMPANION_SHARED", "/nonexistent"))
LOG171 = SHARED / "data" / "ardupilot" / "dronekit_log171.bin"


#: correlation of overlapping AVAR estimates of white noise 0-4 octaves apart (the estimator's own covariance;
#: 400 simulated records of 2000 samples give 0.46-0.61 and 0.10-0.25 for one and two octaves)
RHO = (1.0, 0.53, 0.19, 0.07, 0.02, 0.0)


def _flat(s2, edf) -> bool:
    """ln(AVAR*tau) over consecutive octaves consistent with a constant at 99 % (each point's variance 2 / EDF,
    neighbours correlated as RHO): flat within its noise."""
    from scipy.stats import chi2

    x, sd = np.log(s2), np.sqrt(2.0 / np.asarray(edf))
    k = np.abs(np.subtract.outer(np.arange(x.size), np.arange(x.size)))
    vi = np.linalg.inv(np.asarray(RHO)[np.minimum(k, 5)] * np.outer(sd, sd))
    r = x - (vi.sum(axis=0) @ x) / vi.sum()
    return float(r @ vi @ r) <= chi2.ppf(0.99, x.size - 1)


def _flat_runs(s, edf, tau):
    """(i, j) of the longest flat run from each start spanning >= 2x, those inside another left out."""
    runs = []
    for i in range(len(tau)):
        if edf[i] < 100:
            continue
        j = i
        while j + 1 < len(tau) and edf[j + 1] >= 100 and _flat(s[i:j + 2] ** 2, edf[i:j + 2]):
            j += 1
        if tau[j] >= 2 * tau[i] * (1 - 1e-9) and not any(a <= i and j <= b for a, b in runs):
            runs.append((i, j))
    return runs


def _level(y, rate, fc):
    """(level of the widest flat run with the log's 2-pole roll-off divided out, its relative standard
    deviation) of one axis; (None, None) without a flat run."""
    import allantools

    n = y.size
    ms = 2 ** np.arange(0, int(math.log2(n / 8)))
    tau, dev, _, _ = allantools.oadev(y, rate=rate, data_type="freq", taus=ms / rate)
    edf = np.array([allantools.edf_greenhall(0, 2, int(m), n, overlapping=True) for m in ms[:tau.size]])
    s = dev * np.sqrt(tau)
    runs = _flat_runs(s, edf, tau)
    if not runs:
        return None, None
    i, j = max(runs, key=lambda r: (round(math.log2(tau[r[1]] / tau[r[0]]), 6), tau[r[1]]))
    k = int(round(SENSOR_HZ / rate))  # the filter runs at the 1 kHz sensor rate, the newest value is logged
    _, shape = _truth(fc, k, "point", tuple(int(m) for m in ms[i:j + 1]))
    w = edf[i:j + 1]
    # the level's relative standard deviation: that of its best-resolved point (neighbours are correlated)
    return math.sqrt(float(np.sum(w * s[i:j + 1] ** 2 / shape**2) / np.sum(w))), 1 / math.sqrt(2 * w.max())


@pytest.mark.skipif(not LOG171.exists(), reason="needs the shared real data (COMPANION_SHARED)")
def test_log171_N_at_its_independent_flat_level():
    """dronekit log171, three IMUs at 50 Hz, INS_GYRO_FILTER / INS_ACCEL_FILTER 20 Hz: on every axis with a flat
    white region (>= 12 of 18), N's 95 % interval covering the region's level with the log's roll-off divided
    out, N within 3 % of it on all but at most two axes and on every axis within 3 % or two of the level's own
    standard deviations (a region of 33 s at 50 Hz reads its level to 2-4 %: two valid flat runs of one curve
    can differ by 3 %)."""
    from companion.analysis.source import analyze_source
    from companion.samples import AXES, GYRO_AXES
    from companion.sources.dataflash import open_log
    from companion.sources.dataflash_imu import imu_raw_streams

    streams, _ = analyze_source(str(LOG171), list(AXES))
    raw = {r.key.instance: r for r in imu_raw_streams(open_log(str(LOG171)))[0]}
    seen = []
    for s in streams:
        r = raw[s["instance"]]
        (t0, t1), = s["ranges_s"]
        sel = (r.t >= t0 - 1e-6) & (r.t <= t1 + 1e-6)
        for axis, e in s["axes"].items():
            if e.get("status") != "ok":
                continue
            gyro = axis in GYRO_AXES
            y = (r.gyro if gyro else r.accel)[sel, "xyz".index(axis[1])]
            fc = s["filters_hz"]["gyro" if gyro else "accel"]
            level, sd = _level(y, s["rate_hz"], fc)
            if level is None:
                continue
            wn = next(t for t in e["terms"] if t["effect"] == "white_noise")
            seen.append((s["instance"], axis, wn["N"] / level - 1))
            assert abs(wn["N"] / level - 1) <= max(0.03, 2 * sd), (seen[-1], sd)
            assert wn["ci95"]["N"][0] <= level <= wn["ci95"]["N"][1], seen[-1]
    assert len(seen) >= 12, seen
    assert sum(abs(d) <= 0.03 for *_, d in seen) >= len(seen) - 2, seen
