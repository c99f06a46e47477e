"""Mutation fuzzing of the four file readers: tlog, DataFlash .bin, ULog .ulg, CSV.

Every input is a seeded mutation (tests/support/fuzz.py: byte flips, truncation, insertion, deletion, duplicated
chunks, header damage, and damage aimed at the structure: record headers, message ids, length fields,
FMT records and ULog format definitions, CSV delimiters) of a SMALL seed log, loaded in this process with
``companion.sources.load`` (written to a tmpfs file first: the readers take paths). The seeds are made in
memory, never stored: short cuts of the real logs in ../shared/data that keep what the reader needs (the
DataFlash FMT records of the kept types, a few PARM/MSG/EV/MODE records and the first IMU/ISBH/ISBD ones; the
ULog header, format definitions of the IMU topics, a few parameters and the first data messages of those
topics; a 12 KiB window of the tlog; the CSV's first 200 rows) and one small simulator-written log per reader,
so that a load takes milliseconds and every input reaches the IMU decoding.

Per reader: inputs, loaded (damage skipped and counted), refused (one CompanionError line), invalid (loaded
with impossible numbers: non-finite or non-increasing times, infinite values), tracebacks (any other
exception, or text the reader printed on stdout), inputs per CPU-second and per wall-second; then every
distinct traceback/invalid class (exception type and the innermost companion frame) with its count and the
first input that shows it (``--replay`` writes that input to a file). Target: 0 tracebacks and 0 invalid
over >= 100,000 inputs per reader.

    nice -n 10 python -m benchmarks.bench_fuzz --count 100000 --workers 2 [--seconds 3600] [--readers bin,ulg]
    python -m benchmarks.bench_fuzz --replay bin:1:123:45 --out /tmp/x.bin   # base 1, seed 123, input 45
"""

from __future__ import annotations

import argparse
import gzip
import logging
import multiprocessing as mp
import struct
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from benchmarks import results
from benchmarks.results import SHARED_DATA

import numpy as np

SHARED = SHARED_DATA
CHUNK = 500  # mutations per task

REAL = {
    "tlog": ["tlogs/ardusub_2023-04-18.tlog"],
    "bin": ["ardupilot/methodic_backend_log_80k.bin", "ardupilot/dronekit_log171.bin"],
    "ulg": ["px4/pyulog_sample_log_small.ulg", "px4/pyulog_sample_appended_multiple.ulg"],
    "csv": ["adis16405/adis16405_imu1.csv.gz"],
}

# --------------------------------------------------------------------------------------------------
# small seeds

#: DataFlash types kept in a seed and how many of each (file order); every other type is dropped with its FMT
BIN_KEEP = {"IMU": 120, "IMU2": 60, "IMU3": 60, "ISBH": 3, "ISBD": 40, "PARM": 40, "MSG": 8, "EV": 8, "ARM": 4,
            "MODE": 4, "ERR": 4, "GPS": 4, "ATT": 4}


def bin_seed(data: bytes) -> bytes:
    from companion.sources.dataflash import FMT_TYPE, index

    log = index(np.frombuffer(data, dtype=np.uint8))
    keep_types = {t for t, f in log.formats.items() if f.name in BIN_KEEP}
    fmt_rec = log.records("FMT")
    fmt_pos = log.offsets[FMT_TYPE]
    picked = [int(p) for p, r in zip(fmt_pos, fmt_rec) if int(r["Type"]) in keep_types | {FMT_TYPE}]
    for t in keep_types:
        picked += log.offsets.get(t, np.zeros(0, np.int64))[:BIN_KEEP[log.formats[t].name]].tolist()
    out = bytearray()
    for p in sorted(picked):
        ln = 89 if data[p + 2] == FMT_TYPE else log.formats[data[p + 2]].length
        out += data[p:p + ln]
    return bytes(out)


ULOG_TOPICS = ("sensor_combined", "sensor_gyro", "sensor_accel", "sensor_gyro_fifo", "sensor_accel_fifo",
               "vehicle_imu", "vehicle_status")
ULOG_PARAMS = (b"IMU_GYRO_CUTOFF", b"IMU_INTEG_RATE", b"CAL_GYRO0_ID", b"CAL_GYRO1_ID")
_BASIC = {"int8_t", "uint8_t", "int16_t", "uint16_t", "int32_t", "uint32_t", "int64_t", "uint64_t", "float",
          "double", "bool", "char"}


def _ulog_messages(data: bytes):
    p = 16
    while p + 3 <= len(data):
        size, typ = struct.unpack_from("<HB", data, p)
        yield p, chr(typ), data[p + 3:p + 3 + size]
        p += 3 + size


def ulg_seed(data: bytes, per_topic: int = 120) -> bytes:
    """Header, flag bits (appended data cleared), a few infos and parameters, the format definitions the
    IMU topics need, their subscriptions and first ``per_topic`` data messages, a few log lines."""
    formats = {}
    for _, typ, body in _ulog_messages(data):
        if typ == "F":
            name, _, fields = body.decode("ascii", "replace").partition(":")
            formats[name] = (body, [f.split(" ")[0].split("[")[0] for f in fields.split(";") if f])
    need, todo = set(), [t for t in ULOG_TOPICS if t in formats]
    while todo:
        t = todo.pop()
        if t in need:
            continue
        need.add(t)
        todo += [ft for ft in formats[t][1] if ft not in _BASIC and ft in formats]
    out = bytearray(data[:16])
    ids, count = {}, Counter()
    for p, typ, body in _ulog_messages(data):
        rec = data[p:p + 3 + len(body)]
        if typ == "B":
            b = bytearray(rec)
            b[3 + 8] &= 0xFE  # no appended data (its offsets point into the full file)
            b[3 + 16:3 + 40] = bytes(24)
            out += b
        elif typ == "F" and body.decode("ascii", "replace").partition(":")[0] in need:
            out += rec
        elif typ in "IL" and count[typ] < 4:
            count[typ] += 1
            out += rec
        elif typ == "P" and (count["P"] < 12 or any(k in body for k in ULOG_PARAMS)):
            count["P"] += 1
            out += rec
        elif typ == "A" and body[3:].decode("ascii", "replace") in ULOG_TOPICS:
            ids[struct.unpack_from("<H", body, 1)[0]] = 0
            out += rec
        elif typ == "D" and len(body) >= 2:
            mid = struct.unpack_from("<H", body, 0)[0]
            if mid in ids and ids[mid] < per_topic:
                ids[mid] += 1
                out += rec
    return bytes(out)


def _simulated(ext: str, tmp: Path) -> bytes:
    from companion.mavlink.tlog_writer import write_imu_tlog
    from companion.sim.dataflash_writer import write_imu_log
    from companion.sim.ulog_writer import write_ulog

    rng = np.random.default_rng(0)
    n = 150
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


def _real_seed(ext: str, data: bytes) -> bytes:
    if ext == "bin":
        return bin_seed(data)
    if ext == "ulg":
        return ulg_seed(data)
    if ext == "tlog":
        mid = len(data) // 2
        return data[mid:mid + 12 * 1024]
    lines = data.split(b"\n", 201)
    return b"\n".join(lines[:201]) + b"\n"


def bases(ext: str) -> list[tuple[str, bytes]]:
    """(label, seed bytes) of one reader: the real cuts whose files are present, then the simulated log."""
    out = []
    for rel in REAL[ext]:
        p = SHARED / rel
        if p.is_file():
            raw = gzip.decompress(p.read_bytes()) if rel.endswith(".gz") else p.read_bytes()
            out.append((Path(rel).name, _real_seed(ext, raw)))
    with tempfile.TemporaryDirectory() as d:
        out.append(("simulated", _simulated(ext, Path(d))))
    return out


# --------------------------------------------------------------------------------------------------
# the run

_BASES: dict = {}


def _prepared(ext: str):
    from tests.support import fuzz

    if ext not in _BASES:
        _BASES[ext] = [(label, b, fuzz.hot_offsets(ext, b)) for label, b in bases(ext)]
    return _BASES[ext]


def input_of(ext: str, base: int, seed: int, i: int) -> bytes:
    """Input ``i`` of ``seed`` on base ``base`` (what a report line names), for a regression test."""
    from tests.support import fuzz

    _, data, hot = _prepared(ext)[base]
    for j, m in fuzz.seeds_of(data, i + 1, seed, hot):
        if j == i:
            return m
    raise ValueError(i)


def _task(args):
    from tests.support import fuzz

    logging.disable(logging.CRITICAL)  # the readers log what they skip; counted here instead
    ext, base, seed, count = args
    _, data, hot = _prepared(ext)[base]
    c = Counter()
    classes: dict = {}
    t0 = time.process_time()
    with tempfile.TemporaryDirectory(dir="/dev/shm" if Path("/dev/shm").is_dir() else None) as d:
        for i, m in fuzz.seeds_of(data, count, seed, hot):
            kind, detail = fuzz.check(f"f.{ext}", m, d)
            c[kind] += 1
            if kind in ("traceback", "invalid"):
                sig = detail.splitlines()[0][:200] if kind == "traceback" else "invalid: " + _shape(detail)
                n, first = classes.get(sig, (0, (base, seed, i)))
                classes[sig] = (n + 1, first)
    return ext, c, classes, time.process_time() - t0


def _shape(detail: str) -> str:
    """An invalid result's class: its text without numbers."""
    import re

    return re.sub(r"\d+", "#", detail)[:160]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--count", type=int, default=100_000, help="mutated inputs per reader (default 100000)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=None, help="stop handing out work after this long")
    ap.add_argument("--readers", default="tlog,bin,ulg,csv")
    ap.add_argument("--first-seed", type=int, default=0, help="seeds used: first-seed, first-seed+1, ...")
    ap.add_argument("--replay", metavar="EXT:BASE:SEED:INDEX", help="write that input to --out and stop")
    ap.add_argument("--out", help="where --replay writes")
    args = results.parse_args(ap, {"count": 2000}, argv)
    if args.replay:
        ext, base, seed, i = args.replay.split(":")
        Path(args.out).write_bytes(input_of(ext, int(base), int(seed), int(i)))
        return 0
    readers = args.readers.split(",")
    for ext in readers:
        bs = _prepared(ext)
        print(f"{ext}: seeds " + ", ".join(f"{k}: {label} ({len(b):,} bytes)" for k, (label, b, _) in enumerate(bs)),
              flush=True)
    per = -(-args.count // CHUNK)
    tasks = []
    for k in range(per):
        for ext in readers:
            seed = args.first_seed + k
            tasks.append((ext, seed % len(_BASES[ext]), seed, min(CHUNK, args.count - k * CHUNK)))
    done = {e: Counter() for e in readers}
    cpu = {e: 0.0 for e in readers}
    classes = {e: {} for e in readers}
    t0 = time.time()
    last = t0
    with mp.Pool(args.workers) as pool:
        for ext, c, cl, cs in pool.imap_unordered(_task, tasks):
            done[ext].update(c)
            cpu[ext] += cs
            for sig, (n, first) in cl.items():
                if sig not in classes[ext]:
                    print(f"new class: {ext}: {sig}  (first: --replay {ext}:{':'.join(map(str, first))})", flush=True)
                m, f0 = classes[ext].get(sig, (0, first))
                classes[ext][sig] = (m + n, min(f0, first))
            if time.time() - last > 60:
                last = time.time()
                print(f"[{last - t0:.0f} s] " + ", ".join(f"{e} {sum(done[e].values())}" for e in readers)
                      + f"; tracebacks/invalid classes: {sum(len(v) for v in classes.values())}", flush=True)
            if args.seconds and time.time() - t0 > args.seconds:
                pool.terminate()
                break
    wall = time.time() - t0
    print(f"\n{'reader':<6} {'inputs':>8} {'loaded':>8} {'refused':>8} {'invalid':>8} {'tracebacks':>10} "
          f"{'per CPU-s':>10}")
    for ext in readers:
        c = done[ext]
        n = sum(c.values())
        print(f"{ext:<6} {n:>8} {c['ok']:>8} {c['refused']:>8} {c['invalid']:>8} {c['traceback']:>10} "
              f"{n / cpu[ext] if cpu[ext] else 0:>10.0f}")
    total = sum(sum(c.values()) for c in done.values())
    print(f"total {total} inputs in {wall:.0f} s wall ({total / wall:.0f} /s on {args.workers} workers)")
    for ext in readers:
        for sig, (n, (base, seed, i)) in sorted(classes[ext].items(), key=lambda kv: -kv[1][0]):
            print(f"{ext}: {n} x {sig}  (first: --replay {ext}:{base}:{seed}:{i})")
    return 1 if any(classes[e] for e in readers) else 0


if __name__ == "__main__":
    sys.exit(results.run(main))
