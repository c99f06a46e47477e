"""Telemetry rates: every IMU watched at 1-10 Hz, false alarms, and a gyro that dies mid-flight named.

    python -m benchmarks.bench_telemetry_rates            # simulated 1, 2, 4, 10 Hz (>= 100 IMU-h) + real tlogs
    python -m benchmarks.bench_telemetry_rates --quick    # the short run
    python -m benchmarks.bench_telemetry_rates --faults-only  # the samples each fault needs, alone

1. Simulated telemetry (companion.sim.vehicle, 3 IMUs, random flights and handlings, 50 Hz inside): each
   IMU's samples taken as a telemetry stream takes them, the latest sample every 1/rate s with +-20 %
   jitter and 3 % of the messages lost, gyro rounded to RAW_IMU's 1 mrad/s, accelerometer to 1 mG; fed
   to the run pipeline (Pipeline.on_samples, HEARTBEATs with the armed bit). Healthy runs: every FAULT
   transition is a false alarm (IMU-hours counted per IMU). Dead runs: one IMU's gyro set to exactly 0 on
   every axis from the middle of a flight on; the delay to the first "dead"/"stuck" naming that IMU,
   against the target max(60 s, 60 samples); any other IMU named after the onset is a false alarm too.
2. Real tlogs (the shared ArduSub tlog, /work/reallogs/ardusub, /work/reallogs/tlogs_extra; rates 1-4 Hz):
   the log as it is (every IMU watched? false alarms, rate switches), then once per IMU message a copy
   changed from the middle of its samples on (benchmarks/tlog_zero_gyro.py), replayed as ``companion run
   --source`` replays it (service.replay.replay_log): its gyro reading 0 (the delay to the first dead/stuck
   naming of that IMU); clipped at the 80th percentile of its largest |axis| in the second half (a range its
   fastest fifth of motion exceeds, 0.1 rad/s at least; logs with fewer than 5 % of those samples beyond
   0.1 rad/s, at rest in their second half, are left out): the delay to "saturated" from the first sample
   beyond the clip (a clip shows only once the motion reaches it); in multi-IMU logs, its X axis biased by
   10 deg/s: the delay to "disagrees" or "bias jump". Any other IMU named after the onset counts against it.

Targets (issue 48): every IMU watched, 0 false alarms over >= 100 simulated IMU-hours, every zeroed,
clipped or biased gyro named within max(60 s, 60 samples), its healthy twins not named.
"""

from __future__ import annotations

import argparse
import glob
import re
import tempfile
from pathlib import Path

import numpy as np

from benchmarks import results
from benchmarks.tlog_zero_gyro import edit_gyro, gyro_values
from companion.health.clip_watch import ClipWatch
from companion.health.frozen_watch import FrozenWatch
from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline
from companion.service.pipeline_config import PipelineConfig
from companion.sim.vehicle import IMU_MESSAGES, Flight, Handling, Schedule, VehicleSimulator, WarmUp

MODEL = {"rate_hz": 50.0, "axes": {
    **{a: [{"effect": "white_noise", "N": 6.2e-5}, {"effect": "bias_instability", "B": 1e-4},
           {"effect": "random_walk", "K": 2e-5}] for a in ("gx", "gy", "gz")},
    **{a: [{"effect": "white_noise", "N": 2e-3}] for a in ("ax", "ay", "az")}}}
LSB_G, LSB_A = 1e-3, 9.80665e-3
NAMED = re.compile(r"^IMU(\d) gyro [XYZ] (reads 0 while moving: dead|reads exactly 0: dead|reads 0: dead or below "
                   r"resolution|stuck)")


class Sink:
    def __init__(self):
        self.n_values, self.texts = 0, []

    def send_named_value_float(self, ms, name, value):
        self.n_values += 1

    def send_statustext(self, sev, text, time_boot_ms=None):
        self.texts.append(text)


def telemetry_pick(t: np.ndarray, rate: float, rng) -> np.ndarray:
    """Indices of the samples a telemetry stream at ``rate`` sends: the latest one at each send time
    (period 1/rate, +-20 % jitter), 3 % of the messages lost."""
    base = np.arange(t[0], t[-1], 1.0 / rate)
    send = base + rng.uniform(-0.2, 0.2, base.size) / rate
    idx = np.unique(np.clip(np.searchsorted(t, np.sort(send), side="right") - 1, 0, t.size - 1))
    return idx[rng.random(idx.size) >= 0.03]


def sim_run(seed: int, rate: float, hours: float, imus: int, dead: bool, watch_only: bool = False) -> dict:
    """One simulated run through the pipeline (``watch_only``: through the dead/frozen test alone, to reach
    many IMU-hours: the whole pipeline costs ~0.1 s of CPU per simulated second); returns the pipeline (or the
    watch's events) and, for a dead run, the onset and the IMU."""
    dur = hours * 3600.0
    if dead:  # a handling, then one flight over most of the run: the gyro dies in the air
        sch = Schedule(flights=[Flight(200.0, dur - 100.0)], handlings=[Handling(100.0, 20.0)])
    else:
        sch = Schedule.random(dur, seed=seed, flights_per_hour=3, handlings_per_hour=2, flight_s=(300.0, 900.0))
    sim = VehicleSimulator(MODEL, imus=imus, seed=seed, schedule=sch, warmup=WarmUp())
    rng = np.random.default_rng(seed + 1000)
    onset, bad = None, None
    if dead:
        f = sch.flights[0]
        onset = sim.t_start + f.arm_at + rng.uniform(60.0, f.disarm_at - f.arm_at - 180.0)
        bad = int(rng.integers(imus))
    p = Pipeline(PipelineConfig(), Reporter(Sink(), 1.0))
    watch, clip, events = FrozenWatch(), ClipWatch(32.767), []
    keys = [StreamKey(1, 1, IMU_MESSAGES[i], i) for i in range(imus)]
    for blk in sim.blocks(dur, block_s=600.0):
        picks = [telemetry_pick(blk.t, rate, rng) for _ in range(imus)]
        for c0 in np.arange(blk.t[0], blk.t[-1] + 1e-9, 10.0):
            c1 = c0 + 10.0
            armed = bool(sim.armed_at(c0))
            p.on_heartbeat(1, 2, 3, 128 if armed else 0)
            for i in range(imus):
                j = picks[i][(blk.t[picks[i]] >= c0) & (blk.t[picks[i]] < c1)]
                g = np.round(blk.gyro[i][j] / LSB_G) * LSB_G
                if dead and i == bad:
                    g[blk.t[j] >= onset] = 0.0
                a = np.round(blk.accel[i][j] / LSB_A) * LSB_A
                if watch_only:
                    watch.add(i, blk.t[j], g, a)
                    clip.add(i, blk.t[j], g)
                else:
                    p.on_samples(keys[i], blk.t[j], g, a)
            if watch_only:
                events += watch.judge() + clip.take()
    return {"pipeline": p, "events": events, "onset": onset, "bad": bad, "dur": dur}


def faults_of(p: Pipeline) -> list[tuple[float, int, str]]:
    """(t, imu, text) of every FAULT transition (a 'cleared' is not one)."""
    out = []
    for t, text in p.transitions:
        m = re.match(r"^IMU(\d)", text)
        if m and "cleared" not in text and "baseline learned" not in text:
            out.append((t, int(m.group(1)), text))
    return out


def judge(p: Pipeline, onset: float | None, bad: int | None, pattern=NAMED) -> tuple[list, float | None]:
    """(false alarms, delay to the faulty IMU's naming by ``pattern`` or None)."""
    false, delay = [], None
    for t, imu, text in faults_of(p):
        if onset is not None and imu == bad and t >= onset:
            if delay is None and pattern.match(text):
                delay = t - onset
            continue
        false.append((t, text))
    return false, delay


def simulated(rates, seeds: int, hours: float, imus: int) -> bool:
    """The whole pipeline: ``seeds`` healthy and ``seeds`` dead runs of ``hours`` per rate."""
    ok = True
    total_h, total_false = 0.0, 0
    for rate in rates:
        imu_h, fa, delays, missed, unwatched = 0.0, [], [], 0, 0
        target = max(60.0, 60.0 / rate)
        for s in range(seeds):
            for dead in (False, True):
                r = sim_run(1000 * int(rate * 10) + s, rate, hours, imus, dead)
                if not r:
                    continue
                p = r["pipeline"]
                unwatched += sum(1 for ch in p.channels.values() if not ch.rate_hz)
                false, delay = judge(p, r["onset"], r["bad"])
                fa += false
                if not dead:
                    imu_h += imus * hours
                elif delay is None or delay > target:
                    missed += 1
                else:
                    delays.append(delay)
        total_h += imu_h
        total_false += len(fa)
        d = np.array(delays) if delays else np.array([np.nan])
        print(f"  {rate:>4g} Hz: {imu_h:6.1f} healthy IMU-h, false alarms {len(fa)}; dead gyro named in "
              f"{len(delays)}/{len(delays) + missed} runs within {target:.0f} s (delay median {np.median(d):.1f} s, "
              f"max {np.max(d):.1f} s); IMUs with no rate {unwatched}")
        for t, text in fa[:3]:
            print(f"      false alarm at {t:.0f} s: {text}")
        ok &= not fa and missed == 0 and unwatched == 0
    print(f"  total: {total_h:.1f} healthy simulated IMU-hours through the pipeline, {total_false} false alarms")
    return ok


def watch_only(rates, seeds: int, hours: float, imus: int) -> bool:
    """The sample tests alone (health/frozen_watch.py, health/clip_watch.py) on healthy runs: their false
    alarms per IMU-hour."""
    total_h, total_false = 0.0, 0
    for rate in rates:
        n_false = 0
        for s in range(seeds):
            r = sim_run(7000 + 1000 * int(rate * 10) + s, rate, hours, imus, False, watch_only=True)
            n_false += sum(1 for _, ev in r["events"] if ev.state == 1)
        total_h += seeds * hours * imus
        total_false += n_false
        print(f"  {rate:>4g} Hz: {seeds * hours * imus:6.1f} healthy IMU-h, dead/stuck/saturated false alarms {n_false}")
    print(f"  total: {total_h:.1f} healthy simulated IMU-hours through the dead/frozen and clip tests, "
          f"{total_false} false alarms")
    return total_false == 0


def fault_samples(rates, seeds: int) -> bool:
    """The samples after the onset each fault needs at each rate, on the simulated telemetry of the tests
    (tests/support/telemetry_sim.py: 3 IMUs, body rates +-0.5 rad/s changing from sample to sample; 100 s,
    the fault on IMU1 from 50 s): the count of IMU1's samples from the onset to its naming, and whether
    another IMU was named."""
    from tests.support.telemetry_sim import run, telemetry

    faults = {
        "dead (gyro 0)": (lambda g, m: np.where(m[:, None], 0.0, g), NAMED),
        "at the 32.767 rad/s limit": (lambda g, m: np.where(m[:, None], np.clip(100.0 * g, -32.767, 32.767), g),
                                      SATURATED),
        "clipped at 0.3 rad/s": (lambda g, m: np.where(m[:, None], np.clip(g, -0.3, 0.3), g), SATURATED),
        "X biased 10 deg/s": (lambda g, m: g + np.where(m, np.radians(10.0), 0.0)[:, None] * [1.0, 0.0, 0.0],
                              DISAGREES),
    }
    ok = True
    for name, (fn, pattern) in faults.items():
        row = []
        for rate in rates:
            counts, other = [], 0
            for seed in range(seeds):
                t, g, a = telemetry(rate, 100.0, seed=100 * seed + int(rate * 10) + 7, imus=3)
                g[1] = fn(g[1], t >= 50.0)
                p, _ = run(t, g, a)
                false, delay = judge(p, 50.0, 1, pattern)
                other += len(false)
                counts.append(None if delay is None else int(np.count_nonzero((t >= 50.0) & (t <= 50.0 + delay))))
            got = [c for c in counts if c is not None]
            ok &= len(got) == len(counts) and other == 0
            row.append(f"{rate:g} Hz {min(got) if got else '-'}-{max(got) if got else '-'}"
                       + (f" ({len(counts) - len(got)} missed)" if len(got) < len(counts) else "")
                       + (f" (+{other} other IMU)" if other else ""))
        print(f"  {name:27s} samples to naming: " + "; ".join(row))
    return ok


def real_logs() -> list[Path]:
    name = Path("tlogs") / "ardusub_2023-04-18.tlog"
    shared = [results.SHARED_DATA / name, Path("/work/shared/data") / name]
    more = sorted(glob.glob("/work/reallogs/ardusub/*.tlog")) + sorted(glob.glob("/work/reallogs/tlogs_extra/*.tlog"))
    out, sizes = [], set()
    for p in shared + [Path(m) for m in more]:
        if p.exists() and p.stat().st_size not in sizes:  # the shared ArduSub tlog is also in reallogs/ardusub
            sizes.add(p.stat().st_size)
            out.append(p)
    return out


def replay(path) -> Pipeline:
    from companion.service.replay import replay_log

    p = Pipeline(PipelineConfig(), Reporter(Sink(), 1.0))
    replay_log(path, p)
    return p


SATURATED = re.compile(r"^IMU(\d) gyro [XYZ] saturated")
DISAGREES = re.compile(r"^IMU(\d) gyro X (disagrees|bias jump)")
BIAS_MRAD = 1000.0 * np.radians(10.0)  # 10 deg/s: twice ArduPilot's 5 deg/s gyro consistency limit
CLIP_MIN_MRAD = 100.0  # the lowest clip injected: far above any gyro's noise


def clip_level(path, message: str) -> float | None:
    """The injected clip (mrad/s): the 80th percentile of the largest |axis| of each sample of the second
    half (a range its fastest fifth of motion exceeds), 0.1 rad/s at least; None where fewer than 5 % of
    those samples exceed 0.1 rad/s (a log at rest in its second half: nothing to clip)."""
    t, g = gyro_values(path, message)
    top = np.abs(g[g.shape[0] // 2:]).max(axis=1)
    if np.mean(top > CLIP_MIN_MRAD) < 0.05:
        return None
    return max(CLIP_MIN_MRAD, float(np.percentile(top, 80.0)))


def injected(path, s, fn, pattern, tmp, level: float | None = None) -> tuple[float | None, list]:
    """Replay a copy of ``path`` whose ``s`` gyro is ``fn(gyro)`` from the middle of its samples: (the delay to
    the first naming of that IMU matching ``pattern``, the other IMUs named after the onset). ``level``
    (mrad/s, a clip): the delay from the first sample the clip changed, as a clip shows only once the motion
    reaches it."""
    from companion.sources import load

    z = Path(tmp) / "z.tlog"
    info = edit_gyro(path, z, s.key.message, fn)
    pz = replay(z)
    # the onset on the replay's time axis (a log with a reboot has its later sessions shifted)
    zs = [x for x in load(str(z)).streams if x.key == s.key][0]
    k0 = zs.t.size - info["frames"]
    onset = float(zs.t[k0]) if zs.t.size == info["total"] else info["t0"]
    if level is not None and zs.t.size == info["total"]:
        _, g = gyro_values(path, s.key.message)
        reached = np.flatnonzero(np.any(np.abs(g[k0:]) > level, axis=1))
        onset = float(zs.t[k0 + reached[0]]) if reached.size else onset
    return judge(pz, onset, s.key.instance, pattern)


def verdict(name, delay, false, target) -> tuple[str, bool]:
    text = f"{name} " + ("not named" if delay is None else f"{delay:.1f} s") + (f" (+{len(false)} false)" if false else "")
    return text, delay is not None and delay <= target and not false


def real(logs) -> bool:
    from companion.sources import load

    ok = True
    tally = {"zeroed": [0, 0], "clipped": [0, 0], "biased": [0, 0]}
    with tempfile.TemporaryDirectory() as d:
        for path in logs:
            streams = [s for s in load(str(path)).streams if s.is_imu]
            p = replay(path)
            watched = sum(1 for ch in p.channels.values() if ch.rate_hz)
            false, _ = judge(p, None, None)
            rates = ", ".join(f"{s.rate_hz:.2f}" for s in streams)
            switches = ", ".join(str(ch.rate_switches) for _, ch in sorted(p.channels.items()))
            lines = {"zeroed": [], "clipped": [], "biased": []}
            for s in streams:
                target = max(60.0, 60.0 / s.rate_hz)
                cases = [("zeroed", np.zeros_like, NAMED, s.key.message, None)]
                level = clip_level(path, s.key.message)
                if level is not None:
                    cases.append(("clipped", lambda g, c=level: np.clip(g, -c, c), SATURATED,
                                  f"{s.key.message} at {level / 1000:.2f} rad/s", level))
                if len(streams) > 1:
                    cases.append(("biased", lambda g: g + np.array([BIAS_MRAD, 0.0, 0.0]), DISAGREES, s.key.message,
                                  None))
                for kind, fn, pattern, name, lv in cases:
                    fz, delay = injected(path, s, fn, pattern, d, lv)
                    text, good = verdict(name, delay, fz, target)
                    lines[kind].append(text)
                    tally[kind][0] += good
                    tally[kind][1] += 1
                    ok &= good
                    for t, x in fz[:2]:
                        lines[kind].append(f"[{kind} {s.key.message}: at {t:.0f} s {x}]")
            print(f"  {path.name}: {len(streams)} IMU(s) at {rates} Hz, {watched} watched, "
                  f"{sum(1 for _ in p.channels)} seen, rate switches {switches}, false alarms {len(false)}")
            for kind, texts in lines.items():
                print(f"      {kind}: " + ("; ".join(texts) if texts else "-"))
            for t, text in false[:3]:
                print(f"      false alarm at {t:.0f} s: {text}")
            ok &= watched == len(streams) and not false
    print("  named within max(60 s, 60 samples), no other IMU named: " + ", ".join(
        f"{k} {v[0]}/{v[1]}" for k, v in tally.items()))
    return ok


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", type=float, nargs="+", default=[1.0, 2.0, 4.0, 10.0])
    ap.add_argument("--seeds", type=int, default=1, help="healthy and dead runs per rate through the pipeline")
    ap.add_argument("--hours", type=float, default=0.35, help="hours per simulated run through the pipeline")
    ap.add_argument("--imus", type=int, default=3)
    ap.add_argument("--watch-hours", type=float, default=3.0, help="hours per healthy run of the dead/frozen "
                    "test alone (3 runs per rate)")
    ap.add_argument("--fault-seeds", type=int, default=5, help="runs per fault and rate of the samples-needed table")
    ap.add_argument("--faults-only", action="store_true", help="only the samples each fault needs")
    ap.add_argument("--no-real", action="store_true", help="skip the real tlogs")
    ap.add_argument("--no-sim", action="store_true", help="skip the simulated runs")
    args = results.parse_args(ap, {"seeds": 1, "hours": 0.35, "watch_hours": 0.5})
    ok = True
    if args.faults_only:
        print(f"samples each fault needs (3 IMUs, {args.fault_seeds} runs per rate; docs/health.md):")
        ok = fault_samples(args.rates, args.fault_seeds)
        print("targets met" if ok else "targets NOT met")
        return 0
    if not args.no_sim:
        print(f"simulated telemetry: {args.imus} IMUs, {args.seeds} healthy + {args.seeds} dead runs of "
              f"{args.hours:g} h per rate")
        ok &= simulated(args.rates, args.seeds, args.hours, args.imus)
        print(f"the dead/frozen and clip tests alone: 3 healthy runs of {args.watch_hours:g} h per rate")
        ok &= watch_only(args.rates, 3, args.watch_hours, args.imus)
        print(f"samples each fault needs (3 IMUs, {args.fault_seeds} runs per rate; docs/health.md):")
        ok &= fault_samples(args.rates, args.fault_seeds)
    if not args.no_real:
        print("real tlogs (each IMU's gyro zeroed from the middle of its samples, one at a time):")
        ok &= real(real_logs())
    print("targets met" if ok else "targets NOT met")
    return 0


if __name__ == "__main__":
    import sys

    part = (" faults" if "--faults-only" in sys.argv else " real" if "--no-sim" in sys.argv
            else " sim" if "--no-real" in sys.argv else "")
    raise SystemExit(results.run(main, "bench_telemetry_rates" + part))
