"""Memory and time of ``companion run``'s final analysis (companion.service.still_record, final_analysis).

A run keeps the still samples it feeds its estimators (time and the analysed axes, float64) so that its summary
gives ``companion analyze``'s figure on them. This feeds 3 IMUs x 400 Hz x 1 h of still 1-s blocks (the rows a
channel queues: time, 6 axes, temperature) into three still records as the estimator banks do, and measures
the memory they hold (tracemalloc) and the process' peak RSS, then the final analysis of one IMU (3 gyro axes
of 1.44 M samples through companion.analysis.stream.pieces_entry): its time and its extra peak memory.

Target (the choice in still_record.py): the kept samples of the 3 x 400 Hz x 1 h run under 64 MiB per IMU
(MAX_KEPT_BYTES), so nothing of that run is dropped.

    python -m benchmarks.bench_still_record            # 3 IMUs x 400 Hz x 1 h
    python -m benchmarks.bench_still_record --quick    # 10 min
"""
from __future__ import annotations

import argparse
import resource
import time
import tracemalloc

import numpy as np

from benchmarks.results import run


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main(argv=None) -> None:
    from companion.analysis.stream import pieces_entry
    from companion.service.estimator_bank import COLUMNS
    from companion.service.still_record import MAX_KEPT_BYTES, StillRecord

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10 min instead of 1 h")
    args = ap.parse_args(argv)
    imus, rate, seconds = 3, 400.0, 600 if args.quick else 3600
    per_block = int(rate)
    rng = np.random.default_rng(49)
    rss0 = _peak_rss_mb()
    tracemalloc.start()
    records = [StillRecord({"t": 0, **{a: COLUMNS[a] for a in ("gx", "gy", "gz")}}) for _ in range(imus)]
    t0 = time.perf_counter()
    for k in range(seconds):
        t = (k * per_block + np.arange(per_block)) / rate
        for rec in records:
            rows = np.empty((per_block, 8))
            rows[:, 0] = t
            rows[:, 1:4] = rng.normal(0.0, 2e-3, (per_block, 3))
            rows[:, 4:7] = rng.normal(0.0, 2e-2, (per_block, 3))
            rows[:, 7] = 40.0
            rec.add(rows, per_block / rate, junction=False)
    feed_s = time.perf_counter() - t0
    held, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    kept = sum(r.nbytes for r in records)
    print(f"{imus} IMUs x {rate:g} Hz x {seconds} s still: {imus * per_block * seconds / 1e6:.2f} M samples per axis "
          f"set; kept {kept / 2**20:.1f} MiB in all ({kept / imus / 2**20:.1f} MiB per IMU, budget "
          f"{MAX_KEPT_BYTES / 2**20:.0f} MiB), dropped {sum(r.dropped_s for r in records):.0f} s")
    print(f"  held by the records (tracemalloc): {held / 2**20:.1f} MiB, peak {peak / 2**20:.1f} MiB; "
          f"feeding {feed_s:.1f} s; process peak RSS {_peak_rss_mb():.0f} MB (start {rss0:.0f} MB)")
    rec = records[0]
    tracemalloc.start()
    t0 = time.perf_counter()
    ns = {}
    for ax in ("gx", "gy", "gz"):
        e = pieces_entry(rec.axis_pieces(ax), rate, ax, "RAW_IMU", {}, "octave", None)
        ns[ax] = next((t["N"] for t in e["terms"] if t["effect"] == "white_noise"), None)
    fit_s = time.perf_counter() - t0
    _, fit_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print(f"  final analysis of one IMU (3 axes, {rec.kept_s:.0f} s): {fit_s:.1f} s, extra peak {fit_peak / 2**20:.0f} "
          f"MiB (tracemalloc); process peak RSS {_peak_rss_mb():.0f} MB")
    truth = 2e-3 / np.sqrt(rate)
    print("  N / truth: " + ", ".join(f"{a} {n / truth:.4f}" for a, n in ns.items() if n))


if __name__ == "__main__":
    run(main)
