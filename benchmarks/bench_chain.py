"""The companion in a real chain: `companion sim-autopilot --refuse-interval` -> MAVProxy (PyPI) with its
default stream-rate behaviour (REQUEST_DATA_STREAM of all streams at 4 Hz, again every 15 s) -> `companion
run --gcs udpout:...` -> a pymavlink ground-station listener; MAVProxy killed once for ``--outage`` wall
seconds and started again.

Printed: the IMU rate drops (50 -> 4 Hz stretches in message time, gaps of the outage left out) and the
longest in wall seconds; STATUSTEXTs the GCS received that name a fault (false alarms: the model is a
healthy gyro); the "data stopped" texts during the outage and "data back" after it; the wall seconds from
"data back" to the first IMU0G_HLTH != 3 at the GCS.

    python benchmarks/bench_chain.py                       # 1800 simulated s at 8x (225 s), 20 s outage
    python benchmarks/bench_chain.py --duration 600        # shorter
"""

from __future__ import annotations

import argparse
import signal
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from loopback import free_udp_port, start, stop  # noqa: E402
from readiness import READY, wait_for_text  # noqa: E402
from test_chain import FAULT_WORDS, MODEL, Listener, imu_times, start_mavproxy  # noqa: E402


def episodes(t, rate_hz, gap_s=2.0):
    """(start, length) of the stretches below 0.8 x ``rate_hz`` in message time; intervals over ``gap_s``
    (the outage) end a stretch and are not counted."""
    out, start, prev = [], None, None
    for a, b in zip(t, t[1:]):
        dt = b - a
        slow = 1.25 / rate_hz < dt <= gap_s
        if slow and start is None:
            start = a
        elif not slow and start is not None:
            out.append((start, a - start))
            start = None
        prev = b
    if start is not None:
        out.append((start, prev - start))
    return [e for e in out if e[1] >= 1.0]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=1800.0, help="simulated seconds")
    ap.add_argument("--speedup", type=float, default=8.0)
    ap.add_argument("--outage", type=float, default=20.0, help="wall seconds without MAVProxy")
    args = ap.parse_args()
    wall = args.duration / args.speedup
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        (tmp / "model.yaml").write_text(MODEL)
        p_master, p_run, p_gcs = free_udp_port(), free_udp_port(), free_udp_port()
        gcs = Listener(p_gcs)
        procs = []
        try:
            proxy = start_mavproxy(tmp, p_master, p_run, default_streamrate=True)
            procs.append(proxy)
            run = start(["run", "--source", f"udpin:127.0.0.1:{p_run}", "--gcs", f"udpout:127.0.0.1:{p_gcs}",
                         "--no-state", "--baseline-s", "120", "--duration", str(wall + 200), "--out-tlog",
                         str(tmp / "run.tlog")], tmp, "run.out")
            procs.append(run)
            wait_for_text(tmp / "run.out", READY, run)
            sim = start(["sim-autopilot", "--model", "model.yaml", "--connect", f"udpout:127.0.0.1:{p_master}",
                         "--speedup", str(args.speedup), "--duration", str(args.duration), "--wait-request",
                         "--refuse-interval", "--wall-limit", str(wall + 150), "--quiet"], tmp, "sim.out")
            procs.append(sim)
            t0 = time.monotonic()
            gcs.wait_for(lambda g: time.monotonic() - t0 > wall / 2, wall)  # let half of it run
            stop(proxy, signal.SIGKILL)
            t_kill = time.monotonic()
            gcs.wait_for(lambda g: time.monotonic() - t_kill > args.outage, args.outage + 5)
            procs.append(start_mavproxy(tmp, p_master, p_run, default_streamrate=True, name="mavproxy2.out"))
            t_restart = time.monotonic()
            sim.wait(wall + 200)
            stop(run)
        finally:
            for p in procs:
                stop(p, signal.SIGKILL)
            gcs.close()
        t = imu_times(tmp / "run.tlog")
        drops = episodes(t, 50.0)
        texts = [(ta, x) for ta, x in gcs.texts]
        alarms = [x for _, x in texts if any(w in x.lower() for w in FAULT_WORDS)]
        stopped = [ta for ta, x in texts if "data stopped" in x and t_kill < ta < t_restart + 5]
        back = [ta for ta, x in texts if "data back" in x and ta > t_restart]
        hl = [ta for ta, v in gcs.health if back and ta >= back[0] - 0.5 and v != 3.0]
        print(f"chain: {args.duration:g} simulated s at {args.speedup:g}x ({wall:.0f} s), MAVProxy default stream rates, "
              f"{args.outage:g} s router outage")
        print(f"  IMU rate drops below 40 Hz: {len(drops)}; longest {max((x for _, x in drops), default=0):.1f} s "
              f"message time = {max((x for _, x in drops), default=0) / args.speedup:.2f} s wall (target < 10 s)")
        print(f"  false alarms at the GCS: {len(alarms)} {alarms[:5]}")
        print(f"  GCS got 'data stopped' {len(stopped)} times during the outage, 'data back' {len(back)} times after it")
        print(f"  HLTH != 3 at the GCS {hl[0] - back[0]:.2f} s after 'data back'" if hl and back else "  HLTH: not seen")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
