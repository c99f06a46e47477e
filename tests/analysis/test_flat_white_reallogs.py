"""The reported N against the flat white level of real logs, the level derived independently of the analysis:
allantools' overlapping ADEV of the samples the analysis used, Greenhall's EDF for white FM noise, the log's
own low-pass filter's roll-off from its impulse response (tests/analysis/test_flat_white_chain.py), and the
flat-region rule of the issue-49 target (a maximal run of cluster times with EDF >= 100 whose 95 % intervals
of ADEV*sqrt(tau) share a value, spanning >= 2x). Skipped without the shared data (COMPANION_SHARED)."""

import math
import os
from pathlib import Path

import numpy as np
import pytest

from tests.analysis.test_flat_white_chain import SENSOR_HZ, _truth

SHARED = Path(os.environ.get("COMPANION_SHARED", "/nonexistent"))
LOG171 = SHARED / "data" / "ardupilot" / "dronekit_log171.bin"


def _flat_runs(s, lo, hi, edf, tau):
    """(i, j) of every maximal run from each start, those inside another left out."""
    runs = []
    for i in range(len(tau)):
        if edf[i] < 100:
            continue
        bot, top, j = lo[i], hi[i], i
        while j + 1 < len(tau) and edf[j + 1] >= 100 and max(bot, lo[j + 1]) <= min(top, hi[j + 1]):
            bot, top, j = max(bot, lo[j + 1]), min(top, hi[j + 1]), j + 1
        if tau[j] >= 2 * tau[i] * (1 - 1e-9) and not any(a <= i and j <= b for a, b in runs):
            runs.append((i, j))
    return runs


def _level(y, rate, fc):
    """(tau, widest flat run (i, j), its level with the log's 2-pole roll-off divided out) of one axis."""
    import allantools

    n = y.size
    ms = 2 ** np.arange(0, int(math.log2(n / 8)))
    tau, dev, _, _ = allantools.oadev(y, rate=rate, data_type="freq", taus=ms / rate)
    edf = np.array([allantools.edf_greenhall(0, 2, int(m), n, overlapping=True) for m in ms[:tau.size]])
    lo, hi = zip(*(allantools.confidence_interval(d, e, ci=0.95) for d, e in zip(dev, edf)))
    s, lo, hi = dev * np.sqrt(tau), np.array(lo) * np.sqrt(tau), np.array(hi) * np.sqrt(tau)
    runs = _flat_runs(s, lo, hi, edf, tau)
    if not runs:
        return tau, None, None
    i, j = max(runs, key=lambda r: (round(math.log2(tau[r[1]] / tau[r[0]]), 6), tau[r[1]]))
    k = int(round(SENSOR_HZ / rate))  # the filter runs at the 1 kHz sensor rate, the newest value is logged
    _, shape = _truth(fc, k, "point", tuple(int(m) for m in ms[i:j + 1]))
    w = edf[i:j + 1]
    return tau, (i, j), math.sqrt(float(np.sum(w * s[i:j + 1] ** 2 / shape**2) / np.sum(w)))


@pytest.mark.skipif(not LOG171.exists(), reason="needs the shared real data (COMPANION_SHARED)")
def test_log171_N_at_its_independent_flat_level():
    """dronekit log171, three IMUs at 50 Hz, INS_GYRO_FILTER / INS_ACCEL_FILTER 20 Hz: on every axis with a flat
    white region (>= 12 of 18), N within 3 % of the region's level with the log's roll-off divided out and its
    95 % interval covering that level."""
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
            _, run, level = _level(y, s["rate_hz"], fc)
            if run is None:
                continue
            wn = next(t for t in e["terms"] if t["effect"] == "white_noise")
            seen.append((s["instance"], axis, wn["N"] / level - 1))
            assert abs(wn["N"] / level - 1) <= 0.03, seen[-1]
            assert wn["ci95"]["N"][0] <= level <= wn["ci95"]["N"][1], seen[-1]
    assert len(seen) >= 12, seen
