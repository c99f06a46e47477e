"""Gyro fault detection of `companion run`: delay per fault kind beside its information limit, and false alarms.

Drives the real pipeline (companion.service.pipeline.Pipeline through its block API on_samples: the same
blocks, motion gate, detectors and reports as sample by sample) with the multi-IMU vehicle simulator
(companion.sim.vehicle), gyro rounded to 1 mrad/s like ArduPilot's RAW_IMU/SCALED_IMU2/3, 100 Hz.

Every case draws FRESH RANDOM parameters from its seed: the gyro's white noise (0.7-4 LSB per sample),
bias instability (10-50 deg/h), rate random walk (10-100 deg/h^1.5), the fault's time, axis, IMU and
size (ranges printed), the vehicle's scale/misalignment spread, warm-up and schedule.

Delay: from the fault to the first STATUSTEXT that names the right IMU, axis and kind (a name that is
wrong counts as a miss and is printed). The information limit beside it is the delay of an oracle CUSUM
that knows the fault exactly, with the same threshold h: h / (fs * KL per sample) (Lorden 1971):
variance ratio r: KL = (r - 1 - ln r) / 2; mean step d on white noise sigma: d^2 / (2 sigma^2);
spikes of 0.3 rad/s (hundreds of robust sigmas on a still gyro, one is decisive): the wait for the first
spike (its time on that case; the detector needs two, whose time is printed); a frozen output: one sample;
a value frozen with a dither on rounded data (--preset-faults of an ArduPilot preset): the divergence of
its codes from a healthy gyro's at the same level (quantised_stuck_limit; on a code boundary the variance
ratio is no bound: the flips between two codes have the healthy gyro's variance).

False alarms: runs of H hours with two IMUs (every IMU-hour counts), each with warm-up drift (0.1 deg/s,
exponential, tau 200 s: 95 % within 10 min), random flights (arm, take-off, manoeuvres up to ~1.5
rad/s, vibration, landing, disarm) and handlings (picked up, turned, put down in a new attitude), int16
rounding with 0.7 LSB of noise (even runs) or 2-30 LSB (odd runs); any fault or degradation
STATUSTEXT is a false alarm.

    python -m benchmarks.bench_faults --quick          # 3 seeds per kind (no B x2), 2 healthy IMU-hours
    python -m benchmarks.bench_faults                  # 20 seeds per kind, 100 healthy IMU-hours
    python -m benchmarks.bench_faults --skip-healthy --seeds 5 --kinds stuck,noise
    python -m benchmarks.bench_faults --skip-faults --preset copter,plane,rover,px4 --healthy-runs 8 --healthy-hours 1
    python -m benchmarks.bench_faults --skip-faults --preset plane,rover,copter,px4 --healthy-runs 8 --first-run 8 \
        --healthy-hours 1 --jobs 2 --log soak.jsonl       # pieces append to one file ...
    python -m benchmarks.bench_faults --summary soak.jsonl  # ... and add up

--preset: the healthy runs use the realistic simulator (companion.sim.realism with the vehicle presets: each
preset's IMUs, logged rate, gyro low-pass and decimation, vibration per flight phase, IMU timing skew,
temperature-driven bias with its temperature carried to the pipeline as a log carries it, Gauss-Markov bias,
sensor LSB), random flights (1.5 per hour) and handlings (2 per hour); IMU-hours = hours x the preset's IMUs.

Target: each kind named right within its delay target (stuck and noise 10 s, bias jump 15 s, spikes and N x2 30 s, N x1.5 120 s, in-flight stuck or disagreement 10 s: the TARGET column), close to the oracle limit; 0 false alarms in 100 healthy IMU-hours.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np


from benchmarks import results
from benchmarks.fault_cases import (DEG, FAULT_WORDS, LSB, MISLEARNED, RATE, make_pipeline,
                                     preset_simulator, random_model, run_b2, run_case)
from companion.service.replay import replay_vehicle
from companion.sim.vehicle import Schedule, VehicleSimulator, WarmUp


def healthy_run(seed, hours, imus=2):
    rng = np.random.default_rng(20_000 + seed)
    # even runs: 0.7 LSB of noise (the coarse-rounding case); odd runs: 2-30 LSB (a noisy gyro)
    model0, _ = random_model(rng, sigma_lsb=0.7 if seed % 2 == 0 else float(rng.uniform(2.0, 30.0)))
    dur = hours * 3600.0
    sched = Schedule.random(dur, seed=seed, flights_per_hour=1.5, handlings_per_hour=2.0)
    sim = VehicleSimulator(model0, imus=imus, seed=seed, schedule=sched, warmup=WarmUp(amplitude=0.1 * DEG, tau_s=200.0))
    p, sink = make_pipeline(baseline_s=600.0)
    replay_vehicle(sim, p, dur, lsb=LSB, chunk_s=10.0)
    alarms = [(t, text) for t, text in p.transitions
              if any(w in text for w in FAULT_WORDS) and "cleared" not in text and "back to normal" not in text]
    moving = sum(ch.counts["blocks_moving"] for ch in p.channels.values())
    return alarms, len(sched.flights), len(sched.handlings), moving


def healthy_preset_run(preset, seed, hours):
    """One healthy realistic vehicle for ``hours`` through the pipeline (temperature carried like a log's);
    returns (alarms, IMUs, flights, handlings, rests the gate found mislearned)."""
    dur = hours * 3600.0
    sim, lsb = preset_simulator(preset, seed, dur)
    logs: list[str] = []
    p, sink = make_pipeline(baseline_s=600.0, log=logs.append)
    replay_vehicle(sim, p, dur, lsb=lsb, chunk_s=10.0)
    alarms = [(round(t), text) for t, text in p.transitions
              if any(w in text for w in FAULT_WORDS) and "cleared" not in text and "back to normal" not in text]
    mislearned = sum(MISLEARNED in x for x in logs)
    return alarms, sim.imus, len(sim.schedule.flights), len(sim.schedule.handlings), mislearned


def _preset_job(job):
    preset, seed, hours = job
    t0 = time.time()
    alarms, imus, nf, nh, ml = healthy_preset_run(preset, seed, hours)
    return preset, seed, hours, imus, nf, nh, alarms, ml, time.time() - t0


def healthy_presets(presets, runs, hours, first, jobs, log=None):
    """Healthy realistic runs, the presets in turn (run r: preset r mod len, seed r); prints each (every alarm
    with its time) as it ends and the total; ``log``: also one JSON line per run appended to that file, so that
    pieces run at different times (``--first-run``) add up (``--summary FILE``)."""
    import json
    from concurrent.futures import ProcessPoolExecutor

    todo = [(presets[r % len(presets)], r, hours) for r in range(first, first + runs)]
    t0 = time.time()
    imu_h, n_alarm, n_ml, by_preset = 0.0, 0, 0, {}
    with ProcessPoolExecutor(max_workers=max(1, jobs)) as ex:
        for preset, seed, h, imus, nf, nh, alarms, ml, wall in ex.map(_preset_job, todo):
            imu_h += h * imus
            n_alarm += len(alarms)
            n_ml += ml
            row = by_preset.setdefault(preset, [0.0, 0])
            row[0] += h * imus
            row[1] += len(alarms)
            print(f"healthy {preset} seed {seed}: {h:g} h x {imus} IMUs, {nf} flights, {nh} handlings: "
                  f"{len(alarms)} false alarms ({wall:.0f} s wall)" + (f": {alarms}" if alarms else "")
                  + (f"; the gate's rest found mislearned {ml}x" if ml else ""), flush=True)
            if log:
                with open(log, "a") as f:
                    f.write(json.dumps({"preset": preset, "seed": seed, "hours": h, "imus": imus, "flights": nf,
                                        "handlings": nh, "alarms": alarms, "mislearned": ml,
                                        "wall_s": round(wall)}) + "\n")
    print("by preset: " + ", ".join(f"{k} {v[1]} in {v[0]:g} IMU-h" for k, v in by_preset.items()))
    print(f"FALSE ALARMS (realistic presets): {n_alarm} in {imu_h:g} simulated healthy IMU-hours "
          f"({time.time() - t0:.0f} s wall, {jobs} jobs); the gate's rest found mislearned {n_ml}x")


def summarize(path):
    """The total of the healthy runs logged with --log: IMU-hours and false alarms per preset, each alarm."""
    import json

    rows = [json.loads(x) for x in Path(path).read_text().splitlines() if x.strip()]
    seen, by = set(), {}
    for r in rows:
        if (r["preset"], r["seed"], r["hours"]) in seen:  # a run logged twice counts once
            continue
        seen.add((r["preset"], r["seed"], r["hours"]))
        b = by.setdefault(r["preset"], {"runs": 0, "imu_h": 0.0, "alarms": [], "flights": 0, "handlings": 0})
        b["runs"] += 1
        b["imu_h"] += r["hours"] * r["imus"]
        b["flights"] += r["flights"]
        b["handlings"] += r["handlings"]
        b["alarms"] += [(r["seed"], t, text) for t, text in r["alarms"]]
    for k, b in by.items():
        print(f"{k}: {b['runs']} runs, {b['imu_h']:g} IMU-h, {b['flights']} flights, {b['handlings']} handlings, "
              f"{len(b['alarms'])} false alarms" + (f": {b['alarms']}" if b["alarms"] else ""))
    print(f"FALSE ALARMS (realistic presets): {sum(len(b['alarms']) for b in by.values())} in "
          f"{sum(b['imu_h'] for b in by.values()):g} simulated healthy IMU-hours ({len(seen)} runs)")


TARGET = {"stuck": 10, "noise": 10, "bias": 15, "drift": None, "spikes": 30, "N2": 30, "N1.5": 120, "saturate": None,
          "flight_stuck2": 10, "flight_bias2": 10, "flight_stuck3": 10, "flight_bias3": 10, "B2": 3600}
MAX_DELAY = {"stuck": 60, "noise": 60, "bias": 90, "drift": 600, "spikes": 120, "N2": 120, "N1.5": 400, "saturate": 300,
             "flight_stuck2": 60, "flight_bias2": 60, "flight_stuck3": 60, "flight_bias3": 60}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="3 seeds per kind, 1 healthy run of 1 h x 2 IMUs")
    ap.add_argument("--seeds", type=int, default=None, help="seeds per fault kind (default 20, quick 3)")
    ap.add_argument("--kinds", default=None, help="comma-separated subset of: " + ", ".join(TARGET))
    ap.add_argument("--healthy-runs", type=int, default=None, help="healthy runs (default 10, quick 1)")
    ap.add_argument("--healthy-hours", type=float, default=None, help="hours per healthy run, 2 IMUs each (default 5, quick 1)")
    ap.add_argument("--b2-seeds", type=int, default=3, help="seeds of the B x2 case (each simulates 2 h + 80 min)")
    ap.add_argument("--first-run", type=int, default=0, help="seed of the first healthy run (to split the runs over processes)")
    ap.add_argument("--preset", default=None, metavar="P[,P...]",
                    help="healthy runs on the realistic simulator with these presets in turn (copter, plane, rover, px4), "
                         "their own IMUs and rates, temperature carried through")
    ap.add_argument("--preset-faults", default=None, metavar="P",
                    help="the fault cases on the realistic simulator with this preset (its model, rate, filter, "
                         "vibration, temperature); B2 is skipped")
    ap.add_argument("--jobs", type=int, default=1, help="processes for the --preset healthy runs (default 1)")
    ap.add_argument("--log", default=None, metavar="FILE",
                    help="--preset runs: append one JSON line per healthy run to FILE (pieces add up)")
    ap.add_argument("--summary", default=None, metavar="FILE",
                    help="print the total of the JSON lines of --log FILE (per preset, every alarm) and exit")
    ap.add_argument("--per-seed", action="store_true", help="print every fault case's delay and limit")
    ap.add_argument("--skip-healthy", action="store_true")
    ap.add_argument("--skip-faults", action="store_true")
    args = ap.parse_args()
    if args.summary:
        summarize(args.summary)
        return
    seeds = args.seeds or (3 if args.quick else 20)
    kinds = args.kinds or ",".join(k for k in TARGET if not (args.quick and k == "B2"))
    runs = args.healthy_runs or (1 if args.quick else 10)
    hours = args.healthy_hours or (1.0 if args.quick else 5.0)
    t_all = time.time()
    if not args.skip_faults:
        if args.preset_faults:
            kinds = ",".join(k for k in kinds.split(",") if k.strip() != "B2")
            print(f"detection delay on the realistic simulator, preset {args.preset_faults}, {seeds} seeds per kind")
        else:
            print(f"detection delay at {RATE:g} Hz, 1 mrad/s rounding, fresh random parameters, {seeds} seeds per kind")
        print(f"{'kind':>14} {'target':>7} {'median':>8} {'max':>8} {'limit(med)':>11} {'named':>6}  ranges / misses")
        for kind in kinds.split(","):
            kind = kind.strip()
            if kind == "B2":
                res = [run_b2(s) for s in range(min(seeds, args.b2_seeds))]
            else:
                res = [run_case(kind, s, MAX_DELAY[kind], args.preset_faults) for s in range(seeds)]
            d = np.array([r["delay"] for r in res])
            lim = np.array([r["limit"] for r in res])
            ok = np.isfinite(d)
            tgt = TARGET[kind]
            med = f"{np.median(d[ok]):.1f} s" if ok.any() else "-"
            mx = f"{np.max(d[ok]):.1f} s" if ok.any() else "-"
            lm = f"{np.nanmedian(lim):.2f} s" if np.isfinite(lim).any() else "-"
            late = int(np.sum(d[ok] > tgt)) if tgt else 0
            print(f"{kind:>14} {(str(tgt) + ' s') if tgt else '-':>7} {med:>8} {mx:>8} {lm:>11} {ok.sum():>3}/{len(res)}"
                  f"  e.g. {res[0]['desc']}; {res[0]['text']}" + (f"; {late} over target" if late else ""), flush=True)
            for r in res:
                if args.per_seed:
                    print(f"{'':>14}   seed {r['seed']}: {r['desc']}: {r['delay']:.1f} s (limit {r['limit']:.2f} s)")
                if not math.isfinite(r["delay"]) or r["early"]:
                    print(f"{'':>14}   seed {r['seed']}: {r['desc']} on IMU{r['imu']} {r['axis']}: "
                          f"{'MISSED, said: ' + r['text'] if not math.isfinite(r['delay']) else ''}"
                          f"{' EARLY ' + str(r['early']) if r['early'] else ''}", flush=True)
    if not args.skip_healthy and args.preset:
        healthy_presets([p.strip() for p in args.preset.split(",")], runs, hours, args.first_run, args.jobs, args.log)
    elif not args.skip_healthy:
        t0 = time.time()
        total, n_alarm = 0.0, 0
        for r in range(args.first_run, args.first_run + runs):
            alarms, nf, nh, moving = healthy_run(r, hours)
            total += 2 * hours
            n_alarm += len(alarms)
            print(f"healthy run {r}: {hours:g} h x 2 IMUs, {nf} flights, {nh} handlings, {moving} moving blocks: "
                  f"{len(alarms)} false alarms" + (f" e.g. {alarms[:3]}" if alarms else ""), flush=True)
        print(f"FALSE ALARMS: {n_alarm} in {total:g} simulated healthy IMU-hours ({time.time() - t0:.0f} s wall)")
    print(f"total {time.time() - t_all:.0f} s wall")


if __name__ == "__main__":
    sys.exit(results.run(main))
