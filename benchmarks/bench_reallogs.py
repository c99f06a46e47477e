"""Real autopilot logs through `companion run` (the replay path) and `companion analyze`.

Every log found in ../shared/data (ArduPilot .bin, PX4 .ulg, tlogs) and in a directory of fetched public
logs (default /work/reallogs, searched recursively) is replayed exactly as a user would:

    companion run --source LOG --no-state --quiet      (the alarms are the summary's "at T s: ..." lines)
    companion analyze LOG --json OUT --quiet            (did it produce a report, or which error line)

Per log: IMUs, duration, every alarm (kind, IMU, axis, time) and an explanation. The explanations are
what was found in the data around each alarm (see EXPLAIN below, measured by hand, see docs/run.md);
an alarm without one is printed as "UNEXPLAINED". The logs are not part of the repository (public logs
without a licence allowing redistribution are used locally only).

    python -m benchmarks.bench_reallogs [DIR ...] [--json OUT] [--jobs 2] [--skip-analyze]

Prints one row per alarm and a summary: logs, log-hours, alarms by kind; with analyze, run's N against
analyze's on every gyro axis where both resolve it (each from its own still data: run's motion gate, analyze's
still selection), and the axes more than 10 % apart.

Target: every alarm explained (0 UNEXPLAINED; each false alarm is a finding); run's N within 10 % of analyze's on every axis both resolve. The quick run reads only the shared data.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from benchmarks import results
from benchmarks.results import SHARED_DATA

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
SHARED = SHARED_DATA
EXTS = (".bin", ".ulg", ".tlog", ".tlog.gz", ".bin.gz", ".ulg.gz")

#: log-name substring -> {kind or kind@IMUi: explanation}: what the data around each alarm showed
#: (1 s blocks of mean, std, distinct values, |accel| std, temperature and the other IMUs' means, read by
#: hand with the DataFlash reader). An explanation starting with TRUE is a real sensor event that must be
#: named; every other alarm is a false alarm.
DEAD = "TRUE: dead gyro, every sample of all three axes exactly 0 for the whole log"
CRASH = "TRUE: crash/impact, |rate| at the sensor's 2000 deg/s range (accel std > 10 m/s^2 at that second)"
EXPLAIN: dict[str, dict[str, str]] = {
    "mpu9250-ms5611_3.": {"stuck": DEAD, "dead": DEAD},
    "mpu9250-ms5611_5.": {"stuck": DEAD, "dead": DEAD},
    "mpu9250-ms5611_6.": {"stuck": DEAD, "dead": DEAD},
    "mpu9250-ms5611_7.": {"stuck": DEAD, "dead": DEAD},
    "dronekit_log171": {
        "saturated": CRASH + " (dronekit-la: crash at 239.8 s)",
        "disagrees": "handled at 25-28 s and take-off 83-87 s: 1 s means of the IMUs differ by 0.3-2 deg/s "
                     "while the rate std is 7-37 deg/s (each IMU sampled at its own time, filtered differently); "
                     "dronekit-la (5.7 deg/s for 0.5 s) finds nothing before the crash",
    },
    "7-9-2014_14": {"saturated": CRASH},
    # public PX4 logs (github.com/PX4/flight-review-rs and Auterion/px4-ulog-rs test fixtures)
    "fixtures_ekf_failure": {"saturated": "TRUE: crash/impact at 115 s: accel std 27-33 m/s^2 and 302 m/s^2 (30 g) "
                             "in that second, one Y sample of 49 rad/s beyond the sensor's 2000 deg/s range"},
    "6ba1abc7-b433-4029-b8f5-3b2bb12d3b6c": {"rate": "TRUE: PX4 SITL log whose sensor_combined stream has 1186 gaps "
                                             "in 26 s of data: the timestamps really are irregular (the simulator's lockstep)"},
    "sample_logging_tagged": {"disagrees": "PX4 SITL, three simulated gyros logged at 1 Hz for 11 s: single "
                              "samples taken at different instants while the vehicle moves"},
    "22-12-2014_37": {"disagrees": "in flight: 1 s means differ by 0.1-1 deg/s, one block of 8 deg/s in a "
                      "155 deg/s-std manoeuvre (IMUs sampled at different instants)"},
    "22-12-2014_41": {"disagrees": "in flight: a steady 0.6-1.1 deg/s Y difference between the IMUs (bias/scale "
                      "difference of two healthy MEMS parts) plus flight vibration",
                      "spikes": "flight vibration (heavy-tailed, rate std 20-80 deg/s in that second)"},
    "pxf_copter_": {"spikes": "flight or handling: heavy-tailed vibration/knocks (rate std 5-100 deg/s, "
                    "|accel| std 0.3-1.7 m/s^2 in those seconds), one IMU so no cross-check"},
    "pxf_plane_4-12-2014_329": {
        "stuck": "10 Hz, every sample distinct (10 of 10 per block): the noise fell (std 0.09 -> 0.02 deg/s) when "
                 "the engine/vibration stopped; a variance drop taken for a frozen gyro",
        "bias jump": "parked plane rocked about X (std 0.05-0.37 deg/s for 10 s): 1 s means move 0.1 deg/s",
        "noise": "same rocking about X on the ground (wind or engine), accel unchanged",
        "bias drift": "after the flight (landed at 518 s) the X/Y bias is 0.1-0.2 deg/s off the pre-flight one: "
                      "ordinary MEMS bias wander/temperature",
    },
    "pxf_plane_5-12-2014": {"stuck": "10 Hz, every sample distinct: noise fell when the vibration stopped "
                            "(std 0.09 -> 0.015 deg/s); a variance drop, not frozen values"},
    "mpu6000-ms5611_2": {"bias jump": "rover standing with motor/servo running (|accel| std 0.15 m/s^2, Z std "
                         "0.4 deg/s): 1 s means wander +-0.4 deg/s, far beyond white noise",
                         "bias drift": "same wander of the 1 s means (+-0.4 deg/s) on a standing, vibrating rover"},
    "mpu9250-ms5611_10": {"bias jump": "rover standing, 1 s means wander 0.1-0.25 deg/s (uncalibrated MPU9250)"},
    "mpu9250-ms5611_2.": {"bias jump": "rover standing, 1 s means wander 0.1-0.15 deg/s (uncalibrated MPU9250)"},
    "rover_25-8-2014_61": {
        "bias jump": "uncalibrated gyro (bias -24/-23/+3 deg/s), standing, bumped at 85 and 91-92 s: the 1 s means "
                     "wander 0.1-0.7 deg/s over tens of seconds (Y -23.0 -> -23.8 -> -23.0)",
        "bias drift": "same bias wander of 0.4 deg/s over a minute on an uncalibrated MPU",
        "noise": "one bump (326 s: X std 0.8 deg/s in one block, then back to 0.06): a knock, not a noise change",
    },
}

KINDS = (
    ("stuck", re.compile(r"\bstuck\b")),
    ("dead", re.compile(r"\bdead\b|\bconstant\b")),
    ("noise", re.compile(r"\bnoise\b")),
    ("bias jump", re.compile(r"bias jump")),
    ("bias drift", re.compile(r"bias drift")),
    ("spikes", re.compile(r"\bspikes\b")),
    ("saturated", re.compile(r"\bsaturated\b")),
    ("rate", re.compile(r"\brate\b|timing")),
    ("disagrees", re.compile(r"disagrees")),
    ("degrading", re.compile(r"degrading")),
)
ALARM = re.compile(r"^\s+at (-?\d+) s: (IMU(\d+) gyro(?: ([XYZ]))? (.*))$")
HEAD = re.compile(r"^IMU(\d+) \(([^,]+), ([\d.]+) Hz\).*?(\d+) samples")
#: a summary line of run's Allan terms: the final analysis ("  gx: N 0.229 [0.221, 0.237] deg/sqrt(h); ..." or
#: "  gx: N < 0.667 deg/sqrt(h)"), else the online one ("  gx online: N 0.229 +- 0.0064 deg/sqrt(h); ...")
N_LINE = re.compile(r"^  (g[xyz])( online)?: N (<\s*)?([\d.eE+-]+)")
RAD_TO_DEG_SQRT_H = 180.0 / 3.141592653589793 * 60.0
CLEARED = re.compile(r"cleared|recovered|healthy again|back to|\bOK\b")


def find_logs(dirs: list[Path], exts: tuple[str, ...] = EXTS) -> list[Path]:
    """The real logs under ``dirs`` (a file among them is taken as given), each once: by content, not by path
    (../shared/data is always searched, a folder named again or inside another would count its logs twice, and
    a public log fetched again under another name -- ../shared/data's pyulog_sample.ulg is pyulog's
    test/sample.ulg -- is the same flight). ``exts``: the name endings of a log (the other benchmarks' own)."""
    import hashlib

    out, seen = [], set()

    def take(p: Path) -> None:
        digest = hashlib.sha1(p.read_bytes()).hexdigest()
        if digest not in seen:
            seen.add(digest)
            out.append(p)

    for d in map(Path, dirs):
        if d.is_file():
            take(d)
            continue
        if not d.is_dir():
            continue
        for p in sorted(d.rglob("*")):
            name = p.name.lower()
            if "sim" in p.relative_to(d).parts[:-1]:
                continue  # simulated logs kept beside the real ones are not real data
            if p.is_file() and name.endswith(exts) and p.stat().st_size > 20_000:
                take(p)
    return out


def kind_of(text: str) -> str:
    for k, rx in KINDS:
        if rx.search(text):
            return k
    return "other"


def companion(*args: str, timeout: float = 900) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "companion", *args], capture_output=True, text=True,
                          env=env, timeout=timeout, cwd=str(REPO))


def run_log(path: Path, analyze: bool) -> dict:
    t0 = time.time()
    r = companion("run", "--source", str(path), "--no-state", "--quiet")
    row = {"log": str(path), "name": path.name, "run_rc": r.returncode, "imus": [], "alarms": [], "clears": 0,
           "duration_s": 0.0, "run_error": ""}
    if r.returncode != 0:
        row["run_error"] = (r.stderr.strip().splitlines() or ["?"])[-1]
    for line in r.stdout.splitlines():
        m = HEAD.match(line)
        if m:
            imu, msg, rate, n = int(m[1]), m[2], float(m[3]), int(m[4])
            row["imus"].append({"imu": imu, "message": msg, "rate_hz": rate, "samples": n, "N": {}})
            if rate > 0:
                row["duration_s"] = max(row["duration_s"], n / rate)
            continue
        m = N_LINE.match(line)
        if m and row["imus"]:
            row["imus"][-1]["N"].setdefault(m[1], (float(m[4]), bool(m[3])))  # the final analysis' first
            continue
        m = ALARM.match(line)
        if m:
            text = m[2]
            if CLEARED.search(m[5]):
                row["clears"] += 1
                continue
            row["alarms"].append({"t": int(m[1]), "imu": int(m[3]), "axis": m[4] or "", "kind": kind_of(m[5]),
                                  "text": text})
    row["run_wall_s"] = round(time.time() - t0, 1)
    if analyze:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "a.json"
            a = companion("analyze", str(path), "--json", str(out), "--quiet")
            row["analyze_rc"] = a.returncode
            row["analyze_n"] = analyze_n(out) if a.returncode == 0 and out.exists() else []
            lines = [ln for ln in (a.stderr + a.stdout).splitlines() if ln.strip()]
            row["analyze_note"] = ""
            for ln in lines:
                if "gyro dead" in ln or (a.returncode != 0 and "error" in ln.lower()):
                    row["analyze_note"] = ln.strip()[:160]
                    break
            if a.returncode != 0 and not row["analyze_note"]:
                row["analyze_note"] = (lines or ["?"])[-1][:160]
    for al in row["alarms"]:
        al["explanation"] = explain(path.name, al)
    return row


def analyze_n(path: Path) -> list[dict]:
    """Per analysed stream of an analyze JSON: message, instance and the gyro axes' N (deg/sqrt(h), bound?)."""
    out = []
    for st in json.loads(path.read_text()).get("streams", []):
        n = {}
        for ax in ("gx", "gy", "gz"):
            a = (st.get("axes") or {}).get(ax) or {}
            for t in list(a.get("terms") or []) + list(a.get("bounds") or []):
                if t.get("effect") == "white_noise" and "N" in t:
                    n[ax] = (float(t["N"]) * RAD_TO_DEG_SQRT_H, bool(t.get("bound")))
                    break
        out.append({"message": st.get("message"), "instance": st.get("instance"), "N": n})
    return out


def n_pairs(row: dict) -> list[tuple]:
    """(log, IMU, axis, analyze's N, run's N) where both resolve N: run's IMU k against analyze's stream of
    the same message and instance k (the message alone when it names one stream)."""
    out = []
    streams = row.get("analyze_n") or []
    for imu in row["imus"]:
        same = [s for s in streams if s["message"] == imu["message"]]
        match = [s for s in same if s["instance"] == imu["imu"]] or (same if len(same) == 1 else [])
        if not match:
            continue
        for ax, (vr, br) in imu["N"].items():
            va = match[0]["N"].get(ax)
            if va and not va[1] and not br and va[0] > 0:
                out.append((row["name"], imu["imu"], ax, va[0], vr))
    return out


def explain(name: str, alarm: dict) -> str:
    for key, d in EXPLAIN.items():
        if key in name:
            for k in (f"{alarm['kind']}@IMU{alarm['imu']}", alarm["kind"]):
                if k in d:
                    return d[k]
    return "UNEXPLAINED"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dirs", nargs="*", default=["/work/reallogs"], help="directories of fetched logs (recursive)")
    ap.add_argument("--json", metavar="OUT", help="write every row as JSON")
    ap.add_argument("--jobs", type=int, default=2, help="logs replayed in parallel (default 2)")
    ap.add_argument("--skip-analyze", action="store_true", help="only `companion run`")
    ap.add_argument("--match", help="only logs whose path contains this string")
    ap.add_argument("--from-json", metavar="IN", help="print the table of an earlier --json run (explanations redone)")
    args = results.parse_args(ap, {"dirs": []}, argv)
    if args.from_json:
        rows = json.loads(Path(args.from_json).read_text())["rows"]
        for row in rows:
            for al in row["alarms"]:
                al["explanation"] = explain(row["name"], al)
        return report(rows, args, 0.0)

    logs = find_logs([SHARED] + [Path(d) for d in args.dirs])
    if args.match:
        logs = [p for p in logs if args.match in str(p)]
    if not logs:
        print("no logs found", file=sys.stderr)
        return 1
    t0 = time.time()
    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as ex:
        rows = list(ex.map(lambda p: run_log(p, not args.skip_analyze), logs))
    return report(rows, args, t0)


def report(rows: list[dict], args, t0: float) -> int:
    analyzed = any("analyze_rc" in r for r in rows)

    print(f"{'log':44s} {'IMUs':>4s} {'dur s':>7s} {'alarms':>6s}  analyze")
    for row in rows:
        an = "" if not analyzed else ("ok" if row.get("analyze_rc") == 0 else "refused")
        if row.get("analyze_note"):
            an += f" ({row['analyze_note']})"
        err = f"  RUN FAILED: {row['run_error']}" if row["run_rc"] else ""
        print(f"{row['name'][-44:]:44s} {len(row['imus']):4d} {row['duration_s']:7.0f} {len(row['alarms']):6d}  {an}{err}")
        for al in row["alarms"]:
            print(f"    {al['t']:5d} s  {al['kind']:10s} IMU{al['imu']} {al['axis'] or '-'}  {al['text'][:60]:60s} "
                  f"<- {al['explanation']}")
    hours = sum(r["duration_s"] for r in rows) / 3600
    imu_hours = sum(r["duration_s"] * len(r["imus"]) for r in rows) / 3600
    by_kind: dict[str, int] = {}
    for r in rows:
        for al in r["alarms"]:
            by_kind[al["kind"]] = by_kind.get(al["kind"], 0) + 1
    n_al = sum(by_kind.values())
    unexplained = sum(1 for r in rows for al in r["alarms"] if al["explanation"] == "UNEXPLAINED")
    true = sum(1 for r in rows for al in r["alarms"] if al["explanation"].startswith("TRUE"))
    print(f"\n{len(rows)} logs, {hours:.2f} log-hours ({imu_hours:.2f} IMU-hours), {n_al} gyro alarms "
          f"({true} true, {n_al - true} false; {unexplained} unexplained): "
          + ", ".join(f"{k} {v}" for k, v in sorted(by_kind.items(), key=lambda kv: -kv[1]))
          + (f"; {time.time() - t0:.0f} s wall" if t0 else ""))
    pairs = [p for r in rows for p in n_pairs(r)]
    if pairs:
        ratios = sorted(p[4] / p[3] for p in pairs)
        w5 = sum(abs(x - 1.0) <= 0.05 for x in ratios)
        w10 = sum(abs(x - 1.0) <= 0.10 for x in ratios)
        print(f"run's N against analyze's (each from its own still data), {len(pairs)} axes on "
              f"{len(set(p[0] for p in pairs))} logs: {ratios[0]:.2f}-{ratios[-1]:.2f}x, median "
              f"{ratios[len(ratios) // 2]:.3f}, within 5 %: {w5}, within 10 %: {w10}; beyond 10 %:")
        for name, imu, ax, va, vr in pairs:
            if abs(vr / va - 1.0) > 0.10:
                print(f"    {name[-44:]:44s} IMU{imu} {ax}  analyze {va:.3f}  run {vr:.3f}  ({vr / va:.2f}x)")
    if args.json and not args.from_json:
        Path(args.json).write_text(json.dumps({"rows": rows, "hours": hours, "imu_hours": imu_hours,
                                               "by_kind": by_kind}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
