"""Vibration pick-up ratios between IMUs in flight (companion/health/pickup.py): how stable they are.

``--mode spread``: per real multi-IMU flight log and per simulated healthy flight, per pair and gyro axis,
L = 0.5 ln(P_i / P_j) of the band powers (1) over 5-s windows in flight: its median, its spread between
windows (sd of one window; sd of 30-s means) and, for logs of one vehicle, the spread of the flight medians.

    python -m benchmarks.bench_pickup --mode spread
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from benchmarks import results

WINDOW_S = 5.0
REAL = ["/work/shared/data/ardupilot/dronekit_log171.bin", "/work/reallogs/erle/pxf_brain_3.BIN",
        "/work/reallogs/erle/pxf_copter_22-12-2014_37.BIN", "/work/reallogs/erle/pxf_copter_22-12-2014_41.BIN",
        "/work/reallogs/erle/pxf_copter_31-3-2015_83.BIN",
        "/work/reallogs/flightreview/crates_converter_tests_fixtures_battery_brownout.ulg",
        "/work/reallogs/flightreview/crates_converter_tests_fixtures_ekf_failure.ulg",
        "/work/reallogs/flightreview/crates_converter_tests_fixtures_gps_interference.ulg",
        "/work/reallogs/robologs/robologs_test.ulg",
        "/work/reallogs/tlogs_extra/phoenix_mission1.tlog", "/work/reallogs/tlogs_extra/phoenix_mission2.tlog"] + [
        f"/work/reallogs/long47/{n}" for n in ("joeydouglas_2014-10-18_20-04-24.bin", "joeydouglas_2014-10-18_20-44-05.bin",
                                               "joeydouglas_2014-10-18_21-19-07.bin", "peterbarker_1.BIN",
                                               "peterbarker_3.BIN", "beastayyg_log_0036_mechanical_failure.bin")]


def window_ratios(tracks, intervals, window_s=WINDOW_S):
    """tracks [(t, g)] per IMU; {(i, j): (windows, 3) L} over the windows of ``intervals``."""
    from companion.health.pickup import band, band_power

    rates = [1.0 / float(np.median(np.diff(t))) for t, _ in tracks]
    bands = [band(r) for r in rates]
    if any(b is None for b in bands):
        return {}, rates
    lo, hi = max(b[0] for b in bands), min(b[1] for b in bands)
    rows = []
    for a, b in intervals:
        for w0 in np.arange(a, b - window_s + 1e-9, window_s):
            p = []
            for (t, g), r in zip(tracks, rates):
                k0, k1 = np.searchsorted(t, [w0, w0 + window_s])
                p.append(band_power(g[k0:k1], r, lo, hi))
            rows.append(p)
    if not rows:
        return {}, rates
    P = np.array(rows)  # (windows, imus, 3)
    n = P.shape[1]
    return {(i, j): 0.5 * np.log(P[:, i] / P[:, j]) for i in range(n) for j in range(i + 1, n)}, rates


def summarize(name, L, rates):
    meds = {}
    for (i, j), v in L.items():
        ok = np.all(np.isfinite(v), axis=1)
        v = v[ok]
        if v.shape[0] < 2:
            continue
        med = np.median(v, axis=0)
        sdw = np.std(v, axis=0, ddof=1)
        k = v.shape[0] // 6
        sd30 = np.std(v[:6 * k].reshape(k, 6, 3).mean(axis=1), axis=0, ddof=1) if k >= 2 else np.full(3, np.nan)
        meds[(i, j)] = med
        print(f"  {name} IMU{i}/IMU{j} ({v.shape[0]} windows, {rates[i]:.0f}/{rates[j]:.0f} Hz): L median "
              + " ".join(f"{x:+.3f}" for x in med) + "; sd 5 s " + " ".join(f"{x:.3f}" for x in sdw)
              + "; sd 30 s " + " ".join(f"{x:.3f}" for x in sd30), flush=True)
    return meds


def real(paths):
    from companion.analysis.conditions import condition_intervals
    from companion.analysis.inflight import _monotonic, imu_family
    from companion.sources import load

    out = {}
    for f in paths:
        if not Path(f).exists():
            continue
        res = load(f)
        members = imu_family(res.imu_streams())
        if len(members) < 2:
            print(f"  {Path(f).name}: one IMU")
            continue
        tracks = [_monotonic(m) for m in members]
        c = condition_intervals(*tracks[0], res.meta.get("armed"), bool(res.meta.get("has_armed_state")))
        L, rates = window_ratios(tracks, c["flight"])
        if not L:
            print(f"  {Path(f).name}: no band (rates {[round(r) for r in rates]} Hz) or no flight window")
            continue
        out[Path(f).name] = summarize(Path(f).name, L, rates)
    return out


def sim(spec, seed, flights=2, flight_s=900.0):
    from benchmarks.bench_inflight_live import parse_kind, simulator

    kind, imus, rate = parse_kind(spec)
    s, _ = simulator(kind, seed, flight_s, imus=imus, rate_hz=rate, flights=flights)
    blk = s.run(flights * (flight_s + 60.0))
    tracks = [(blk.t, blk.gyro[i]) for i in range(imus)]
    t0 = [30.0 + k * (flight_s + 60.0) for k in range(flights)]
    meds = []
    for k, a in enumerate(t0):
        L, rates = window_ratios(tracks, [(a + 30.0, a + flight_s - 30.0)])
        if not L:
            print(f"  {spec} seed {seed}: no band at {rates[0]:.0f} Hz")
            return []
        meds.append(summarize(f"{spec} seed {seed} flight {k}", L, rates))
    return meds


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mode", choices=("spread",), default="spread")
    ap.add_argument("--logs", nargs="*", default=REAL)
    ap.add_argument("--sim", nargs="*", default=["copter:3", "copter:3:400", "px4:3", "copter:2"])
    ap.add_argument("--seeds", type=int, default=2)
    args = ap.parse_args()
    print("real multi-IMU flight logs: L = 0.5 ln(P_i/P_j) per gyro axis x y z")
    real(args.logs)
    print("simulated healthy flights (2 flights of one vehicle each)")
    for spec in args.sim:
        for s in range(args.seeds):
            m = sim(spec, 900 + s)
            if len(m) == 2:
                d = [np.abs(m[0][k] - m[1][k]) for k in m[0]]
                print(f"  {spec} seed {900 + s}: |flight medians difference| max {np.max(d):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main, name="bench_pickup"))
