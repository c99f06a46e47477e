"""Ingest speed and robustness: companion's tlog reader vs pymavlink, side by side, same files, same run.

    python -m benchmarks.bench_ingest              # 400,000 RAW_IMU messages + a 60,000 garbage-laced tlog
    python -m benchmarks.bench_ingest --n 100000   # quicker

1. A 400,000-message RAW_IMU tlog (400 Hz, gyro/accel noise, temperature, 1 Hz HEARTBEAT) written by
   companion.mavlink.tlog_writer in a temp dir. Timed: ``companion.sources.load`` (read, CRC-check,
   decode to SI, timing analysis) and pymavlink ``mavlogfile(...).recv_match(type='RAW_IMU')`` until
   the end. Values compared (time_usec and gyro of every message).
2. Robustness against a corrupted link: 60,000 RAW_IMU records with a 1-40 byte garbage run every 500 records,
   for a few garbage seeds. Counts of RAW_IMU messages each reader returns (pymavlink's loss depends on
   where a garbage byte happens to look like a frame start: from a few % to half of the file).

Target: values identical to pymavlink's; every message of the garbage-laced file recovered; the speed ratio is the figure.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


from benchmarks import results
from companion.mavlink.tlog_writer import write_imu_tlog
from companion.sources import load


def pymavlink_read(path, want=("time_usec", "xgyro", "ygyro", "zgyro")):
    from pymavlink import mavutil

    log = mavutil.mavlogfile(str(path))
    rows = []
    while True:
        m = log.recv_match(type="RAW_IMU")
        if m is None:
            break
        rows.append([getattr(m, f) for f in want])
    return np.array(rows, dtype=np.float64).reshape(-1, len(want))


def make(path, n, seed=0, heartbeat_hz=1.0):
    rng = np.random.default_rng(seed)
    t = 10.0 + np.arange(n) / 400.0
    gyro = rng.normal(0.0, 0.004, (n, 3))
    accel = rng.normal(0.0, 0.05, (n, 3)) + [0.0, 0.0, -9.80665]
    write_imu_tlog(path, t, gyro, accel, temperature=40.0 + rng.normal(0, 0.1, n), heartbeat_hz=heartbeat_hz)


def garbage_laced(src, dst, n, every=500, seed=1):
    """Insert a 1-40 byte random run after every ``every`` records (all records have the same length)."""
    data = Path(src).read_bytes()
    rec = len(data) // n
    rng = np.random.default_rng(seed)
    parts, junk = [], 0
    for i in range(0, n, every):
        parts.append(data[i * rec:(i + every) * rec])
        g = rng.integers(0, 256, int(rng.integers(1, 41)), dtype=np.uint8).tobytes()
        parts.append(g)
        junk += len(g)
    Path(dst).write_bytes(b"".join(parts))
    return junk


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=400_000, help="RAW_IMU messages in the speed file")
    ap.add_argument("--garbage-n", type=int, default=60_000, help="RAW_IMU records in the garbage-laced file")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="garbage seeds")
    args = results.parse_args(ap, {"n": 100_000, "garbage_n": 20_000, "seeds": [1]}, argv)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        big = tmp / "raw_imu.tlog"
        t0 = time.perf_counter()
        make(big, args.n)
        t_write = time.perf_counter() - t0
        print(f"wrote {args.n:,} RAW_IMU messages ({big.stat().st_size / 1e6:.1f} MB) in {t_write:.2f} s")

        best = best_cpu = float("inf")
        for _ in range(3):
            t0, c0 = time.perf_counter(), time.process_time()
            res = load(big)
            best = min(best, time.perf_counter() - t0)
            best_cpu = min(best_cpu, time.process_time() - c0)
        s = res.streams[0]
        t0, c0 = time.perf_counter(), time.process_time()
        ref = pymavlink_read(big)
        t_pm, c_pm = time.perf_counter() - t0, time.process_time() - c0
        same = (ref.shape[0] == s.samples and np.array_equal(ref[:, 0] * 1e-6, s.t)
                and np.array_equal(ref[:, 1:4] * 1e-3, s.gyro))
        ours, theirs = s.samples / best, ref.shape[0] / t_pm
        print(f"{'reader':<34}{'messages':>10}{'wall s':>9}{'msg/s':>12}{'cpu s':>8}{'msg/cpu-s':>12}")
        print(f"{'companion.sources.load (best of 3)':<34}{s.samples:>10,}{best:>9.3f}{ours:>12,.0f}"
              f"{best_cpu:>8.3f}{s.samples / best_cpu:>12,.0f}")
        print(f"{'pymavlink recv_match(RAW_IMU)':<34}{ref.shape[0]:>10,}{t_pm:>9.3f}{theirs:>12,.0f}"
              f"{c_pm:>8.3f}{ref.shape[0] / c_pm:>12,.0f}")
        print(f"speed ratio (wall): {ours / theirs:.1f}x  (cpu): {(s.samples / best_cpu) / (ref.shape[0] / c_pm):.1f}x"
              f"   values identical to pymavlink: {same}")

        clean = tmp / "clean.tlog"
        make(clean, args.garbage_n, seed=3, heartbeat_hz=0)
        bad = tmp / "garbage.tlog"
        print(f"\ngarbage-laced tlogs: {args.garbage_n:,} RAW_IMU records, a 1-40 byte garbage run every 500;"
              " RAW_IMU messages returned")
        print(f"{'garbage seed':<14}{'bytes':>7}{'companion':>11}{'bad frames':>12}{'pymavlink':>11}")
        for seed in args.seeds:
            junk = garbage_laced(clean, bad, args.garbage_n, seed=seed)
            res = load(bad)
            pm = pymavlink_read(bad).shape[0]
            print(f"{seed:<14}{junk:>7}{res.streams[0].samples:>11,}{res.totals['bad_frames']:>12}{pm:>11,}")
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
