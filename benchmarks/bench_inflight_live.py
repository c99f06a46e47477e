"""`companion run`'s in-flight noise test (companion/service/inflight_live.py) on simulated flights: how soon a
doubled in-flight noise on one IMU is named and that the others stay silent, false alarms over many healthy
flights, and the CPU cost of 3 IMUs at 400 Hz with the in-flight estimation.

Targets (issue 47): one IMU's noise x2 in flight named within 120 s, the others silent (``--mode detect``);
0 false alarms over >= 100 simulated flight IMU-hours (``--mode fa``, about 25 min of CPU; ``--quick`` flies
10); 3 IMUs x 400 Hz within 10 % of one core, CPU time / data time (``--mode cpu``).

Fault flights (``--kinds``, ``preset[:imus[:rate]]``): the ``copter`` preset (companion/sim/presets: 3 IMUs
at 50 Hz, per-IMU vibration pick-up, filter, skew, temperature bias, Gauss-Markov bias; also at 400 Hz and
with 2 IMUs) and the ``px4`` preset flown with 3 IMUs at 250 Hz, with the fault ``flight_noise`` x2 (the IMU's
white noise and its vibration pick-up doubled); the plain vehicle (noise model only, common vibration,
100 Hz, int16) with the fault ``noise`` x2. The flight starts 30 s after the start, its first 240 s learn
the baseline, the fault comes 150-400 s later on a random IMU and axis. Healthy vehicles (``--mode fa``,
:data:`FA_MIX`) fly ``--flights`` flights each, the baseline learned in the first and kept; only the flight
time after it counts. ``--mode compare``: `run`'s flight figures against `analyze`'s on the same logs
(simulated flights written as DataFlash logs, and ``--logs``). ``--jobs``: flights in parallel.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
import re
import sys
import time

import numpy as np

from benchmarks import results

#: the verdicts naming an IMU: the noise test's and the vibration pick-up test's (companion/health/pickup.py)
NAMED = re.compile(r"IMU(\d) gyro ([XYZ]) ((flight|ground) noise changed|vibration pick-up [\d.e+-]+x)")


def names(text: str, imu: int, axis: str) -> bool:
    """Does ``text`` name IMU ``imu``'s gyro ``axis`` (X, Y, Z) as changed in flight?"""
    m = NAMED.search(text)
    return bool(m) and int(m.group(1)) == imu and m.group(2) == axis and "ground" not in m.group(3)
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


def simulator(kind: str, seed: int, flight_s: float, fault=None, imus: int = 3, rate_hz=None, flights: int = 1):
    """A vehicle of ``kind``: a preset's name (``copter``, ``px4``: its model and realism, at ``rate_hz`` or
    the preset's rate) or ``plain`` (:data:`PLAIN_MODEL`), flying ``flights`` flights of ``flight_s`` with
    60 s disarmed between them, the first 30 s after the start; (simulator, LSB of the replayed messages)."""
    from companion.sim.preset import load_preset
    from companion.sim.vehicle import Flight, Schedule, VehicleSimulator

    t0 = [30.0 + k * (flight_s + 60.0) for k in range(flights)]
    sched = Schedule(flights=tuple(Flight(t, t + flight_s, max_rate=1.0) for t in t0))
    if kind != "plain":
        P = load_preset(kind)
        return VehicleSimulator(P["model"], imus=imus, seed=seed, rate_hz=rate_hz or P["vehicle"]["rate_hz"],
                                schedule=sched, fault=fault, realism=P["realism"]), 1e-3
    return VehicleSimulator(PLAIN_MODEL, imus=imus, seed=seed, rate_hz=rate_hz, schedule=sched, fault=fault), 1e-3


def parse_kind(spec: str) -> tuple[str, int, float | None]:
    """``copter:3:400`` -> (``copter``, 3 IMUs, 400 Hz); the rate may be left out (the preset's)."""
    parts = spec.split(":")
    return parts[0], int(parts[1]) if len(parts) > 1 else 3, float(parts[2]) if len(parts) > 2 else None


def fly(sim, lsb, duration_s, stop=None):
    """Replay through a fresh Pipeline; (pipeline, [(t, text)] of the in-flight verdicts)."""
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline import Pipeline, PipelineConfig
    from companion.service.replay import replay_vehicle

    p = Pipeline(PipelineConfig(), Reporter(_Sink(), 1.0))
    replay_vehicle(sim, p, duration_s, lsb=lsb, on_chunk=(lambda t: stop(p)) if stop else None)
    return p, [(t, x) for t, x in p.transitions if NAMED.search(x)]


def _detect_one(spec: str, seed: int, imu: int, axis: str, at: float) -> tuple[float, list]:
    """One fault flight (:func:`detection`): (delay of the naming or inf, other IMUs' verdicts)."""
    from companion.sim.vehicle import Fault

    kind, imus, rate = parse_kind(spec)
    fault_kind = "noise" if kind == "plain" else "flight_noise"
    sim, lsb = simulator(kind, seed, at + 200.0, Fault(fault_kind, at=at, size=2.0, imu=imu, axis=axis),
                         imus=imus, rate_hz=rate)
    ax = axis[1].upper()
    p, v = fly(sim, lsb, at + 240.0, stop=lambda p: any(names(x, imu, ax) for _, x in p.transitions))
    hit = [t for t, x in v if names(x, imu, ax)]
    others = [x for _, x in v if not names(x, imu, ax) and (imus > 2 or ax not in x)]
    return (hit[0] - (sim.t_start + at) if hit else math.inf), others


def _submit_detection(spec: str, seeds: int, pool, rng_seed: int = 47) -> list:
    """The fault flights of ``spec``: [(seed, imu, axis, fault time, future)] (random IMU, axis and time)."""
    imus = parse_kind(spec)[1]
    rng = np.random.default_rng(rng_seed)
    out = []
    for s in range(seeds):
        imu, axis = int(rng.integers(imus)), ("gx", "gy", "gz")[int(rng.integers(3))]
        d = (100 + s, imu, axis, 30.0 + 240.0 + float(rng.uniform(150.0, 400.0)))
        out.append((*d, pool.submit(_detect_one, spec, *d)))
    return out


def detection(spec: str, seeds: int, flights: list) -> tuple[list[str], list[float], int]:
    """Flights of ``spec`` (:func:`parse_kind`) with one IMU's in-flight noise doubled at a random time, IMU
    and axis (:func:`_submit_detection`); (summary lines, delays of the named faults (inf when not named),
    flights naming another IMU). Two IMUs: both are named (suspects), so only the delay counts."""
    draws = [f[:4] for f in flights]
    got = [f[4].result() for f in flights]
    delays, wrong = [], 0
    for (seed, imu, axis, at), (delay, others) in zip(draws, got):
        delays.append(delay)
        wrong += bool(others)
        print(f"  {spec} seed {seed}: x2 on IMU{imu} {axis} at {at:.0f} s: "
              + (f"named after {delay:.0f} s" if math.isfinite(delay) else "NOT named")
              + (f"; others named: {others}" if others else ""), flush=True)
    d = np.array(delays)
    fin = d[np.isfinite(d)] if np.isfinite(d).any() else np.array([math.nan])
    line = (f"{spec}: {int(np.isfinite(d).sum())}/{seeds} named, delay median {np.median(fin):.0f} s, "
            f"max {np.max(fin):.0f} s, within 120 s {int(np.sum(d <= 120.0))}/{seeds}; another IMU named in "
            f"{wrong}/{seeds} flights")
    return [line], delays, wrong


def _fa_vehicle(spec: str, seed: int, flight_s: float, flights: int) -> tuple[float, list, float]:
    """One healthy vehicle (:func:`false_alarms`): (flight IMU-hours under test, its verdicts, CPU s)."""
    t0 = time.process_time()
    kind, imus, rate = parse_kind(spec)
    sim, lsb = simulator(kind, seed, flight_s, imus=imus, rate_hz=rate, flights=flights)
    p, v = fly(sim, lsb, flights * (flight_s + 60.0))
    nz = p.inflight.noise
    flown = max((pr.seconds["flight"] for pr in nz.pairs.values()), default=0.0)
    hours = imus * max(flown - nz.cfg.baseline_s, 0.0) / 3600.0 if nz.baseline["flight"] else 0.0
    return hours, list(v), time.process_time() - t0


def false_alarms(specs, imu_hours: float, flight_s: float, flights: int, pool, deadline: float):
    """Healthy vehicles of each (spec, share) of ``specs`` (:func:`parse_kind`), each flying ``flights`` flights
    of ``flight_s`` (the baseline learned in the first and kept, as `run`'s state file keeps it), until
    ``share x imu_hours`` flight IMU-hours under test (after the baseline) are flown, or the wall clock
    passes ``deadline`` (then the vehicles still flying are dropped, and said so); {spec: [hours, verdicts,
    texts, vehicles]}."""
    from concurrent.futures import FIRST_COMPLETED, wait

    out = {spec: [0.0, 0, [], 0] for spec, _ in specs}
    jobs = {}
    queue = []
    for spec, share in specs:
        imus = parse_kind(spec)[1]
        per = imus * (flights * flight_s - 300.0) / 3600.0  # about: the baseline and the take-offs not tested
        queue += [(spec, 5000 + k) for k in range(max(1, math.ceil(share * imu_hours / per)))]
    queue.sort(key=lambda q: q[1])  # the kinds interleaved: each progresses
    while (queue or jobs) and time.time() < deadline:
        while queue and len(jobs) < pool._max_workers:
            spec, seed = queue.pop(0)
            jobs[pool.submit(_fa_vehicle, spec, seed, flight_s, flights)] = (spec, seed)
        done, _ = wait(list(jobs), timeout=max(1.0, min(60.0, deadline - time.time())), return_when=FIRST_COMPLETED)
        for f in done:
            spec, seed = jobs.pop(f)
            h, texts, cpu_s = f.result()
            _CPU[0] += cpu_s
            o = out[spec]
            o[0] += h
            o[1] += len(texts)
            o[2] += [(seed, x) for x in texts]
            o[3] += 1
            print(f"    {spec} vehicle {seed}: {h:.2f} IMU-h under test, verdicts {texts or 0}", flush=True)
    if jobs or queue:
        print(f"  (wall-clock limit: {len(jobs)} vehicles in flight and {len(queue)} not started left out)")
        for proc in list(pool._processes.values()):
            proc.terminate()
    return out


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


def real_logs(paths: list[str], baseline_s: float | None, sequence: bool = False) -> None:
    """Every log under ``paths`` with two or more IMUs of one system replayed as `run --no-state` does
    (``sequence``: one vehicle's logs in the order given, the state kept from one to the next as `run
    --state` keeps it); ``baseline_s``: shorter in-flight baselines (noise and pick-up), so that the tests
    run on short real flights."""
    import functools
    from pathlib import Path

    import companion.health.pickup as pickup
    import companion.service.inflight_live as inflight
    from companion.errors import CompanionError
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline import Pipeline, PipelineConfig
    from companion.service.pipeline_state import load_pipeline_state, pipeline_state
    from companion.service.replay import replay_log, replay_tlog
    from companion.sources import load

    if baseline_s:
        inflight.InflightConfig = functools.partial(inflight.InflightConfig, baseline_s=baseline_s)
        pickup.PickupConfig = functools.partial(pickup.PickupConfig, baseline_s=baseline_s)
    files = [f for f in paths if Path(f).is_file()] if sequence else sorted(
        str(f) for d in paths for f in Path(d).rglob("*")
        if f.is_file() and f.suffix.lower() in (".bin", ".ulg", ".tlog", ".log"))
    multi, tested, verdicts, picked, state = 0, 0, 0, 0, None
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
        if state is not None:
            load_pipeline_state(p, state)
        try:
            (replay_tlog if f.lower().endswith(".tlog") else replay_log)(f, p)
        except CompanionError:
            continue
        if sequence:
            state = pipeline_state(p)
        nz, pw = p.inflight.noise, p.inflight.pickup.watch
        v = [x for _, x in p.transitions if NAMED.search(x)]
        verdicts += len(v)
        tested += any(b for b in nz.baseline.values())
        picked += bool(pw.base)
        # flight seconds the test saw (take-offs and landings left out), and those after its baseline
        flight = max((pr.seconds["flight"] for pr in nz.pairs.values()), default=0.0)
        after = flight - nz.cfg.baseline_s if nz.baseline["flight"] else 0.0
        rate = max((pr.rate_hz or 0.0 for pr in nz.pairs.values()), default=0.0)
        print(f"  {Path(f).name}: {len({i for k in nz.pairs for i in k})} IMUs at {rate:.0f} Hz, {flight:.0f} s in "
              f"flight, {max(after, 0.0):.0f} s after the baseline, figures: "
              f"{', '.join(c for c in nz.figures if nz.figures[c]) or 'none'}, baseline learned: "
              f"{', '.join(c for c in nz.baseline if nz.baseline[c]) or 'no'}; pick-up baseline: "
              f"{'yes' if pw.base else f'no ({pw.learned_s:.0f} s of windows)'}, verdicts: {v or 0}", flush=True)
    print(f"REAL LOGS: {len(files)} logs, {multi} with two or more IMUs, {tested} with an in-flight baseline "
          f"(the noise test ran), {picked} with a pick-up baseline (the pick-up test ran), {verdicts} verdicts")


DETECT = ("copter:3", "copter:3:400", "px4:3", "plain:3", "copter:2")
#: healthy vehicles for the false-alarm count: (kind, share of the IMU-hours); copter vibration at 50 and 400 Hz,
#: 3 and 2 IMUs, and the PX4 quad at 250 Hz with 3 IMUs
FA_MIX = (("copter:3", 0.4), ("copter:2", 0.3), ("copter:3:400", 0.15), ("px4:3", 0.15))


_CPU = [0.0]  # CPU seconds of the vehicles flown by the workers


def _cpu_now() -> float:
    """CPU seconds of this process and of the vehicles its workers flew."""
    return time.process_time() + _CPU[0]


def detect_mode(kinds, seeds: int, pool) -> None:
    print("doubled in-flight noise on one IMU: delay from the fault to its STATUSTEXT (2 IMUs: both named)")
    lines, all_d, wrong, n = [], [], 0, 0
    futures = {spec: _submit_detection(spec, seeds, pool) for spec in kinds}  # every flight queued at once
    for spec in kinds:
        ln, d, w = detection(spec, seeds, futures[spec])
        lines += ln
        all_d += d
        wrong += w if parse_kind(spec)[1] > 2 else 0
        n += len(d)
    for line in lines:
        print(line)
    d = np.array(all_d)
    fin = np.sort(d[np.isfinite(d)])
    q = (lambda p: f"{np.percentile(fin, p):.0f}") if fin.size else (lambda p: "-")
    print(f"ALL {n} fault flights: named {fin.size}/{n}, within 120 s {int(np.sum(d <= 120.0))}/{n}; delay "
          f"percentiles 10/50/90 %: {q(10)}/{q(50)}/{q(90)} s, max {q(100)} s; another IMU named (3 IMUs) in "
          f"{wrong} flights")


def fa_mode(hours: float, flight_s: float, flights: int, pool, wall_s: float) -> None:
    from companion.service.inflight_live import InflightNoise

    nz = InflightNoise()
    per = nz.cfg.test.per_imu_hour
    c = nz.cfg
    z3, z2 = (c.test.z(k, c.check_s, c.memory_s, c.baseline_s) for k in (3, 2))
    print(f"healthy vehicles, {flights} flights of {flight_s:g} s each (baseline learned in the first, kept); "
          f"design false-alarm rate {per:g} per flight IMU-hour (z {z3:.2f} at 3 IMUs, {z2:.2f} at 2)")
    t0 = _cpu_now()
    out = false_alarms(FA_MIX, hours, flight_s, flights, pool, time.time() + wall_s)
    total_h, total_a = 0.0, 0
    for spec, (h, a, seen, n) in out.items():
        total_h, total_a = total_h + h, total_a + a
        print(f"  {spec}: {n} vehicles, {h:.1f} flight IMU-hours under test, false alarms {a}"
              + (f" ({seen[:3]})" if a else ""))
    print(f"FALSE ALARMS: {total_a} in {total_h:.1f} simulated flight IMU-hours under test (expected at the "
          f"design rate: {per * total_h:.2f}); {_cpu_now() - t0:.0f} s CPU")


def _offline(path: str) -> dict:
    """`companion analyze`'s flight figures of a log: {imu: {axis: (N, lo, hi, bound)}} (rad/s/sqrt(Hz))."""
    import contextlib
    import io
    import json
    import tempfile

    from companion.cli.main import main as cli

    with tempfile.TemporaryDirectory() as d, contextlib.redirect_stdout(io.StringIO()):
        cli(["analyze", path, "--quiet", "--json", f"{d}/r.json"])
        rep = json.loads(open(f"{d}/r.json").read())
    out: dict = {}
    for st in rep.get("streams", []):
        for ax, e in ((st.get("flight") or {}).get("axes") or {}).items():
            for term in e.get("terms", []) + e.get("bounds", []):
                if term["effect"] == "white_noise":
                    lo, hi = term.get("ci95", {}).get("N", [0.0, term["N"]])
                    out.setdefault(st["instance"], {})[ax] = (term["N"], lo, hi, bool(term.get("bound")))
    return out


def _live(path: str) -> dict:
    """`run`'s flight figures of the same log, replayed: {imu: {axis: (N, 1-sigma, bound)}} (pairs: each IMU)."""
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline import Pipeline, PipelineConfig
    from companion.service.replay import replay_log, replay_tlog

    p = Pipeline(PipelineConfig(), Reporter(_Sink(), 1.0))
    (replay_tlog if path.lower().endswith(".tlog") else replay_log)(path, p)
    p.inflight.noise.check()
    out: dict = {}
    for who, axes in p.inflight.noise.figures["flight"].items():
        for imu in (who if isinstance(who, tuple) else (who,)):
            out[imu] = {ax: (n, s, bound or isinstance(who, tuple)) for ax, (n, s, bound) in axes.items()}
    return out


def _sim_log(path: str, kind: str, seed: int, imus: int, flight_s: float) -> None:
    """A simulated flight of ``kind`` written as a DataFlash log (float samples, the preset's filter as
    INS_GYRO_FILTER), armed 30 s after the start."""
    from companion.sim.dataflash_writer import write_imu_log

    sim, _ = simulator(kind, seed, flight_s, imus=imus)
    blk = sim.run(flight_s + 40.0)
    params = {"INS_GYRO_FILTER": 20.0} if kind != "plain" else None
    arm = np.flatnonzero(np.diff(blk.armed.astype(int)))
    events = [(float(blk.t[k + 1]), bool(blk.armed[k + 1])) for k in arm]
    write_imu_log(path, blk.t, np.array(blk.gyro), np.array(blk.accel), layout="4.x", params=params, armed=events)


def compare_mode(kinds, seeds: int, flight_s: float, real: list[str]) -> None:
    """Live (`run` replaying the log) against offline (`analyze`) flight N per IMU and axis on the same logs:
    their ratio, and whether they agree within their intervals (live 1.96 sigma, offline its 95 % interval)."""
    import tempfile

    logs = []
    with tempfile.TemporaryDirectory() as d:
        for spec in kinds:
            kind, imus, _ = parse_kind(spec)
            for s in range(seeds):
                path = f"{d}/{kind}{imus}_{s}.bin"
                _sim_log(path, kind, 300 + s, imus, flight_s)
                logs.append((f"{spec} seed {300 + s}", path))
        logs += [(Path(f).name, f) for f in real]
        ratios, agree, n_all = [], 0, 0
        for name, path in logs:
            off, live = _offline(path), _live(path)
            parts, r_log = [], []
            for imu in sorted(set(off) & set(live)):
                for ax in sorted(set(off[imu]) & set(live[imu])):
                    n0, lo, hi, b0 = off[imu][ax]
                    n1, s1, b1 = live[imu][ax]
                    if b0 or b1:
                        parts.append(f"IMU{imu} {ax} bound(s) {n1 / n0:.2f}")
                        continue
                    ok = abs(n1 - n0) <= math.hypot(1.96 * s1, 0.5 * (hi - lo))
                    ratios.append(n1 / n0)
                    r_log.append(n1 / n0)
                    agree += ok
                    n_all += 1
                    parts.append(f"IMU{imu} {ax} {n1 / n0:.2f}{'' if ok else '!'}")
            print(f"  {name}: live/offline N " + ("; ".join(parts) or "no common figures"), flush=True)
    r = np.array(ratios) if ratios else np.array([math.nan])
    print(f"COMPARE: {n_all} IMU-axes with values both ways, within their intervals {agree}/{n_all}; live/offline "
          f"median {np.median(r):.3f}, range {np.min(r):.2f}-{np.max(r):.2f} ('!': outside the intervals)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mode", choices=("all", "detect", "fa", "cpu", "compare"), default="all",
                    help="one part only (each mode its own section of RESULTS.md)")
    ap.add_argument("--kinds", nargs="*", default=list(DETECT), help="fault flights: preset[:imus[:rate]]")
    ap.add_argument("--seeds", type=int, default=10, help="flights with a fault per kind")
    ap.add_argument("--fa-hours", type=float, default=100.0, help="healthy flight IMU-hours under test (target: >= 100)")
    ap.add_argument("--flight-s", type=float, default=900.0, help="length of each healthy flight")
    ap.add_argument("--flights", type=int, default=4, help="flights per healthy vehicle")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes (the flights are independent)")
    ap.add_argument("--wall-s", type=float, default=math.inf, help="--mode fa: stop after this wall time (s), "
                    "reporting the IMU-hours flown")
    ap.add_argument("--cpu-s", type=float, default=300.0, help="data seconds of the CPU measurement")
    ap.add_argument("--real", nargs="+", metavar="DIR", help="only: replay the real logs under DIR (e.g. "
                    "/work/shared/data /work/reallogs) and count in-flight verdicts")
    ap.add_argument("--logs", nargs="*", default=[], help="with --mode compare: real logs compared too")
    ap.add_argument("--sequence", action="store_true", help="with --real: the files given are one vehicle's "
                    "flights, replayed in order with the state kept (as `run --state`)")
    ap.add_argument("--real-baseline-s", type=float, default=None, help="with --real: a shorter in-flight baseline")
    args = results.parse_args(ap, {"seeds": 4, "fa_hours": 10.0, "flight_s": 900.0, "cpu_s": 120.0})
    if args.real:
        return real_logs(args.real, args.real_baseline_s, args.sequence)
    if args.mode == "compare":
        return compare_mode(args.kinds, args.seeds, args.flight_s, args.logs)
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(args.jobs) as pool:
        if args.mode in ("all", "detect"):
            detect_mode(args.kinds, args.seeds, pool)
        if args.mode in ("all", "fa"):
            print()
            fa_mode(args.fa_hours, args.flight_s, args.flights, pool, args.wall_s)
    if args.mode in ("all", "cpu"):
        on, off = cpu(400.0, args.cpu_s, True), cpu(400.0, args.cpu_s, False)
        print(f"\nCPU, 3 IMUs x 400 Hz in flight (copter preset at 400 Hz): {100 * on:.1f} % of one core with the "
              f"in-flight estimation, {100 * off:.1f} % without (target: <= 10 %)")


if __name__ == "__main__":
    mode = sys.argv[sys.argv.index("--mode") + 1] if "--mode" in sys.argv[:-1] else "all"
    sys.exit(results.run(main, name="bench_inflight_live" + ("" if mode == "all" else f" {mode}")))
