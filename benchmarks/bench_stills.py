"""How much of a real log's still, disarmed time `analyze` uses, against an independent reference.

    python -m benchmarks.bench_stills [DIR ...]          # ../shared/data and /work/reallogs
    python -m benchmarks.bench_stills --quick            # ../shared/data only
    python -m benchmarks.bench_stills --verbose          # one row per log

Per log: the reference still time (benchmarks/stills_reference.py: 1 s blocks -- 8 samples at least --, every IMU
stream's gyro and accelerometer spread within 4x its quietest fifth of blocks, no gyro mean 3 deg/s off, disarmed,
runs of 10 s or more) and what `analyze` selects with its defaults (the same call as
companion.analysis.source.analyze_source: select_still over every IMU stream, then each stream's index ranges).
"Used" is, per IMU instance, the time its streams' analysed ranges cover inside the reference still time; the
log's figure is the best instance's (an instance whose gyro alone changed is set aside by design: the time each
instance lost that way is printed). "Moving taken" is the
time analysed inside the reference's moving blocks (a spread above 10x the quiet level, 0.05 rad/s or 0.5 m/s^2,
a 3 deg/s turn, or armed).

Targets: >= 80 % of the reference still time used on quiet logs (those with a reference still run of 10 s or more),
0 s of moving time analysed; a log with a reference still run is never refused.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import time
from pathlib import Path

from benchmarks import results
from benchmarks.stills_reference import intersect, length, reference, union

EXTS = (".bin", ".ulg", ".tlog", ".csv", ".gz")
REALLOGS = Path("/work/reallogs")
TARGET_USED = 0.80


def logs_in(dirs) -> list[Path]:
    from benchmarks.bench_reallogs import find_logs

    return find_logs(dirs, EXTS)


def used_intervals(sel, streams) -> dict[int, list[tuple[float, float]]]:
    """Per IMU instance, the time intervals its streams' analysed ranges cover (as analyze_source uses them)."""
    out: dict[int, list] = {}
    for s in streams:
        dt = 1.0 / s.rate_hz if s.rate_hz > 0 else 0.0
        iv = [(float(s.t[a]), float(s.t[b - 1]) + dt) for a, b in sel.ranges(s)]
        out.setdefault(s.key.instance, []).extend(iv)
    return {k: union(v) for k, v in out.items()}


def measure(path: Path) -> dict:
    from companion.errors import CompanionError
    from companion.sources import load
    from companion.sources.still import select_still

    try:
        res = load(str(path))
    except CompanionError as exc:
        return {"log": path.name, "error": str(exc)[:80]}
    streams = [s for s in res.imu_streams() if s.samples >= 2]
    if not streams:
        return {"log": path.name, "error": "no IMU samples"}
    ref = reference(streams, res.meta)
    sel = select_still(res.imu_streams(), res.meta)
    used = used_intervals(sel, res.imu_streams())
    per_inst = {k: length(intersect(v, ref.still)) for k, v in used.items()}
    taken = max((length(intersect(v, ref.moving)) for v in used.values()), default=0.0)
    status = "ok"
    if not sel.intervals:
        status = "refused: " + (sel.notes[0] if sel.notes else "no still data")
    elif not any(used.values()):
        status = "refused: no IMU stream analysed"
    rate = max(s.rate_hz for s in streams)
    dur = max(float(s.t[-1] - s.t[0]) for s in streams)
    return {"log": path.name, "dur": dur, "rate": rate, "imus": len({s.key.instance for s in streams}),
            "ref": ref.still_s, "longest": ref.longest_s, "used": max(per_inst.values(), default=0.0),
            "selected": sel.still_s, "taken": taken, "status": status, "block": ref.block_s,
            "excluded": {k: sel.excluded_s(k) for k in sel.excluded}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dirs", nargs="*", help="log files or directories (default: the shared data and /work/reallogs)")
    ap.add_argument("--shared-only", action="store_true", help="only ../shared/data")
    ap.add_argument("--verbose", action="store_true", help="one row per log")
    args = results.parse_args(ap, {"shared_only": True, "verbose": True})
    dirs = args.dirs or ([results.SHARED_DATA] + ([] if args.shared_only else [REALLOGS]))
    paths = logs_in(dirs)
    t_start = time.perf_counter()
    rows = [measure(p) for p in paths]
    quiet = [r for r in rows if "error" not in r and r["longest"] >= 10.0]
    if args.verbose:
        print(f"{'log':48s} {'dur s':>7s} {'Hz':>6s} IMUs {'ref s':>7s} {'used s':>7s} {'used':>5s} "
              f"{'moving taken s':>14s}  status")
        for r in rows:
            if "error" in r:
                print(f"{r['log'][:48]:48s} not loaded: {r['error']}")
                continue
            frac = f"{r['used'] / r['ref']:.0%}" if r["ref"] > 0 else "-"
            print(f"{r['log'][:48]:48s} {r['dur']:7.0f} {r['rate']:6.1f} {r['imus']:4d} {r['ref']:7.0f} "
                  f"{r['used']:7.0f} {frac:>5s} {r['taken']:14.1f}  {r['status']}")
    below = [r for r in quiet if r["used"] < TARGET_USED * r["ref"]]
    refused = [r for r in quiet if r["status"] != "ok"]
    ref_s, used_s = sum(r["ref"] for r in quiet), sum(r["used"] for r in quiet)
    taken = [r for r in rows if "error" not in r and r["taken"] > 0]
    print(f"{len(rows)} logs ({sum('error' in r for r in rows)} not loaded), {len(quiet)} quiet (a reference still "
          f"run >= 10 s) in {time.perf_counter() - t_start:.0f} s")
    print(f"quiet logs: reference still {ref_s:.0f} s, used by analyze {used_s:.0f} s "
          f"({used_s / ref_s if ref_s else 0:.1%}); logs below {TARGET_USED:.0%} used: {len(below)} of {len(quiet)}"
          + (f" ({', '.join(r['log'] for r in below[:8])}{', ...' if len(below) > 8 else ''})" if below else ""))
    fr = [min(1.0, r["used"] / r["ref"]) for r in quiet if r["ref"] > 0]
    logs = [r for r in quiet if r["dur"] < 3600.0]  # without the hours-long bench recordings, which dominate the sum
    ref_l, used_l = sum(r["ref"] for r in logs), sum(r["used"] for r in logs)
    mean, median = (np.mean(fr), np.median(fr)) if fr else (0.0, 0.0)
    print(f"per quiet log: mean {mean:.1%}, median {median:.1%} of its reference still time used; logs under an "
          f"hour ({len(logs)}): {used_l:.0f} of {ref_l:.0f} s ({used_l / ref_l if ref_l else 0:.1%})")
    print(f"quiet logs refused: {len(refused)}" + (f" ({', '.join(r['log'] for r in refused)})" if refused else ""))
    print(f"moving time analysed: {sum(r['taken'] for r in taken):.1f} s in {len(taken)} logs"
          + (" (" + ", ".join(f"{r['log']} {r['taken']:.1f} s" for r in taken[:8]) + ")" if taken else ""))
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
