"""Soak: 24 simulated hours of `companion run`'s pipeline at accelerated speed -- is memory flat, and
within the 100 MB a small companion computer can spare?

Feeds the real Pipeline message by message (``on_heartbeat`` / ``on_sample``, exactly what the live loop
and the tlog replay call) with ``--imus`` IMUs at ``--rate`` Hz (default 3 at 400 Hz; white noise, 1 mrad/s
rounding, a HEARTBEAT per second, an armed and moving hour in the middle, a reboot at 18 h), reports
going to a sink that counts them. The process first imports what a live `companion run` holds (the CLI,
the link, pymavlink and its MAVLink 2 dialect), so its resident memory is that of the real process.
Every simulated hour it prints the process RSS (``/proc/self/status`` VmRSS) and its peak (VmHWM),
Python heap in use (tracemalloc, with --heap), and the size of the saved state (JSON, written atomically);
at the end the ratio of the final RSS to the 100 MB target.

    python -m benchmarks.bench_soak                          # 24 h, 3 IMUs at 400 Hz (about 50 min on a free core)
    python -m benchmarks.bench_soak --hours 2 --imus 1 --rate 100   # quick look

Target: resident memory flat over the hours and below 100 MB; no false alarm.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np


import companion.cli.run  # noqa: E402,F401  (what the live process imports)
import companion.mavlink.link  # noqa: E402,F401
from benchmarks import results
from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.state import save_state

N = 3e-3
TARGET_MIB = 100.0 * 1e6 / 2**20  # 100 MB


class CountSink:
    def __init__(self):
        self.nvf = 0
        self.texts = []

    def send_named_value_float(self, *a):
        self.nvf += 1

    def send_statustext(self, sev, text, time_boot_ms=None):
        self.texts.append(text)


def status_kib(field: str = "VmRSS") -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    return -1


def rss_kib() -> int:
    return status_kib("VmRSS")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--imus", type=int, default=3, help="number of IMUs (RAW_IMU, SCALED_IMU2, SCALED_IMU3)")
    ap.add_argument("--rate", type=float, default=400.0, help="IMU rate in Hz (default 400)")
    ap.add_argument("--heap", action="store_true", help="also trace the Python heap (tracemalloc; slower)")
    args = results.parse_args(ap, {"hours": 2.0, "imus": 1, "rate": 100.0})
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil  # noqa: F401  the live process holds pymavlink and its dialect
    from pymavlink.dialects.v20 import ardupilotmega  # noqa: F401

    rate = float(args.rate)
    rng = np.random.default_rng(0)
    sink = CountSink()
    p = Pipeline(PipelineConfig(), Reporter(sink, 1.0))
    messages = ("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")
    keys = [StreamKey(1, 1, messages[i % 3], i) for i in range(args.imus)]
    state = Path(tempfile.mkdtemp()) / "state.json"
    hours = int(np.ceil(args.hours))
    arm_h, reboot_h = hours // 2, int(hours * 0.75)
    if args.heap:
        tracemalloc.start()
    rss0 = rss_kib() / 1024
    t_wall = time.time()
    boot = 1.0
    print(f"{args.imus} IMU(s) at {rate:g} Hz for {hours} h; RSS after imports {rss0:.1f} MiB")
    print(f"{'hour':>4} {'RSS MiB':>8} {'peak MiB':>9} {'heap MiB':>9} {'state KiB':>9} {'NVF sent':>9} {'wall s':>7}")
    rows = []
    piece_s = 10.0  # 10-second pieces keep the generator's own memory small
    n = int(piece_s * rate)
    for h in range(hours):
        armed = h == arm_h and hours > 2
        for part in range(int(3600 / piece_s)):
            t = boot + np.arange(n) / rate
            if h == reboot_h and part == 0 and hours > 2:
                t = t - t[0] + 0.5  # autopilot reboot: time since boot starts again
            boot = t[-1] + 1.0 / rate
            tl = t.tolist()
            gyro, accel = [], []
            for _ in keys:
                g = np.round(rng.normal(0, N * np.sqrt(rate), (n, 3)) / 1e-3) * 1e-3
                a = np.round((np.array([0, 0, -9.80665]) + rng.normal(0, 0.02, (n, 3))) / 9.80665e-3) * 9.80665e-3
                if armed:
                    g += 0.5 * np.sin(2 * np.pi * 0.3 * t)[:, None]
                    a += rng.normal(0, 2.0, a.shape)
                gyro.append(g.tolist())
                accel.append(a.tolist())
            per_hb = int(rate)
            for k in range(n):
                if k % per_hb == 0:
                    p.on_heartbeat(1, 2, 3, 128 if armed else 0)
                for i, key in enumerate(keys):
                    p.on_sample(key, tl[k], gyro[i][k], accel[i][k])
        save_state(state, p.state_dict())
        cur = tracemalloc.get_traced_memory()[0] if args.heap else float("nan")
        row = (h + 1, rss_kib() / 1024, status_kib("VmHWM") / 1024, cur / 2**20, state.stat().st_size / 1024,
               sink.nvf, time.time() - t_wall)
        rows.append(row)
        print(f"{row[0]:>4} {row[1]:>8.1f} {row[2]:>9.1f} {row[3]:>9.2f} {row[4]:>9.1f} {row[5]:>9} {row[6]:>7.0f}",
              flush=True)
    json.loads(state.read_text())
    for imu, ch in sorted(p.channels.items()):
        print(f"IMU{imu} counts: {ch.counts}")
    print(f"transitions: {p.transitions}; STATUSTEXT: {sink.texts}")
    last = rows[-1]
    print(f"RSS after imports {rss0:.1f} MiB; hour 1 {rows[0][1]:.1f} MiB; hour {last[0]} {last[1]:.1f} MiB "
          f"(peak {last[2]:.1f} MiB); target 100 MB = {TARGET_MIB:.1f} MiB: ratio {last[2] / TARGET_MIB:.2f} "
          f"({'ok' if last[2] <= TARGET_MIB else 'MISSED'}); {args.imus * rate * 3600 * hours / last[6]:.0f} "
          f"samples/s ({3600 * hours / last[6]:.0f}x real time)")


if __name__ == "__main__":
    sys.exit(results.run(main))
