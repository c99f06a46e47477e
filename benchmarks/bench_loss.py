"""Link loss: `companion run` fed by `companion sim-autopilot` through a lossy UDP relay on 127.0.0.1 --
does run count exactly what was lost, warn, and keep N within 5 %?

The relay and the loop are those of ``tests/support/relay.py`` (checked in ``tests/mavlink/test_link.py``) (the relay drops vehicle->run datagrams
independently with probability p, or in bursts by a Gilbert model, and hands what it keeps on as fast as
run reads it, so the only losses are the relay's and it knows how many there were). Each case: 150
simulated seconds at 10x, white noise N = 3e-3 rad/s/sqrt(Hz) per axis at 100 Hz with 1 mrad/s rounding
(truth 10.31 deg/sqrt(h)). Printed per case: frames dropped by the relay and counted by run, the loss
STATUSTEXT, N per axis and its worst ratio to the truth.

    python -m benchmarks.bench_loss                  # 0, 10, 20, 30 % random; bursts of 12.5 and 50 frames
    python -m benchmarks.bench_loss --cases 20       # one case

Target: every lost frame counted exactly, the loss STATUSTEXT sent, N within 5 % of the truth.
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
from pathlib import Path


from benchmarks import results
from tests.support.relay import N_TRUE, loop_through_relay

CASES = {
    "0": {"p": 0.0},
    "10": {"p": 0.1},
    "20": {"p": 0.2},
    "30": {"p": 0.3},
    "burst12": {"burst": (0.02, 0.08)},  # mean burst 1/0.08 = 12.5 datagrams (125 ms at 100 Hz), ~20 % lost
    "burst50": {"burst": (0.005, 0.02)},  # mean burst 50 datagrams (0.5 s: a gap that restarts settling)
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma list of {', '.join(CASES)}")
    args = results.parse_args(ap, {"cases": "20,burst12"})
    names = [c.strip() for c in args.cases.split(",") if c.strip()]
    bad = [c for c in names if c not in CASES]
    if bad:
        ap.error(f"unknown case(s) {bad}; choose from {', '.join(CASES)}")
    print(f"truth N = {N_TRUE:.2f} deg/sqrt(h) per axis; 150 s simulated at 10x through the relay")
    print(f"{'case':<8} {'dropped':>8} {'counted':>8} {'loss %':>7} {'warned':>6}  N x / y / z [deg/sqrt(h)]"
          f"          worst N/truth")
    worst_all = 0.0
    for name in names:
        with tempfile.TemporaryDirectory(prefix="bench_loss_") as d:
            out, _, relay = loop_through_relay(Path(d), **CASES[name])
        m = re.search(r"link from 1/1: (\d+) frames received, (\d+) lost \(([\d.]+) %\)", out)
        counted = int(m.group(2)) if m else -1
        ns = [float(x) for x in re.findall(r"  g[xyz] online: N ([\d.]+) ", out)[:3]]
        worst = max(abs(n / N_TRUE - 1.0) for n in ns) if ns else float("nan")
        worst_all = max(worst_all, worst)
        pct = 100.0 * relay.dropped / max(relay.dropped + relay.forwarded, 1)
        warned = "yes" if "companion: link loss" in out else "no"
        print(f"{name:<8} {relay.dropped:>8} {counted:>8} {pct:>7.1f} {warned:>6}  "
              f"{' / '.join(f'{n:.2f}' for n in ns):<28} {100 * worst:>5.1f} %"
              + ("" if counted == relay.dropped else "   COUNT MISMATCH"))
    print(f"worst N error over the cases: {100 * worst_all:.1f} % (target 5 %)")
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
