"""In-flight noise per IMU on the real logs: how many are multi-IMU flight logs, how many of those get an
in-flight figure (N value or bound) on every gyro axis of every IMU, and that none ends in a traceback.

Logs: ../shared/data/ardupilot/*.bin, ../shared/data/px4/*.ulg and every file under ../reallogs (not in the
repository; missing directories are skipped); a file whose bytes repeat an earlier one is counted once. Each is
analysed as ``companion analyze LOG --axes gx,gy,gz`` (companion.analysis.source.analyze_source). A log of a
simulator (ArduPilot or PX4 SITL: SIM_* parameters) is listed but not counted among the real logs. Targets (issue
47): >= 90 % of the real multi-IMU flight logs get in-flight figures per IMU; no log with multi-IMU flight
data or ground condition (at least the 10 s a figure needs) refused; 0 tracebacks.

    python -m benchmarks.bench_inflight_real
"""

from __future__ import annotations

import argparse
import hashlib
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


def unique(files: list[Path]) -> tuple[list[Path], list[tuple[Path, Path]]]:
    """The files with distinct contents, and (duplicate, the file it repeats) for the others."""
    seen: dict = {}
    out, dup = [], []
    for f in files:
        h = hashlib.sha256(f.read_bytes()).hexdigest()
        if h in seen:
            dup.append((f, seen[h]))
        else:
            seen[h] = f
            out.append(f)
    return out, dup


def census(path: Path) -> tuple[int, float, float, bool]:
    """(IMUs of the vehicle's redundant family, seconds of flight, seconds of ground condition, whether the log
    comes from a simulator: SITL) of a log, from the log alone."""
    from companion.analysis.conditions import condition_intervals
    from companion.analysis.inflight import _monotonic, imu_family
    from companion.sources import load

    res = load(str(path))
    sitl = any(str(k).startswith("SIM_") for k in (res.meta.get("params") or {}))
    members = imu_family(res.imu_streams())
    if not members:
        return 0, 0.0, 0.0, sitl
    t, g = _monotonic(members[0])
    c = condition_intervals(t, g, res.meta.get("armed"), bool(res.meta.get("has_armed_state")))
    return (len(members), float(sum(b - a for a, b in c["flight"])), float(sum(b - a for a, b in c["ground"])),
            sitl)


def one(path: Path) -> dict:
    from companion.analysis.source import analyze_source
    from companion.errors import CompanionError

    try:
        imus, flight_s, ground_s, sitl = census(path)
    except CompanionError:
        imus, flight_s, ground_s, sitl = 0, 0.0, 0.0, False
    except Exception:  # the count this benchmark exists for
        return {"status": "traceback", "text": traceback.format_exc(limit=3)[-400:], "multi": False}
    multi = imus >= 2 and flight_s > 0
    base = {"multi": multi, "imus": imus, "flight_s": flight_s, "ground_s": ground_s, "sitl": sitl}
    try:
        entries, summary = analyze_source(str(path), ["gx", "gy", "gz"])
    except CompanionError as exc:
        return dict(base, status="error", text=str(exc)[-200:], figures=False, methods=[])
    except Exception:
        return {"status": "traceback", "text": traceback.format_exc(limit=3)[-400:], "multi": multi}
    fl = [e for e in entries if (e.get("flight") or {}).get("intervals_s")]
    return dict(base, status="ok", figures=multi and len(fl) >= max(imus, 2) and all(_figures(e) for e in fl),
                n=[_n_text(e) for e in fl], methods= sorted({(e.get("flight") or {}).get("method", "") for e in fl}),
                text="; ".join(sorted({n for e in fl for n in (e.get("flight") or {}).get("notes", [])}))[:200])


def _n_text(entry: dict) -> str:
    """One IMU's in-flight N per gyro axis in deg/sqrt(h) ("<" for a bound, "-" for none)."""
    from companion.units import to_datasheet

    out = []
    for ax in ("gx", "gy", "gz"):
        e = ((entry.get("flight") or {}).get("axes") or {}).get(ax) or {}
        t = next((x for x in list(e.get("terms", [])) + list(e.get("bounds", [])) if x["effect"] == "white_noise"),
                 None)
        out.append("-" if t is None else ("<" if t.get("bound") else "") + f"{to_datasheet('N', t['N']):.2g}")
    return "/".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    root = results.REPO.parent
    ap.add_argument("paths", nargs="*", default=[str(results.SHARED_DATA / "ardupilot"),
                                                  str(results.SHARED_DATA / "px4"), str(root / "reallogs")])
    args = ap.parse_args()
    files, dups = unique(logs(args.paths))
    for d, f in dups:
        print(f"{d.name}: the same bytes as {f.name}, counted once")
    t0 = time.time()
    rows = []
    for p in files:
        r = one(p)
        rows.append((p, r))
        _print(p, r)
    real = [r for _, r in rows if not r.get("sitl")]
    ok = [r for r in real if r["status"] == "ok"]
    multi = [r for r in real if r.get("multi")]
    tb = sum(r["status"] == "traceback" for _, r in rows)
    err = sum(r["status"] == "error" for r in real)
    fig = sum(bool(r.get("figures")) for r in multi)
    from companion.analysis.inflight import MIN_FIGURE_SECONDS

    refused = [p.name for p, r in rows if r["status"] == "error" and not r.get("sitl")
               and max(r["flight_s"] if r.get("multi") else 0.0, r.get("ground_s", 0.0)) >= MIN_FIGURE_SECONDS]
    sitl = [p.name for p, r in rows if r.get("sitl")]
    print(f"\n{len(files)} distinct logs in {time.time() - t0:.0f} s ({len(sitl)} from a simulator (SITL: SIM_* "
          f"parameters), not counted: {', '.join(sitl) or 'none'}); of {len(real)} real logs: {len(ok)} analysed, "
          f"{err} refused with one error line, {tb} tracebacks")
    print(f"refused although they hold {MIN_FIGURE_SECONDS:g} s of multi-IMU flight or of ground condition: "
          f"{len(refused)}"
          + (f" ({', '.join(refused)})" if refused else ""))
    print(f"real multi-IMU logs with flight data (2-3 IMUs of one family, armed and moving): {len(multi)}; in-flight "
          f"figures (N or bound) on every gyro axis of every IMU: {fig} of {len(multi)} "
          f"({fig / max(len(multi), 1):.0%}; target >= 90 %)")
    return 0 if tb == 0 else 1


def _print(p: Path, r: dict) -> None:
    if r["status"] == "traceback":
        print(f"TRACEBACK {p.name}: {r['text']}")
    elif r.get("multi"):
        print(f"{p.name}{' (SITL)' if r.get('sitl') else ''}: {r['imus']} IMUs, {r['flight_s']:.0f} s in flight, "
              f"figures per IMU: {'yes' if r['figures'] else 'NO'} ({'; '.join(r['methods'])})"
              + (f", N deg/sqrt(h) per IMU gx/gy/gz: {', '.join(r.get('n', []))}" if r["figures"] else
                 f": {r.get('text', '')}"), flush=True)
    elif r["status"] == "error" and r.get("ground_s", 0) > 0:
        print(f"{p.name}: refused with {r['ground_s']:.0f} s of ground condition: {r['text']}", flush=True)


if __name__ == "__main__":
    sys.exit(results.run(main))
