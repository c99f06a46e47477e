"""DataFlash .bin reading: companion's numpy reader vs pymavlink's DFReader, same files, same run.

    python -m benchmarks.bench_dataflash                 # the shared 3-IMU log + a written 4.x log (200 s, 3 IMUs, 400 Hz)
    python -m benchmarks.bench_dataflash --seconds 60    # smaller written log

Timed (best of --repeat runs, wall and CPU):
- DFReader: ``DFReader_binary(path)`` (its Cython indexer when installed) + ``recv_match(type=IMU*)`` to the
  end, collecting time, gyro and accel of every message (what an analysis needs);
- companion reader: ``dataflash.open_log`` + ``dataflash_imu.imu_raw_streams`` (the same arrays);
- companion ``sources.load``: the reader plus the timing analysis, batch-sampler streams and metadata
  (PARM, armed state, modes), i.e. all that ``companion analyze`` reads.
Memory: the reader's peak traced allocation (tracemalloc, numpy included) beside the size of the IMU arrays it
returns; the file itself is memory-mapped.
Values are compared element by element (time, gyro, accel of every IMU message) and must be identical.

Target: values identical to DFReader's, element by element; the speed ratio is the figure.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


from benchmarks import results
from benchmarks.results import SHARED_DATA
from companion.sim.dataflash_writer import write_imu_log
from companion.sources import dataflash as df
from companion.sources import load
from companion.sources.dataflash_imu import imu_raw_streams

SHARED = SHARED_DATA / "ardupilot" / "dronekit_log171.bin"
IMU_TYPES = ["IMU", "IMU2", "IMU3"]


def dfreader_arrays(path):
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(path))
    rows: dict = {}
    while True:
        m = r.recv_match(type=IMU_TYPES)
        if m is None:
            break
        name = m.get_type()
        cols = m.get_fieldnames()
        t = m.TimeUS * 1e-6 if "TimeUS" in cols else m.TimeMS * 1e-3
        inst = m.I if "I" in cols else IMU_TYPES.index(name)
        rows.setdefault(inst, []).append((t, m.GyrX, m.GyrY, m.GyrZ, m.AccX, m.AccY, m.AccZ))
    return {k: np.array(v) for k, v in rows.items()}


def ours_arrays(path):
    raws, _ = imu_raw_streams(df.open_log(path))
    return {r.key.instance: np.column_stack([r.t, r.gyro, r.accel]) for r in raws}


def peak_memory(path):
    """Peak traced allocation (numpy included) of reading the IMU arrays, and the size of those arrays."""
    import tracemalloc

    tracemalloc.start()
    out = ours_arrays(path)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak, sum(v.nbytes for v in out.values())


def timed(fn, repeat):
    best_w, best_c, out = float("inf"), float("inf"), None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best_w = min(best_w, time.perf_counter() - w0)
        best_c = min(best_c, time.process_time() - c0)
    return best_w, best_c, out


def bench(path, repeat):
    size = Path(path).stat().st_size
    w_ref, c_ref, ref = timed(lambda: dfreader_arrays(path), 1 if size > 5e6 else repeat)
    w_own, c_own, own = timed(lambda: ours_arrays(path), repeat)
    w_load, c_load, _ = timed(lambda: load(path), repeat)
    n = sum(v.shape[0] for v in ref.values())
    peak, arrays = peak_memory(path)
    same = sorted(ref) == sorted(own) and all(np.array_equal(ref[k], own[k]) for k in ref)
    print(f"{Path(path).name}: {size / 1e6:.1f} MB, {n} IMU messages in {len(ref)} instances; values identical: {same}")
    print(f"  DFReader            {w_ref * 1e3:9.1f} ms wall {c_ref * 1e3:9.1f} ms CPU")
    print(f"  companion reader    {w_own * 1e3:9.1f} ms wall {c_own * 1e3:9.1f} ms CPU   "
          f"{w_ref / w_own:6.1f}x wall {c_ref / c_own:6.1f}x CPU")
    print(f"  companion load()    {w_load * 1e3:9.1f} ms wall {c_load * 1e3:9.1f} ms CPU   "
          f"{w_ref / w_load:6.1f}x wall {c_ref / c_load:6.1f}x CPU")
    print(f"  companion reader peak memory {peak / 1e6:.1f} MB for {arrays / 1e6:.1f} MB of IMU arrays "
          f"(file memory-mapped, {size / 1e6:.1f} MB, not counted)")
    return same


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=200.0, help="length of the written 400 Hz 3-IMU log")
    ap.add_argument("--repeat", type=int, default=3)
    args = results.parse_args(ap, {"seconds": 60.0, "repeat": 2}, argv)
    ok = True
    if SHARED.exists():
        ok &= bench(SHARED, args.repeat)
    else:
        print(f"({SHARED} not present: shared log skipped)")
    with tempfile.TemporaryDirectory() as d:
        rng = np.random.default_rng(1)
        n = int(args.seconds * 400)
        t = 10.0 + np.arange(n) / 400.0
        p = Path(d) / "written_4x.bin"
        write_imu_log(p, t, rng.normal(0, 1e-3, (3, n, 3)), rng.normal(0, 1e-2, (3, n, 3)) + [0, 0, -9.8],
                      layout="4.x", params={"INS_GYRO_FILTER": 20}, armed=[(t[n // 3], True), (t[2 * n // 3], False)])
        ok &= bench(p, args.repeat)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(results.run(main))
