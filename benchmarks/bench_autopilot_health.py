"""The autopilot's own IMU health on every real log: which fields each carries, what they say, no traceback.

Every log in ../shared/data and in the fetched public logs (default /work/reallogs, searched recursively) is
loaded as ``companion inspect`` loads it; its :class:`companion.health.autopilot_view.AutopilotView` is
tallied: logs per format, logs carrying each field (IMU.EG, VIBE.Clip0, vehicle_imu_status.gyro_error_count,
SYS_STATUS, ...), the IMUs the autopilot flags (with its reasons), the ERR events, and the logs whose health
records could not be read or that raised anything but the one-line CompanionError.

    python -m benchmarks.bench_autopilot_health [DIR ...]

Target: 0 tracebacks; the fields present are read on every log that carries them.
"""

from __future__ import annotations

import argparse
import collections
import sys
import traceback
from pathlib import Path

from benchmarks import results
from benchmarks.results import SHARED_DATA

EXTS = (".bin", ".ulg", ".tlog", ".tlog.gz", ".bin.gz", ".ulg.gz")


def logs(dirs: list[Path]) -> list[Path]:
    out = []
    for d in dirs:
        if d.is_dir():
            out += sorted(p for p in d.rglob("*") if p.is_file() and p.name.lower().endswith(EXTS))
    return out


def main() -> int:
    from companion.errors import CompanionError
    from companion.sources import load

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dirs", nargs="*", default=[str(SHARED_DATA), "/work/reallogs"])
    args = results.parse_args(ap, {})
    files = logs([Path(d) for d in args.dirs])
    by_format: collections.Counter = collections.Counter()
    with_fields: collections.Counter = collections.Counter()
    field_logs: collections.Counter = collections.Counter()
    errors, tracebacks, unread, flagged, events = [], [], [], [], collections.Counter()
    from_start = []  # IMUs whose error or clip counts were above 0 at the first record (shown, not flagged)
    for p in files:
        try:
            res = load(str(p), require_imu=False)
        except CompanionError as exc:
            errors.append(f"{p.name}: {str(exc)[:100]}")
            continue
        except Exception:  # noqa: BLE001 - counted: the target is none
            tracebacks.append(f"{p}: {traceback.format_exc().splitlines()[-1]}")
            continue
        view = res.meta.get("autopilot")
        fmt = res.meta.get("format", "tlog")
        by_format[fmt] += 1
        if view is None:
            continue
        if view.error:
            unread.append(f"{p.name}: {view.error}")
        fields = sorted({f for r in view.imus for f in r.fields} | set(view.fields))
        if view.imus:
            with_fields[fmt] += 1
        for f in fields:
            field_logs[f] += 1
        for r in view.imus:
            counts = [c for c in (r.gyro_errors, r.accel_errors, r.clip) if c is not None and c.first > 0]
            if counts:
                from_start.append(f"{p.parent.name}/{p.name} IMU{r.instance}: "
                                  + ", ".join(f"{c.field} {c.first:.0f}" for c in counts))
            if r.flagged():
                flagged.append(f"{p.parent.name}/{p.name} IMU{r.instance}: {'; '.join(r.reasons())}")
        for e in view.events:
            events[f"{e.subsystem} {e.code}"] += 1
    print(f"logs: {len(files)} ({', '.join(f'{k} {v}' for k, v in sorted(by_format.items()))}); "
          f"not loadable (one error line): {len(errors)}; tracebacks: {len(tracebacks)}")
    print("logs with per-IMU autopilot health: " + ", ".join(f"{k} {v}" for k, v in sorted(with_fields.items())))
    print("logs carrying each field:")
    for f, n in sorted(field_logs.items()):
        print(f"  {f:48s} {n}")
    print(f"IMUs the autopilot flags: {len(flagged)}")
    for line in flagged:
        print(f"  {line}")
    print(f"IMUs with counts above 0 at the log's start (counted before logging; shown, not flagged): {len(from_start)}")
    for line in from_start:
        print(f"  {line}")
    print("ERR events of IMU-related subsystems (subsystem code: count): "
          + (", ".join(f"{k}: {v}" for k, v in sorted(events.items())) or "none"))
    print(f"health records not read: {len(unread)}")
    for line in unread + tracebacks + errors:
        print(f"  {line}")
    return 1 if tracebacks else 0


if __name__ == "__main__":
    sys.exit(results.run(main))
