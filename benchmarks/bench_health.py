"""Degradation detection of `companion run`: false alarms over healthy hours, delays after 1.5x / 2x steps.

Drives the real pipeline code (companion.service.pipeline: fast/slow online estimators, baseline learning,
the health detector with its defaults) with simulated still gyro data in 10 s blocks (the estimators'
block updates are split-invariant, so this equals feeding message by message; the still/motion logic is
bypassed: all data is still). Data: an ADIS16405-like gyro at 100 Hz (N 2.3 deg/sqrt(h), B 30 deg/h,
K 60 deg/h^1.5; ../shared/data/README.md), rounded to 1 mrad/s like ArduPilot's RAW_IMU.

    python -m benchmarks.bench_health                  # 100 healthy hours (10 runs x 10 h x 3 axes) + steps
    python -m benchmarks.bench_health --healthy-runs 2 --healthy-hours 2 --seeds 1   # quick look

Prints the false alarms per run and, per step (term x factor), the delay until IMU0G_HLTH = 1 per seed.

Target: 0 false alarms over 100 healthy hours; every 1.5x and 2x step of N, B or K named (IMU0G_HLTH = 1) within --max-delay-h.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np


from benchmarks import results
from companion import units
from companion.health.degradation import DEGRADING
from companion.mavlink.reporter import Reporter
from companion.service.pipeline import Channel, Pipeline, PipelineConfig
from companion.sim.synth import synthesize_axis

RATE = 100.0
LSB = 1e-3
MODEL = [
    {"effect": "white_noise", "N": units.from_datasheet("N", 2.3)},
    {"effect": "bias_instability", "B": units.from_datasheet("B", 30.0)},
    {"effect": "random_walk", "K": units.from_datasheet("K", 60.0)},
]
EFFECT = {"N": "white_noise", "B": "bias_instability", "K": "random_walk"}
CHUNK_S = 3600.0  # synthesis chunk (the random walk continues across chunks; flicker is cut at 1/(4 h))
BLOCK_S = 10.0


class NullSink:
    def send_named_value_float(self, *a):
        pass

    def send_statustext(self, *a, **kw):
        pass


class Gyro:
    """One axis of the model, in chunks; optional step: from t_step on, term p is multiplied by F."""

    def __init__(self, seed, step=None):
        self.rng = np.random.default_rng(seed)
        self.step = step
        self.t = 0.0
        self.last = 0.0
        self.extra_last = 0.0

    def chunk(self):
        n = int(CHUNK_S * RATE)
        y = np.zeros(n)
        for m in MODEL:  # term by term: only the random walk continues across chunks
            c = synthesize_axis([m], RATE, n, self.rng)
            if m["effect"] == "random_walk":
                c += self.last
                self.last = float(c[-1])
            y += c
        t = self.t + np.arange(n) / RATE
        if self.step is not None:
            t0, p, f = self.step
            if t[-1] >= t0:
                base = [m for m in MODEL if m["effect"] == EFFECT[p]][0][p]
                e = synthesize_axis([{"effect": EFFECT[p], p: base * math.sqrt(f * f - 1)}], RATE, n, self.rng)
                if p == "K":  # a random walk that starts from 0 at t0 and continues across chunks
                    i0 = max(0, int(round((t0 - self.t) * RATE)))
                    e += (self.extra_last - e[0]) if self.t >= t0 else -e[i0]
                    self.extra_last = float(e[-1])
                y += np.where(t >= t0, e, 0.0)
        self.t += CHUNK_S
        return t, np.round(y / LSB) * LSB


def make(cfg, axes):
    p = Pipeline(cfg, Reporter(NullSink(), 1.0))
    ch = Channel(0, "SIM", cfg)
    ch.cutter.rate_hz = RATE
    ch.axes = axes
    ch.make_estimators(learning=True)
    p.channels[0] = ch
    return p, ch


def run(cfg, seeds_axes, hours, step_axis=None, step=None, stop_on_flag=False):
    """Returns (transitions [(t, text)], time of first DEGRADING or None)."""
    axes = tuple(seeds_axes)
    p, ch = make(cfg, axes)
    gyros = {ax: Gyro(seed, step if ax == step_axis else None) for ax, seed in seeds_axes.items()}
    nb = int(BLOCK_S * RATE)
    first = None
    t_end = hours * 3600.0
    while True:
        chunks = {ax: g.chunk() for ax, g in gyros.items()}
        t = next(iter(chunks.values()))[0]
        for k in range(0, t.size, nb):
            data = np.zeros((min(nb, t.size - k), 7))
            data[:, 0] = t[k:k + nb]
            for j, ax in enumerate(("gx", "gy", "gz")):
                if ax in chunks:
                    data[:, 1 + j] = chunks[ax][1][k:k + nb]
            if ch.feed(data):
                p._learn_done(ch)
            tt = float(data[-1, 0])
            if ch.check_due(tt):
                p._check(ch, tt)
                if first is None and ch.detector.state == DEGRADING:
                    first = tt
                    if stop_on_flag:
                        return p.transitions, first
            if tt >= t_end:
                return p.transitions, first


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--healthy-runs", type=int, default=10)
    ap.add_argument("--healthy-hours", type=float, default=10.0)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--baseline-s", type=float, default=None, help="override run.baseline_s")
    ap.add_argument("--step-at-h", type=float, default=1.0, help="step time after start (hours)")
    ap.add_argument("--max-delay-h", type=float, default=4.0)
    ap.add_argument("--skip-healthy", action="store_true")
    args = results.parse_args(ap, {"healthy_runs": 1, "healthy_hours": 1.0, "seeds": 1, "step_at_h": 0.5, "max_delay_h": 0.25})
    cfg = PipelineConfig()
    if args.baseline_s:
        cfg.baseline_s = args.baseline_s
    h = cfg.health
    print(f"defaults: baseline_s {cfg.baseline_s:g}, forgetting fast {cfg.forgetting_fast_s:g} s (Q, N) / slow "
          f"{cfg.forgetting_slow_s:g} s (B, K, R), check every {cfg.check_s:g} s; z {h.z:g}, ratio_on {h.ratio_on:g}, "
          f"ratio_off {h.ratio_off:g}, hold_on {h.hold_on}, hold_off {h.hold_off}")
    print("gyro: " + ", ".join(f"{m['effect']} {list(m.values())[1]:.3g}" for m in MODEL) + f" (SI), {RATE:g} Hz, 1 mrad/s LSB")
    if not args.skip_healthy:
        total_h, alarms = 0.0, 0
        t0 = time.time()
        for r in range(args.healthy_runs):
            seeds = {"gx": 1000 + 3 * r, "gy": 1001 + 3 * r, "gz": 1002 + 3 * r}
            tr, first = run(cfg, seeds, args.healthy_hours)
            n = sum(1 for _, text in tr if "degrading" in text)
            alarms += n
            total_h += args.healthy_hours
            print(f"healthy run {r}: {args.healthy_hours:g} h x 3 axes, false alarms {n}" +
                  (f" (first at {first / 3600:.2f} h: {tr[0][1]})" if n else ""), flush=True)
        print(f"FALSE ALARMS: {alarms} in {total_h:g} simulated IMU hours ({3 * total_h:g} axis-hours), "
              f"{time.time() - t0:.0f} s wall")
    t_step = args.step_at_h * 3600.0
    print(f"\nstep at {args.step_at_h:g} h on gx; delay until IMU0G_HLTH = 1 (max {args.max_delay_h:g} h)")
    print(f"{'term':>4} {'factor':>6} " + " ".join(f"{'seed ' + str(s):>12}" for s in range(args.seeds)))
    for p in ("N", "B", "K"):
        for f in (1.5, 2.0):
            cells = []
            for s in range(args.seeds):
                tr, first = run(cfg, {"gx": 7 + s}, args.step_at_h + args.max_delay_h, "gx", (t_step, p, f),
                                stop_on_flag=True)
                if first is None:
                    cells.append("not flagged")
                elif first < t_step:
                    cells.append(f"early {first / 60:.0f} min")
                else:
                    cells.append(f"{(first - t_step) / 60:.1f} min")
            print(f"{p:>4} {f:>6.1f} " + " ".join(f"{c:>12}" for c in cells), flush=True)


if __name__ == "__main__":
    sys.exit(results.run(main))
