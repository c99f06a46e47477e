"""A real rate-random-walk (K) rise on a realistic vehicle that is handled now and then: the delay until
`companion run` names it (`IMUi gyro A degrading: K ...x baseline`).

The still pieces between handlings go to the estimators as separate segments (no Allan cluster straddles a
handling, across which the bias moves); this measures that a K that really grows is still named. Drives the
real pipeline (companion.service.pipeline through its block API, as bench_faults.py) with the realistic
simulator (companion.sim.realism presets: the preset's rate, low-pass, decimation, temperature-driven bias,
Gauss-Markov bias), one IMU, handlings of 10 s every ``--handle-every`` s from 900 s, and from ``--at`` s an
independent random walk of ``--k`` rad/s^1.5 added to one gyro axis (companion.sim.vehicle.Degradation).

    python benchmarks/bench_k_rise.py --preset px4 --k 2e-4,1e-4 --seeds 2
    python benchmarks/bench_k_rise.py --k 0 --seeds 1      # no rise: any `degrading` line is a false alarm

Prints per case the delay from the rise to the first line naming the right IMU, axis and K, and every other
fault or degradation line.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from companion.mavlink.reporter import Reporter  # noqa: E402
from companion.service.pipeline import Pipeline, PipelineConfig  # noqa: E402
from companion.service.replay import replay_vehicle  # noqa: E402
from companion.sim.motion import Handling, Schedule  # noqa: E402
from companion.sim.preset import load_preset  # noqa: E402
from companion.sim.vehicle import Degradation, VehicleSimulator  # noqa: E402


class Sink:
    def send_named_value_float(self, *a):
        pass

    def send_statustext(self, *a, **kw):
        pass


def run(preset: str, k_add: float, seed: int, at: float, axis: str, every: float, max_delay: float) -> str:
    P = load_preset(preset)
    end = at + max_delay
    hand = tuple(Handling(at=float(a), duration=10.0) for a in range(900, int(end), int(every)))
    deg = Degradation(at=at, axis=axis, term={"effect": "random_walk", "K": k_add}) if k_add > 0 else None
    sim = VehicleSimulator(P["model"], imus=1, seed=seed, rate_hz=P["vehicle"].get("rate_hz"),
                           schedule=Schedule(handlings=hand), degrade=deg, realism=P["realism"])
    p = Pipeline(PipelineConfig(baseline_s=600.0), Reporter(Sink(), 1.0))
    word = f"IMU0 gyro {axis[1].upper()} degrading: K"
    t0 = sim.t_start + at
    wall = time.time()
    replay_vehicle(sim, p, end, lsb=None if preset == "px4" else 1e-3, chunk_s=10.0,
                   on_chunk=lambda t: k_add > 0 and any(x.startswith(word) for _, x in p.transitions))
    hit = [(t, x) for t, x in p.transitions if x.startswith(word) and t >= t0]
    other = [(round(t), x) for t, x in p.transitions if ("degrading" in x or "fault" in x.lower()) and (t, x) not in hit[:1]]
    res = (f"delay {hit[0][0] - t0:.0f} s ({hit[0][1]})" if hit else f"not named within {max_delay:.0f} s") if k_add > 0 else "no rise"
    return (f"{preset} K +{k_add:g} on {axis} at {at:g} s, seed {seed}: {res}; other lines {other}; "
            f"{len(hand)} handlings; {time.time() - wall:.0f} s wall")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="px4")
    ap.add_argument("--k", default="2e-4,1e-4", help="random walks added (rad/s^1.5), comma-separated; 0: none")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--at", type=float, default=1200.0, help="time of the rise (s)")
    ap.add_argument("--axis", default="gy")
    ap.add_argument("--handle-every", type=float, default=600.0)
    ap.add_argument("--max-delay", type=float, default=3600.0)
    args = ap.parse_args()
    for k in (float(x) for x in args.k.split(",")):
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            print(run(args.preset, k, seed, args.at, args.axis, args.handle_every, args.max_delay), flush=True)


if __name__ == "__main__":
    main()
