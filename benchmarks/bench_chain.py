"""The companion in a real chain: `companion sim-autopilot --refuse-interval` -> MAVProxy (PyPI) with its
default stream-rate behaviour (REQUEST_DATA_STREAM of all streams at 4 Hz, again every 15 s) -> `companion
run --gcs udpout:...` -> a pymavlink ground-station listener; MAVProxy killed once, half-way, for
``--outage`` wall seconds and started again. The vehicle model is a healthy gyro (white noise only).

Printed: the IMU rate drops (50 -> 4 Hz stretches in message time, gaps of the outage left out) and the
longest in wall seconds; STATUSTEXTs the GCS received that name a fault (false alarms); the "data stopped"
texts during the outage and "data back" after it; the wall seconds from "data back" to the first
IMU0G_HLTH != 3 and to the first IMU0G_HLTH = 0 (healthy) at the GCS; frames the companion counted as lost;
the companion's CPU (share of one core over the run) and peak memory (VmHWM).

    python -m benchmarks.bench_chain                       # 1800 simulated s at 8x (225 s), 20 s outage
    python -m benchmarks.bench_chain --duration 600        # shorter
    nice -n 10 python -m benchmarks.bench_chain --wall-seconds 1800   # the 30-minute soak in real time (1x)

Target: no fault STATUSTEXT at the GCS (0 false alarms); each IMU rate drop back within 10 s; IMU0G_HLTH 0 at the GCS within 2 s of "data back". Needs MAVProxy (`pip install MAVProxy`).
"""

from __future__ import annotations

import argparse
import re
import signal
import sys
import tempfile
import time
from pathlib import Path


from benchmarks import results
from tests.support.chain import FAULT_WORDS, imu_times, low_rate_episodes, start_chain
from tests.support.loopback import stop

CLK_TCK = 100.0  # Linux USER_HZ: the unit of utime/stime in /proc/PID/stat


def proc_usage(pid: int):
    """(CPU seconds, peak resident MiB) of a live process from /proc, or (None, None) off Linux."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None, None
    fields = stat.rsplit(")", 1)[1].split()
    cpu = (int(fields[11]) + int(fields[12])) / CLK_TCK  # utime, stime
    m = re.search(r"VmHWM:\s+(\d+) kB", status)
    return cpu, (int(m.group(1)) / 1024 if m else None)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=1800.0, help="simulated seconds")
    ap.add_argument("--speedup", type=float, default=8.0)
    ap.add_argument("--wall-seconds", type=float, metavar="S",
                    help="a real-time soak: S wall seconds at 1x (sets --duration S --speedup 1)")
    ap.add_argument("--outage", type=float, default=20.0, help="wall seconds without MAVProxy (0: none)")
    ap.add_argument("--baseline", type=float, default=120.0, help="run --baseline-s (simulated s)")
    ap.add_argument("--keep", metavar="DIR", help="keep the processes' outputs and run's tlog in DIR")
    args = results.parse_args(ap, {"duration": 300.0, "outage": 5.0})
    if args.wall_seconds:
        args.duration, args.speedup = args.wall_seconds, 1.0
    wall = args.duration / args.speedup
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(args.keep or d)
        tmp.mkdir(parents=True, exist_ok=True)
        chain = start_chain(tmp, ["--baseline-s", str(args.baseline), "--duration", str(wall + 200),
                                  "--out-tlog", str(tmp / "run.tlog")], default_streamrate=True)
        gcs, run = chain.gcs, chain.run
        t_kill = t_restart = None
        cpu = rss = None
        try:
            sim = chain.start_sim(["--speedup", str(args.speedup), "--duration", str(args.duration),
                                   "--wait-request", "--refuse-interval", "--wall-limit", str(wall + 150), "--quiet"])
            t0 = time.monotonic()
            cpu0, _ = proc_usage(run.pid)
            if args.outage > 0:
                gcs.wait_for(lambda g: time.monotonic() - t0 > wall / 2, wall)  # let half of it run
                stop(chain.proxy, signal.SIGKILL)
                t_kill = time.monotonic()
                gcs.wait_for(lambda g: time.monotonic() - t_kill > args.outage, args.outage + 5)
                chain.restart_proxy(default_streamrate=True)
                t_restart = time.monotonic()
            sim.wait(wall + 200)
            cpu1, rss = proc_usage(run.pid)
            t1 = time.monotonic()
            cpu = (cpu1 - cpu0) / (t1 - t0) if cpu1 is not None and cpu0 is not None else None
            stop(run)
        finally:
            chain.close()
        out = (tmp / "run.out").read_text()
        t = imu_times(tmp / "run.tlog")
        drops = low_rate_episodes(t, 50.0, min_s=1.0, gap_s=2.0)
        texts = list(gcs.texts)
        alarms = [x for _, x in texts if any(w in x.lower() for w in FAULT_WORDS)]
        learned = [ta - t0 for ta, x in texts if "baseline learned" in x]
        states = [v for _, v in gcs.health]
        print(f"chain: {args.duration:g} simulated s at {args.speedup:g}x ({wall:.0f} s wall), MAVProxy default "
              f"stream rates, {args.outage:g} s router outage")
        longest = max((x for _, x in drops), default=0.0)
        print(f"  IMU rate drops below 40 Hz: {len(drops)}; longest {longest:.1f} s message time = "
              f"{longest / args.speedup:.2f} s wall (target < 10 s)")
        print(f"  false alarms at the GCS: {len(alarms)} {alarms[:5]}")
        print(f"  baseline learned {learned[0]:.0f} s (wall) after the start" if learned else
              "  baseline never learned")
        print("  IMU0G_HLTH at the GCS: " + ", ".join(f"{int(h)}: {states.count(h)}" for h in sorted(set(states)))
              + " reports")
        lost = re.search(r"link from 1/1: (\d+) frames received, (\d+) lost \(([\d.]+) %\)", out)
        print(f"  frames the companion counted lost: {lost.group(2)} of {int(lost.group(1)) + int(lost.group(2))} "
              f"({lost.group(3)} %)" if lost else "  frames lost: no link line in run's output")
        if t_kill is not None:
            stopped = [ta for ta, x in texts if "data stopped" in x and t_kill < ta < t_restart + 5]
            back = [ta for ta, x in texts if "data back" in x and ta > t_restart]
            print(f"  GCS got 'data stopped' {len(stopped)} times during the outage, 'data back' {len(back)} times after it")
            if back:
                after = [(ta - back[0], v) for ta, v in gcs.health if ta >= back[0] - 0.5]
                not_stale = [dt for dt, v in after if v != 3.0]
                healthy = [dt for dt, v in after if v == 0.0]
                relapses = [dt for dt, v in after if healthy and dt > healthy[0] and v != 0.0]
                print(f"  HLTH at the GCS after 'data back': != 3 after {not_stale[0]:.2f} s, 0 (healthy) after "
                      f"{healthy[0]:.2f} s (target < 2 s); non-zero again later: {len(relapses)}"
                      if not_stale and healthy else f"  HLTH after 'data back': {after[:10]}")
        if cpu is not None:
            print(f"  companion run: {100 * cpu:.1f} % of one core over the run, peak memory {rss:.0f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
