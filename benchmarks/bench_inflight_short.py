"""In-flight figures of short flights: how often the 95 % interval (or bound) of a pair's figure and of each
IMU's three-cornered-hat share holds the truth, and how wide it is, at the spans a real log's flight gives
(the shortest a figure is made from: companion.analysis.inflight.MIN_FIGURE_SECONDS).

Two kinds of simulated flight with known per-IMU white noise N (uniform 0.5-3 deg/sqrt(h)):

- ``synthetic``: the redundancy tests' flight (tests/redundancy/synthetic.py): 200 Hz float, slow manoeuvres and
  vibration lines common to the IMUs, per-IMU mounting and time offset up to 2 ms;
- ``tlm50``: the realistic draws of companion/sim/flight_draws.py, 50 Hz telemetry in int16 mrad/s from a
  1 kHz sensor with per-IMU 8-12 Hz filters and vibration through each IMU's mounting.

    python -m benchmarks.bench_inflight_short
    python -m benchmarks.bench_inflight_short --spans 10.5 5 --seeds 200 --hat-seeds 150 --tlm-seeds 60
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from benchmarks import results

DEG = math.radians(1.0) / 60.0


def _n(entry: dict):
    """(lo, hi) of an axis entry's white-noise interval (a bound: (0, N)), or None."""
    for t in entry.get("terms", []):
        if t["effect"] == "white_noise":
            return tuple(t["ci95"]["N"])
    for b in entry.get("bounds", []):
        if b["effect"] == "white_noise":
            return 0.0, b["N"]
    return None


def _flight(kind: str, seed: int, imus: int, seconds: float):
    """(tracks, intervals, truth per reported figure) of one simulated flight."""
    from companion.redundancy import ImuTrack

    if kind == "synthetic":
        from tests.redundancy.synthetic import RATE, flight

        rng = np.random.default_rng(4700 + seed)
        n_true = rng.uniform(0.5, 3.0, imus) * DEG
        t, g, _ = flight(seed, n_true, seconds=seconds, offsets=list(rng.uniform(0.0, 0.002, imus)))
        tracks, iv = [ImuTrack(t, g[i], RATE) for i in range(imus)], [(t[0], t[-1])]
    else:
        from companion.sim.flight_draws import draw_flight

        d = draw_flight(seed, "tlm50", imus=imus, flight_s=seconds + 10.0)
        n_true = d.n_true
        tracks = [ImuTrack(d.t, d.gyro[i], d.rate_hz, float(d.filter_hz[i]), d.lsb or None) for i in range(imus)]
        iv = d.intervals
    return tracks, iv, ([math.hypot(*n_true)] if imus == 2 else list(n_true))


def coverage(kind: str, imus: int, seconds: float, seeds: int) -> dict:
    """Axes whose interval holds the truth, axes with a figure, axes, bounds, median relative half-width."""
    from companion.analysis.inflight import MIN_FIGURE_SECONDS
    from companion.redundancy import redundant_noise

    hit = fig = total = bounds = 0
    half = []
    for s in range(seeds):
        tracks, iv, truth = _flight(kind, s, imus, seconds)
        res = redundant_noise(tracks, iv, min_seconds=MIN_FIGURE_SECONDS)
        ents = ([res.pairs[0]["axes"]] if res.pairs else [{}]) if imus == 2 else [p["axes"] for p in res.per_imu]
        for tv, axes in zip(truth, ents):
            total += 3
            for e in axes.values():
                v = _n(e)
                if v is None:
                    continue
                fig += 1
                hit += v[0] <= tv <= v[1]
                if v[0] > 0:
                    half.append((v[1] - v[0]) / (v[1] + v[0]))
                else:
                    bounds += 1
    return {"hit": hit, "fig": fig, "total": total, "bounds": bounds,
            "half": float(np.median(half)) if half else float("nan")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spans", type=float, nargs="+", default=[10.5], help="flight seconds (default: 10.5)")
    ap.add_argument("--seeds", type=int, default=100, help="synthetic two-IMU flights per span")
    ap.add_argument("--hat-seeds", type=int, default=40, help="synthetic three-IMU flights per span")
    ap.add_argument("--tlm-seeds", type=int, default=20, help="realistic 50 Hz two-IMU draws per span (0: none)")
    args = ap.parse_args()
    print("kind       IMUs  span s  flights  axes  figures  interval holds the truth  bounds  half-width/midpoint")
    for span in args.spans:
        for kind, imus, n in (("synthetic", 2, args.seeds), ("synthetic", 3, args.hat_seeds),
                              ("tlm50", 2, args.tlm_seeds)):
            if n <= 0:
                continue
            t0 = time.time()
            c = coverage(kind, imus, span, n)
            print(f"{kind:<10} {imus:>4}  {span:>6.1f}  {n:>7}  {c['total']:>4}  {c['fig']:>7}  "
                  f"{c['hit']:>5} ({c['hit'] / max(c['total'], 1):6.1%}){'':>10}  {c['bounds']:>6}  "
                  f"{c['half']:>8.1%}   ({time.time() - t0:.0f} s)", flush=True)
    print("target: the 95 % interval holds the truth on about 95 % of the axes")
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
