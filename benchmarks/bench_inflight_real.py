"""In-flight noise per IMU on the real logs: how many are multi-IMU flight logs, how many of those get an
in-flight figure (N value or bound) on every gyro axis of every IMU, and that none ends in a traceback.

Logs: ../shared/data/ardupilot/*.bin, ../shared/data/px4/*.ulg and every file under ../reallogs (not in the
repository; missing directories are skipped). Each is analysed as ``companion analyze LOG --axes gx,gy,gz``
(companion.analysis.source.analyze_source). Target (issue 47): >= 90 % of the multi-IMU flight logs get
in-flight figures per IMU; 0 tracebacks.

    python -m benchmarks.bench_inflight_real
"""

from __future__ import annotations

import argparse
import sys
import time
import traceback
from pathlib import Path

from benchmarks import results

LOG_SUFFIXES = (".bin", ".ulg", ".tlog")


def logs(roots) -> list[Path]:
    from benchmarks.bench_reallogs import find_logs

    return find_logs(roots, LOG_SUFFIXES)


def _figures(entry: dict) -> bool:
    axes = (entry.get("flight") or {}).get("axes") or {}
    if len(axes) < 3:
        return False
    return all(any(t["effect"] == "white_noise" for t in list(e.get("terms", [])) + list(e.get("bounds", [])))
               for e in axes.values())


def census(path: Path) -> tuple[int, float]:
    """(IMUs of the vehicle's redundant family, seconds of flight condition) of a log, from the log alone."""
    from companion.analysis.conditions import condition_intervals
    from companion.analysis.inflight import _monotonic, imu_family
    from companion.sources import load

    res = load(str(path))
    members = imu_family(res.imu_streams())
    if not members:
        return 0, 0.0
    t, g = _monotonic(members[0])
    c = condition_intervals(t, g, res.meta.get("armed"), bool(res.meta.get("has_armed_state")))
    return len(members), float(sum(b - a for a, b in c["flight"]))


def one(path: Path) -> dict:
    from companion.analysis.source import analyze_source
    from companion.errors import CompanionError

    try:
        imus, flight_s = census(path)
    except CompanionError:
        imus, flight_s = 0, 0.0
    except Exception:  # the count this benchmark exists for
        return {"status": "traceback", "text": traceback.format_exc(limit=3)[-400:], "multi": False}
    multi = imus >= 2 and flight_s > 0
    try:
        entries, summary = analyze_source(str(path), ["gx", "gy", "gz"])
    except CompanionError as exc:
        return {"status": "error", "text": str(exc)[-200:], "multi": multi, "figures": False, "imus": imus,
                "flight_s": flight_s, "methods": []}
    except Exception:
        return {"status": "traceback", "text": traceback.format_exc(limit=3)[-400:], "multi": multi}
    fl = [e for e in entries if (e.get("flight") or {}).get("intervals_s")]
    return {"status": "ok", "multi": multi, "figures": multi and len(fl) >= 2 and all(_figures(e) for e in fl),
            "imus": imus, "flight_s": flight_s,
            "methods": sorted({(e.get("flight") or {}).get("method", "") for e in fl}),
            "text": "; ".join(sorted({n for e in fl for n in (e.get("flight") or {}).get("notes", [])}))[:200]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    root = results.REPO.parent
    ap.add_argument("paths", nargs="*", default=[str(results.SHARED_DATA / "ardupilot"),
                                                  str(results.SHARED_DATA / "px4"), str(root / "reallogs")])
    args = ap.parse_args()
    files = logs(args.paths)
    t0 = time.time()
    rows = []
    for p in files:
        r = one(p)
        rows.append((p, r))
        if r["status"] == "traceback":
            print(f"TRACEBACK {p.name}: {r['text']}")
        elif r.get("multi"):
            print(f"{p.name}: {r['imus']} IMUs, {r['flight_s']:.0f} s in flight, figures per IMU: "
                  f"{'yes' if r['figures'] else 'NO'} ({'; '.join(r['methods'])})"
                  + ("" if r["figures"] else f": {r.get('text', '')}"), flush=True)
    ok = [r for _, r in rows if r["status"] == "ok"]
    multi = [r for _, r in rows if r.get("multi")]
    tb = sum(r["status"] == "traceback" for _, r in rows)
    err = sum(r["status"] == "error" for _, r in rows)
    fig = sum(bool(r["figures"]) for r in multi)
    print(f"\n{len(files)} logs in {time.time() - t0:.0f} s: {len(ok)} analysed, {err} refused with one error line, "
          f"{tb} tracebacks")
    print(f"multi-IMU logs with flight data (2-3 IMUs of one family, armed and moving): {len(multi)}; in-flight figures (N or bound) on every gyro axis of "
          f"every IMU: {fig} of {len(multi)} ({fig / max(len(multi), 1):.0%}; target >= 90 %)")
    return 0 if tb == 0 else 1


if __name__ == "__main__":
    sys.exit(results.run(main))
