"""Soak: 24 simulated hours of `companion run`'s pipeline at accelerated speed -- is memory flat?

Feeds the real Pipeline message by message (``on_heartbeat`` / ``on_sample``, exactly what the live loop
and the tlog replay call) with one IMU at 100 Hz (white noise, 1 mrad/s rounding, a HEARTBEAT per second,
an armed and moving hour in the middle, a reboot at 18 h), reports going to a sink that counts them.
Every simulated hour it prints the process RSS (``/proc/self/status`` VmRSS), Python heap in use
(tracemalloc, with --heap), and the size of the saved state (JSON, written atomically).

    python benchmarks/bench_soak.py             # 24 h, about 5-10 min on one core
    python benchmarks/bench_soak.py --hours 2   # quick look
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from companion.mavlink.reporter import Reporter  # noqa: E402
from companion.samples import StreamKey  # noqa: E402
from companion.service.pipeline import Pipeline, PipelineConfig  # noqa: E402
from companion.service.state import save_state  # noqa: E402

RATE = 100.0
N = 3e-3


class CountSink:
    def __init__(self):
        self.nvf = 0
        self.texts = []

    def send_named_value_float(self, *a):
        self.nvf += 1

    def send_statustext(self, sev, text):
        self.texts.append(text)


def rss_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return -1


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--heap", action="store_true", help="also trace the Python heap (tracemalloc; slower)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    sink = CountSink()
    p = Pipeline(PipelineConfig(), Reporter(sink, 1.0))
    key = StreamKey(1, 1, "RAW_IMU", 0)
    state = Path(tempfile.mkdtemp()) / "state.json"
    hours = int(np.ceil(args.hours))
    arm_h, reboot_h = hours // 2, int(hours * 0.75)
    if args.heap:
        tracemalloc.start()
    t_wall = time.time()
    boot = 1.0
    print(f"{'hour':>4} {'RSS MiB':>8} {'heap MiB':>9} {'state KiB':>9} {'NVF sent':>9} {'wall s':>7}")
    rows = []
    for h in range(hours):
        armed = h == arm_h and hours > 2
        for part in range(6):  # 10-minute pieces keep the generator's own memory small
            n = int(600 * RATE)
            t = boot + np.arange(n) / RATE
            if h == reboot_h and part == 0 and hours > 2:
                t = t - t[0] + 0.5  # autopilot reboot: time since boot starts again
            boot = t[-1] + 1.0 / RATE
            g = np.round(rng.normal(0, N * np.sqrt(RATE), (n, 3)) / 1e-3) * 1e-3
            a = np.round((np.array([0, 0, -9.80665]) + rng.normal(0, 0.02, (n, 3))) / 9.80665e-3) * 9.80665e-3
            if armed:
                g += 0.5 * np.sin(2 * np.pi * 0.3 * t)[:, None]
                a += rng.normal(0, 2.0, a.shape)
            gl, al, tl = g.tolist(), a.tolist(), t.tolist()
            for k in range(n):
                if k % 100 == 0:
                    p.on_heartbeat(1, 2, 3, 128 if armed else 0)
                p.on_sample(key, tl[k], gl[k], al[k])
        save_state(state, p.state_dict())
        cur = tracemalloc.get_traced_memory()[0] if args.heap else float('nan')
        row = (h + 1, rss_kib() / 1024, cur / 2**20, state.stat().st_size / 1024, sink.nvf, time.time() - t_wall)
        rows.append(row)
        print(f"{row[0]:>4} {row[1]:>8.1f} {row[2]:>9.2f} {row[3]:>9.1f} {row[4]:>9} {row[5]:>7.0f}", flush=True)
    json.loads(state.read_text())
    c = p.channels[0].counts
    print(f"counts: {c}; transitions: {p.transitions}; STATUSTEXT: {sink.texts}")
    if len(rows) >= 4:
        r2, rn = rows[1], rows[-1]
        print(f"RSS hour 2 -> hour {rn[0]}: {r2[1]:.1f} -> {rn[1]:.1f} MiB ({rn[1] - r2[1]:+.1f}); "
              f"heap {r2[2]:.2f} -> {rn[2]:.2f} MiB; state {r2[3]:.1f} -> {rn[3]:.1f} KiB")


if __name__ == "__main__":
    main()
