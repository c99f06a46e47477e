"""`companion run`'s in-flight noise test (companion/service/inflight_live.py) on simulated flights: how soon a
doubled in-flight noise on one IMU is named and that the others stay silent, false alarms over many healthy
flights, and the CPU cost of 3 IMUs at 400 Hz with the in-flight estimation.

Targets (issue 47): one IMU's noise x2 in flight named within 120 s, the others silent; 0 false alarms over
>= 100 simulated flight IMU-hours (``--fa-hours 100``; the default run is shorter); 3 IMUs x 400 Hz within
10 % of one core (CPU time / data time).

Flights: the ``copter`` preset (companion/sim/presets: 3 IMUs at 50 Hz, per-IMU vibration pick-up, filter,
skew, temperature bias, Gauss-Markov bias) with the fault ``flight_noise`` x2 (the IMU's white noise and its
vibration pick-up doubled) on a random IMU and axis; and the plain vehicle (noise model only, common
vibration, 100 Hz, int16) with the fault ``noise`` x2 (white noise doubled). The flight starts 30 s after
the start; the in-flight baseline is learned from its first 240 s, the fault comes 150-400 s later.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import time

import numpy as np

from benchmarks import results

NAMED = re.compile(r"IMU(\d) gyro ([XYZ]) (flight|ground) noise changed")
PLAIN_MODEL = {"rate_hz": 100.0, "axes": {a: [{"effect": "white_noise", "N": 2.0e-4},
                                             {"effect": "bias_instability", "B": 2.0e-5},
                                             {"effect": "random_walk", "K": 2.0e-6}] for a in ("gx", "gy", "gz")}}


class _Sink:
    def __init__(self):
        self.texts = []

    def send_named_value_float(self, *a):
        pass

    def send_statustext(self, sev, text, time_boot_ms=None):
        self.texts.append(text)


def simulator(kind: str, seed: int, flight_s: float, fault=None, imus: int = 3, rate_hz=None):
    from companion.sim.preset import load_preset
    from companion.sim.vehicle import Flight, Schedule, VehicleSimulator

    sched = Schedule(flights=(Flight(30.0, 30.0 + flight_s, max_rate=1.0),))
    if kind == "copter":
        P = load_preset("copter")
        return VehicleSimulator(P["model"], imus=imus, seed=seed, rate_hz=rate_hz or P["vehicle"]["rate_hz"],
                                schedule=sched, fault=fault, realism=P["realism"]), 1e-3
    return VehicleSimulator(PLAIN_MODEL, imus=imus, seed=seed, rate_hz=rate_hz, schedule=sched, fault=fault), 1e-3


def fly(sim, lsb, duration_s, stop=None):
    """Replay through a fresh Pipeline; (pipeline, [(t, text)] of the in-flight verdicts)."""
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline import Pipeline, PipelineConfig
    from companion.service.replay import replay_vehicle

    p = Pipeline(PipelineConfig(), Reporter(_Sink(), 1.0))
    replay_vehicle(sim, p, duration_s, lsb=lsb, on_chunk=(lambda t: stop(p)) if stop else None)
    return p, [(t, x) for t, x in p.transitions if NAMED.search(x)]


def detection(kind: str, seeds: int, rng_seed: int = 47) -> list[str]:
    from companion.sim.vehicle import Fault

    rng = np.random.default_rng(rng_seed)
    delays, wrong, missed = [], 0, 0
    fault_kind = "flight_noise" if kind == "copter" else "noise"
    for s in range(seeds):
        imu, axis = int(rng.integers(3)), ("gx", "gy", "gz")[int(rng.integers(3))]
        at = 30.0 + 240.0 + float(rng.uniform(150.0, 400.0))
        sim, lsb = simulator(kind, 100 + s, at + 200.0, Fault(fault_kind, at=at, size=2.0, imu=imu, axis=axis))
        want = f"IMU{imu} gyro {axis[1].upper()} flight noise changed"
        p, v = fly(sim, lsb, at + 240.0 - 30.0 + 30.0,
                   stop=lambda p: any(want in x for _, x in p.transitions))
        hit = [t for t, x in v if want in x]
        others = [x for _, x in v if want not in x and "changed" in x]
        wrong += bool(others)
        if hit:
            delays.append(hit[0] - (sim.t_start + at))
        else:
            missed += 1
        print(f"  {kind} seed {100 + s}: x2 on IMU{imu} {axis} at {at:.0f} s: "
              + (f"named after {delays[-1]:.0f} s" if hit else "NOT named")
              + (f"; others named: {others}" if others else ""), flush=True)
    d = np.array(delays) if delays else np.array([math.nan])
    return [f"{kind}: {len(delays)}/{seeds} named, delay median {np.median(d):.0f} s, max {np.max(d):.0f} s, "
            f"within 120 s {int(np.sum(d <= 120.0))}/{seeds}; another IMU named in {wrong}/{seeds} flights"]


def false_alarms(kind: str, imu_hours: float, flight_s: float, imus: int) -> tuple[float, int, list]:
    hours, alarms, seen, s = 0.0, 0, [], 0
    while hours < imu_hours:
        sim, lsb = simulator(kind, 5000 + s, flight_s, imus=imus)
        p, v = fly(sim, lsb, flight_s + 40.0)
        hours += imus * flight_s / 3600.0
        alarms += sum(1 for _, x in v if "changed" in x)
        seen += [(5000 + s, x) for _, x in v]
        s += 1
    return hours, alarms, seen


def cpu(rate_hz: float, data_s: float, inflight: bool) -> float:
    """CPU seconds per data second of the pipeline alone (the samples made beforehand), 3 IMUs in flight."""
    from companion.mavlink.reporter import Reporter
    from companion.samples import StreamKey
    from companion.service.pipeline import Pipeline, PipelineConfig
    from companion.sim.vehicle import IMU_MESSAGES

    sim, _ = simulator("copter", 7, data_s + 60.0, rate_hz=rate_hz)
    blk = sim.run(data_s + 30.0)
    p = Pipeline(PipelineConfig(), Reporter(_Sink(), 1.0))
    if not inflight:
        p.inflight.on_block = lambda ch, t: None
    keys = [StreamKey(1, 1, IMU_MESSAGES[i], i) for i in range(3)]
    n = int(round(rate_hz))
    t0 = time.process_time()
    for k in range(0, blk.t.shape[0], n):
        p.on_heartbeat(1, 2, 3, 128 if blk.armed[k] else 0)
        for i, key in enumerate(keys):
            p.on_samples(key, blk.t[k:k + n], blk.gyro[i][k:k + n], blk.accel[i][k:k + n])
    return (time.process_time() - t0) / float(blk.t[-1] - blk.t[0])


def real_logs(paths: list[str], baseline_s: float | None) -> None:
    """Every log under ``paths`` with two or more IMUs of one system replayed as `run --no-state` does;
    ``baseline_s``: a shorter in-flight baseline, so that the test runs on short real flights."""
    import functools
    from pathlib import Path

    import companion.service.inflight_live as inflight
    from companion.errors import CompanionError
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline import Pipeline, PipelineConfig
    from companion.service.replay import replay_log, replay_tlog
    from companion.sources import load

    if baseline_s:
        inflight.InflightConfig = functools.partial(inflight.InflightConfig, baseline_s=baseline_s)
    files = sorted(str(f) for d in paths for f in Path(d).rglob("*")
                   if f.is_file() and f.suffix.lower() in (".bin", ".ulg", ".tlog", ".log"))
    multi, tested, verdicts = 0, 0, 0
    for f in files:
        try:
            streams = load(f).streams
        except (CompanionError, OSError, ValueError):
            continue
        per_sys: dict = {}
        for st in streams:
            per_sys.setdefault(st.key.sysid, set()).add(st.key.instance)
        if max((len(v) for v in per_sys.values()), default=0) < 2:
            continue
        multi += 1
        p = Pipeline(PipelineConfig(), Reporter(_Sink(), 1.0))
        try:
            (replay_tlog if f.lower().endswith(".tlog") else replay_log)(f, p)
        except CompanionError:
            continue
        nz = p.inflight.noise
        v = [x for _, x in p.transitions if NAMED.search(x)]
        verdicts += len(v)
        tested += any(b for b in nz.baseline.values())
        flight = max((pr.seconds["flight"] for pr in nz.pairs.values()), default=0.0)
        print(f"  {Path(f).name}: {flight:.0f} s in flight, figures: "
              f"{', '.join(c for c in nz.figures if nz.figures[c]) or 'none'}, baseline learned: "
              f"{', '.join(c for c in nz.baseline if nz.baseline[c]) or 'no'}, verdicts: {v or 0}", flush=True)
    print(f"REAL LOGS: {len(files)} logs, {multi} with two or more IMUs, {tested} with an in-flight baseline "
          f"(the test ran), {verdicts} verdicts")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=10, help="flights with a fault per simulator kind")
    ap.add_argument("--fa-hours", type=float, default=30.0, help="healthy flight IMU-hours (target: >= 100)")
    ap.add_argument("--flight-s", type=float, default=900.0, help="length of each healthy flight")
    ap.add_argument("--cpu-s", type=float, default=300.0, help="data seconds of the CPU measurement")
    ap.add_argument("--real", nargs="+", metavar="DIR", help="only: replay the real logs under DIR (e.g. "
                    "/work/shared/data /work/reallogs) and count in-flight verdicts")
    ap.add_argument("--real-baseline-s", type=float, default=None, help="with --real: a shorter in-flight baseline")
    args = results.parse_args(ap, {"seeds": 5, "fa_hours": 10.0, "flight_s": 900.0, "cpu_s": 120.0})
    if args.real:
        return real_logs(args.real, args.real_baseline_s)
    print("doubled in-flight noise on one IMU (3 IMUs): delay from the fault to its STATUSTEXT")
    lines = []
    for kind in ("copter", "plain"):
        lines += detection(kind, args.seeds)
    for line in lines:
        print(line)
    print(f"\nhealthy flights of {args.flight_s:g} s, in-flight verdicts")
    total_h, total_a = 0.0, 0
    for kind, imus, share in (("copter", 3, 0.5), ("plain", 3, 0.25), ("plain", 2, 0.25)):
        t0 = time.process_time()
        h, a, seen = false_alarms(kind, share * args.fa_hours, args.flight_s, imus)
        total_h, total_a = total_h + h, total_a + a
        print(f"  {kind}, {imus} IMUs: {h:.1f} flight IMU-hours, false alarms {a}"
              + (f" ({seen[:3]})" if a else "") + f", {time.process_time() - t0:.0f} s CPU", flush=True)
    print(f"FALSE ALARMS: {total_a} in {total_h:.1f} simulated flight IMU-hours")
    on, off = cpu(400.0, args.cpu_s, True), cpu(400.0, args.cpu_s, False)
    print(f"\nCPU, 3 IMUs x 400 Hz in flight (copter preset at 400 Hz): {100 * on:.1f} % of one core with the "
          f"in-flight estimation, {100 * off:.1f} % without (target: <= 10 %)")


if __name__ == "__main__":
    sys.exit(results.run(main))
