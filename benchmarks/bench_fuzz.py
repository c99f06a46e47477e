"""Mutation fuzzing of the four file readers: tlog, DataFlash .bin, ULog .ulg, CSV.

Every input is a seeded mutation (tests/fuzz.py: byte flips, truncation, insertion, deletion, duplicated
chunks, header damage) of a real log from ../shared/data (its first 128 KiB, so that one load is fast and the
formats, definitions and parameters at the start are hit often) or of a small simulator-written log, loaded
with ``companion.sources.load``. Prints per reader: loaded / refused (one CompanionError line) / tracebacks
(any other exception, or text the reader printed on stdout) and the throughput. Target: 0 tracebacks over
>= 100,000 inputs per reader.

    nice -n 10 python benchmarks/bench_fuzz.py --count 100000 --workers 2 [--seconds 3600]

``--seconds`` stops handing out work after that long and reports the count reached.
"""

from __future__ import annotations

import argparse
import gzip
import multiprocessing as mp
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
SHARED = ROOT.parent / "shared" / "data"
CAP = 128 * 1024
CHUNK = 250  # mutations per task

REAL = {
    "tlog": ["tlogs/ardusub_2023-04-18.tlog"],
    "bin": ["ardupilot/methodic_backend_log_80k.bin", "ardupilot/dronekit_log171.bin"],
    "ulg": ["px4/pyulog_sample_appended_multiple.ulg", "px4/pyulog_sample_log_small.ulg"],
    "csv": ["adis16405/adis16405_imu1.csv.gz"],
}


def _simulated(ext: str, tmp: Path) -> bytes:
    from companion.mavlink.tlog_writer import write_imu_tlog
    from companion.sim.dataflash_writer import write_imu_log
    from companion.sim.ulog_writer import write_ulog

    rng = np.random.default_rng(0)
    n = 2000
    t = np.arange(n) / 200.0
    g, a = rng.normal(0, 0.01, (n, 3)), rng.normal(0, 0.05, (n, 3)) + [0, 0, -9.8]
    p = tmp / f"sim.{ext}"
    if ext == "tlog":
        write_imu_tlog(p, t, g, a)
    elif ext == "bin":
        write_imu_log(p, t, np.stack([g, g]), np.stack([a, a]), params={"INS_GYRO_FILTER": 20.0},
                      armed=[(1.0, True)], messages=["ArduCopter V4.5.0"])
    elif ext == "ulg":
        write_ulog(p, t, np.stack([g, g]), np.stack([a, a]), params={"IMU_GYRO_CUTOFF": 30.0}, armed=[(1.0, True)])
    else:
        rows = "\n".join(",".join(f"{v:.7g}" for v in (ti, *gi, *ai)) for ti, gi, ai in zip(t, g, a))
        p.write_text("time_s,gx,gy,gz,ax,ay,az\n" + rows + "\n")
    return p.read_bytes()


def bases(ext: str) -> list[bytes]:
    out = []
    for rel in REAL[ext]:
        p = SHARED / rel
        if p.is_file():
            data = gzip.decompress(p.read_bytes()) if rel.endswith(".gz") else p.read_bytes()
            data = data[:CAP]
            if ext == "csv":
                data = data[:data.rfind(b"\n") + 1]
            out.append(data)
    with tempfile.TemporaryDirectory() as d:
        out.append(_simulated(ext, Path(d)))
    return out


_BASES: dict = {}


def _task(args):
    import fuzz

    ext, seed, count = args
    if ext not in _BASES:
        _BASES[ext] = bases(ext)
    base = _BASES[ext][seed % len(_BASES[ext])]
    c = Counter()
    tracebacks = []
    t0 = time.process_time()
    with tempfile.TemporaryDirectory(dir="/dev/shm" if Path("/dev/shm").is_dir() else None) as d:
        for i, m in fuzz.seeds_of(base, count, seed):
            kind, detail = fuzz.check(f"f.{ext}", m, d)
            c[kind] += 1
            if kind == "traceback":
                tracebacks.append((seed, i, detail.strip().splitlines()[-1][:160]))
    return ext, c, tracebacks, time.process_time() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=100_000, help="mutated inputs per reader (default 100000)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=None, help="stop handing out work after this long")
    ap.add_argument("--readers", default="tlog,bin,ulg,csv")
    args = ap.parse_args(argv)
    readers = args.readers.split(",")
    for ext in readers:
        print(f"{ext}: {len(bases(ext))} base inputs ({', '.join(REAL[ext])} first {CAP // 1024} KiB where present, "
              "plus one simulator-written log)", flush=True)
    per = args.count // CHUNK
    tasks = [(ext, 1000 * k + j, CHUNK) for k in range(per) for j, ext in enumerate(readers)]
    done = {e: Counter() for e in readers}
    cpu = {e: 0.0 for e in readers}
    tbs = {e: [] for e in readers}
    t0 = time.time()
    with mp.Pool(args.workers) as pool:
        it = pool.imap_unordered(_task, tasks)
        pending = len(tasks)
        for ext, c, tb, cs in it:
            done[ext].update(c)
            cpu[ext] += cs
            tbs[ext] += tb
            pending -= 1
            if args.seconds and time.time() - t0 > args.seconds:
                pool.terminate()
                break
    wall = time.time() - t0
    print(f"\n{'reader':<6} {'inputs':>8} {'loaded':>8} {'refused':>8} {'tracebacks':>10} {'per CPU-s':>10}")
    for ext in readers:
        c = done[ext]
        n = sum(c.values())
        print(f"{ext:<6} {n:>8} {c['ok']:>8} {c['refused']:>8} {c['traceback']:>10} "
              f"{n / cpu[ext] if cpu[ext] else 0:>10.0f}")
    total = sum(sum(c.values()) for c in done.values())
    print(f"total {total} inputs in {wall:.0f} s wall ({total / wall:.0f} /s on {args.workers} workers)")
    for ext in readers:
        for seed, i, msg in tbs[ext][:5]:
            print(f"TRACEBACK {ext} seed {seed} input {i}: {msg}")
    return 1 if any(tbs[e] for e in readers) else 0


if __name__ == "__main__":
    sys.exit(main())
