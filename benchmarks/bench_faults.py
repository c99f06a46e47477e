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
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np


from benchmarks import results
from companion import units  # noqa: E402
from companion.health import bias, disagreement, noise, stuck  # noqa: E402
from companion.health.limits import FaultLimits  # noqa: E402
from companion.mavlink.reporter import Reporter  # noqa: E402
from companion.service.pipeline import Pipeline, PipelineConfig  # noqa: E402
from companion.service.replay import replay_vehicle  # noqa: E402
from companion.sim.vehicle import Fault, Flight, Schedule, VehicleSimulator, WarmUp  # noqa: E402

LIMITS = FaultLimits()

RATE = 100.0
LSB = 1e-3
DEG = math.pi / 180.0
AXES = ("gx", "gy", "gz")


class Sink:
    def __init__(self):
        self.texts = []

    def send_named_value_float(self, *a):
        pass

    def send_statustext(self, sev, text, time_boot_ms=None):
        self.texts.append((sev, text))


def random_model(rng, sigma_lsb=None):
    """Fresh per-axis noise: white noise std sigma (LSB per sample), B, K; returns (model, sigmas)."""
    axes, sig = {}, {}
    for a in AXES:
        s = (sigma_lsb if sigma_lsb is not None else rng.uniform(0.7, 4.0)) * LSB
        sig[a] = s
        axes[a] = [{"effect": "white_noise", "N": s / math.sqrt(RATE)},
                   {"effect": "bias_instability", "B": units.from_datasheet("B", rng.uniform(10, 50))},
                   {"effect": "random_walk", "K": units.from_datasheet("K", rng.uniform(10, 100))}]
    return {"rate_hz": RATE, "axes": axes}, sig


def total_sigma(s):
    """Per-sample std after 1 mrad/s rounding (Sheppard: + LSB^2/12)."""
    return math.sqrt(s * s + LSB * LSB / 12.0)


def make_pipeline(baseline_s=300.0, log=None):
    sink = Sink()
    p = Pipeline(PipelineConfig(baseline_s=baseline_s), Reporter(sink, 1.0), log=log)
    return p, sink


#: what `run` logs when the motion gate finds that what it took for rest was not (its references learned afresh)
MISLEARNED = "quieter than what was taken for rest"


def expected_words(kind, imu, axis):
    a = axis[1].upper()
    return {"stuck": [f"IMU{imu} gyro {a} stuck"],
            "noise": [f"IMU{imu} gyro {a} noise"],
            "bias": [f"IMU{imu} gyro {a} bias jump", f"IMU{imu} gyro {a} bias drift"],
            "drift": [f"IMU{imu} gyro {a} bias drift", f"IMU{imu} gyro {a} bias jump"],
            "spikes": [f"IMU{imu} gyro {a} spikes"],
            "saturate": [f"IMU{imu} gyro {a} saturated"],
            "flight": [f"IMU{imu} gyro {a} stuck", f"IMU{imu} gyro {a} disagrees"]}[kind]


FAULT_WORDS = ("stuck", "dead", "noise", "bias", "spikes", "saturated", "disagrees", "degrading", "rate", "timing")


def preset_sigma(preset):
    """Per-axis std of one preset IMU's gyro samples at rest (30 s of IMU0 on the ground: the filtered,
    decimated white noise and the slow terms), the noise scale of the fault sizes; the preset's model and rate."""
    from companion.sim.preset import load_preset

    P = load_preset(preset)
    sim = VehicleSimulator(P["model"], imus=1, seed=999, rate_hz=P["vehicle"].get("rate_hz"), realism=P["realism"])
    g = sim.run(30.0).gyro[0]
    # the sample-to-sample noise the detectors see (second differences): the autopilot's low-pass makes it
    # smaller than the samples' spread, and a stuck gyro's dither is drawn against it
    dd = g[2:] - 2.0 * g[1:-1] + g[:-2]
    return (P["model"], {a: float(np.std(g[:, j])) for j, a in enumerate(AXES)}, sim.rate_hz,
            {a: float(np.sqrt(np.mean(dd[:, j] ** 2) / 6.0)) for j, a in enumerate(AXES)})


def run_case(kind, seed, max_delay, preset=None):
    """One fault case with fresh random parameters; returns a dict (delay, limit, named, text, params).
    ``preset``: on the realistic simulator with that preset's model and rate (the noise scale from
    :func:`preset_sigma`; the oracle limit then treats the filtered samples as white, a lower bound)."""
    rng = np.random.default_rng(10_000 + seed)
    rate = RATE
    if preset is None:
        model, sig = random_model(rng)
        white = sig
    else:
        model, sig, rate, white = preset_sigma(preset)
    axis = AXES[rng.integers(3)]
    s_tot = total_sigma(sig[axis])
    imus, imu = 1, 0
    sched = Schedule()
    t_f = float(rng.uniform(360.0, 480.0))
    amp = 0.3
    if kind == "stuck":
        size = float(rng.uniform(0.0, 0.3)) * white[axis]
        r = max((size * size + LSB * LSB / 12.0 * (size > 0)) / s_tot ** 2, 1e-12)
        limit = 1.0 / rate if size == 0 else stuck.H_ON / (rate * 0.5 * (r - 1 - math.log(r)))
        desc = f"dither {size / (s_tot if preset is None else white[axis]):.2f} sigma"
        fault_kind = "stuck"
    elif kind in ("noise", "N2", "N1.5"):
        size = {"N2": 2.0, "N1.5": 1.5}.get(kind) or float(math.exp(rng.uniform(math.log(3), math.log(100))))
        r = ((size * sig[axis]) ** 2 + LSB ** 2 / 12) / s_tot ** 2
        limit = noise.H_ON / (rate * 0.5 * (r - 1 - math.log(r)))
        desc = f"x{size:.2f}"
        fault_kind = "noise"
    elif kind == "bias":
        # a step at or above the floor (health.limits.FaultLimits.bias_jump_dps): smaller ones are wander
        size = float(rng.uniform(LIMITS.bias_jump_dps, 2.0)) * DEG * (1 if rng.random() < 0.5 else -1)
        limit = bias.H_ON / (rate * size * size / (2 * s_tot ** 2))
        desc = f"{size / DEG:+.2f} deg/s"
        fault_kind = "bias"
    elif kind == "drift":
        size = float(rng.uniform(2e-5, 2e-4)) * (1 if rng.random() < 0.5 else -1)
        # oracle: a ramp D t: cumulative KL D^2 fs t^3 / (6 sigma^2) = h
        limit = (6 * bias.H_ON * s_tot ** 2 / (size * size * rate)) ** (1 / 3)
        desc = f"{size / DEG:+.4f} deg/s per s"
        fault_kind = "drift"
    elif kind == "spikes":
        # oracle: a 0.3 rad/s spike on a still gyro is hundreds of robust sigmas, decisive alone to a test
        # knowing the fault: the limit is the wait for the first spike (measured on the case below; its mean
        # is 1 / (p fs)); the detector asks for two (spikes.SPIKE_LLR_MAX): the second spike's time is printed
        size = float(rng.uniform(0.002, 0.01))
        limit = 1.0 / (rate * size)
        desc = f"{100 * size:.2f} % of {amp} rad/s"
        fault_kind = "spikes"
    elif kind == "saturate":
        size = float(rng.uniform(0.3, 1.0))
        sched = Schedule(flights=(Flight(t_f - 60.0, t_f + 600.0),))
        limit = float("nan")
        desc = f"clip +-{size:.2f} rad/s in flight"
        fault_kind = "saturate"
    elif kind in ("flight_stuck2", "flight_bias2", "flight_stuck3", "flight_bias3"):
        imus = 2 if kind.endswith("2") else 3
        imu = int(rng.integers(imus))
        sched = Schedule(flights=(Flight(t_f - float(rng.uniform(30, 120)), t_f + 600.0),))
        if "stuck" in kind:
            fault_kind, size = "stuck", 0.0
            limit = 1.0 / rate
            desc = f"{imus} IMUs, IMU{imu} frozen in flight"
        else:
            # above the disagreement floor: 5 deg/s + 10 % of the flight's rms rate (~0.5 rad/s: 7.9 deg/s)
            fault_kind, size = "bias", float(rng.uniform(10.0, 15.0)) * DEG * (1 if rng.random() < 0.5 else -1)
            limit = disagreement.H_ON / (rate * size * size / (2 * 2 * s_tot ** 2))
            desc = f"{imus} IMUs, IMU{imu} {size / DEG:+.0f} deg/s in flight"
    else:
        raise ValueError(kind)
    fault = Fault(fault_kind, at=t_f, size=size, imu=imu, axis=axis, amplitude=amp)
    lsb = LSB
    if preset is None:
        sim = VehicleSimulator(model, imus=imus, seed=seed, schedule=sched, fault=fault, warmup=WarmUp())
    else:
        sim, lsb = preset_simulator(preset, seed, 0.0, fault=fault, schedule=sched, imus=imus)
    hits = _record_spikes(sim, fault) if kind == "spikes" else None
    p, sink = make_pipeline()
    words = expected_words("flight" if kind.startswith("flight") else fault_kind, imu, axis)
    t0 = sim.t_start + t_f
    found = {}

    def watch(t):
        for tt, text in p.transitions:
            if "cleared" in text or "back to normal" in text or "learned" in text:
                continue
            if tt < t0:
                found.setdefault("early", (tt, text))
            elif any(text.startswith(w) for w in words):
                found["hit"] = (tt, text)
                return True
            else:
                found.setdefault("other", (tt, text))
        return False

    replay_vehicle(sim, p, t_f + max_delay, lsb=lsb, on_chunk=watch, chunk_s=1.0)
    watch(0)
    if kind == "stuck" and preset is not None and lsb:
        limit, where = quantised_stuck_limit(sim, sig[axis] / lsb, size / lsb, lsb, rate)
        desc += where
    if hits is not None:
        after = sorted(h - t_f for h in hits if h >= t_f)
        limit = after[0] if after else math.nan
        desc += f", spikes at +{', +'.join(f'{h:.1f}' for h in after[:3])} s" if after else ""
    out = {"kind": kind, "seed": seed, "desc": desc, "limit": limit, "axis": axis, "imu": imu}
    if "hit" in found:
        out["delay"] = found["hit"][0] - t0
        out["text"] = found["hit"][1]
    else:
        out["delay"] = math.nan
        out["text"] = (found.get("other") or found.get("early") or (None, "not flagged"))[1]
    out["early"] = found.get("early")
    out["other"] = found.get("other")
    return out


def _record_spikes(sim, fault):
    """The times (s from the simulation's start) of the spikes the simulator adds: the oracle of a spike case
    is the first one."""
    hits = []
    apply = sim._apply_fault

    def wrapped(gyro, s, parts):
        j = AXES.index(fault.axis)
        before = np.array(gyro[fault.imu, :, j], copy=True)
        apply(gyro, s, parts)
        hit = np.abs(gyro[fault.imu, :, j] - before) > 0.5 * fault.amplitude
        t = np.asarray(s, dtype=float)
        hits.extend((t if t.ndim == 1 else t[fault.imu])[hit].tolist())

    sim._apply_fault = wrapped
    return hits


def quantised_stuck_limit(sim, s_lsb, d_lsb, lsb, rate):
    """The oracle limit of a value frozen with a dither of d LSB on rounded data: h / (fs KL) with KL the
    divergence of the frozen value's codes from a healthy gyro's at the same level (sample spread s LSB),
    both per sample and white. The Gaussian variance ratio of the other limits ((d^2 + 1/12) / s^2) is no
    bound there: a value frozen on a code boundary flips between two codes with a variance up to 1/4 LSB^2,
    as much as the healthy gyro's, and what tells them apart is only the healthy samples beyond those two
    codes. Returns (limit s, where the value froze: its distance from the nearest boundary in LSB, and the limit
    of an oracle that does not know the healthy level: the level closest to the frozen codes)."""
    from scipy.special import ndtr

    frozen = sim._frozen if sim._frozen is not None else (sim._blk_frozen or (0, math.nan))[1]
    v = float(frozen) / lsb
    if not math.isfinite(v):
        return math.nan, ""
    c = np.arange(math.floor(v) - 8, math.floor(v) + 10, dtype=float)
    healthy = ndtr((c + 0.5 - v) / s_lsb) - ndtr((c - 0.5 - v) / s_lsb)
    if d_lsb > 0:
        f = ndtr((c + 0.5 - v) / d_lsb) - ndtr((c - 0.5 - v) / d_lsb)
    else:
        f = (np.abs(c - v) <= 0.5).astype(float)
    m = f > 1e-12
    kl = float(np.sum(f[m] * np.log(f[m] / np.maximum(healthy[m], 1e-300))))
    off = abs((v - math.floor(v)) - 0.5)
    # an oracle that knows the frozen value's codes but not the healthy level (the detector cannot know it: the
    # value froze at one sample of the noise, about a sample's sd from the level, and the level wanders): the
    # healthy level closest to the frozen codes
    mu = v + np.arange(-1.5, 1.5 + 1e-9, 0.002)[:, None]
    h_mu = ndtr((c[m] + 0.5 - mu) / s_lsb) - ndtr((c[m] - 0.5 - mu) / s_lsb)
    kl_unk = float(np.min(np.sum(f[m] * np.log(f[m] / np.maximum(h_mu, 1e-300)), axis=1)))
    unk = stuck.H_ON / (rate * kl_unk) if kl_unk > 0 else math.inf
    return ((stuck.H_ON / (rate * kl) if kl > 0 else math.inf),
            f", {off:.2f} LSB from a code boundary, {unk:.1f} s not knowing the level")


def run_b2(seed, max_delay=3600.0):
    """B x2 with the baseline from `companion analyze` (analyze_axis: the same code) of a 2 h still log of the
    same gyro (another seed); the degradation adds an independent flicker of B sqrt(3) at t_d."""
    from companion.analysis.axis import analyze_axis
    from companion.health.baseline import Baseline, params_from_terms
    from companion.sim.vehicle import Degradation

    rng = np.random.default_rng(30_000 + seed)
    model, sig = random_model(rng)
    axis = AXES[rng.integers(3)]
    pre = VehicleSimulator(model, imus=1, seed=90_000 + seed)
    g = np.round(pre.run(7200.0).gyro[0] / LSB) * LSB
    base = Baseline("analyze")
    for j, a in enumerate(AXES):
        base.set_axis(0, a, params_from_terms(analyze_axis(g[:, j], RATE, lsb=LSB)["terms"]))
    b_true = [t["B"] for t in model["axes"][axis] if t["effect"] == "bias_instability"][0]
    t_d = 1200.0
    deg = Degradation(at=t_d, axis=axis, term={"effect": "bias_instability", "B": b_true * math.sqrt(3.0)})
    sim = VehicleSimulator(model, imus=1, seed=seed, degrade=deg)
    sink = Sink()
    p = Pipeline(PipelineConfig(), Reporter(sink, 1.0), baseline=base)
    word = f"IMU0 gyro {axis[1].upper()} degrading: B"
    t0 = sim.t_start + t_d

    def watch(t):
        return any(text.startswith(word) and tt >= t0 for tt, text in p.transitions)

    replay_vehicle(sim, p, t_d + max_delay, lsb=LSB, on_chunk=watch, chunk_s=10.0)
    hit = [(tt, text) for tt, text in p.transitions if text.startswith(word) and tt >= t0]
    early = [(tt, text) for tt, text in p.transitions if tt < t0]
    b_b = base.get(0, axis)["B"]
    desc = (f"B {units.to_datasheet('B', b_true, axis):.0f} deg/h, baseline {units.to_datasheet('B', b_b[0], axis):.1f}"
            f" +- {units.to_datasheet('B', b_b[1], axis):.1f}")
    return {"kind": "B2", "seed": seed, "desc": desc, "limit": math.nan, "axis": axis, "imu": 0,
            "delay": hit[0][0] - t0 if hit else math.nan, "text": hit[0][1] if hit else "not flagged",
            "early": early[0] if early else None, "other": None}


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


def preset_simulator(preset, seed, duration_s, fault=None, schedule=None, imus=None):
    """A realistic vehicle (companion.sim.realism, a preset of sim/presets: its noise model, IMUs, logged rate,
    low-pass and decimation, vibration per flight phase, IMU skew, temperature-driven bias with the logged
    temperature, Gauss-Markov bias, sensor LSB); a random schedule of flights and handlings unless given.
    Returns (simulator, LSB of the replayed messages: ArduPilot's int16 mrad/s, None for PX4's floats)."""
    from companion.sim.preset import load_preset

    P = load_preset(preset)
    kw = {"max_rate": float(P["vehicle"]["max_rate"])} if "max_rate" in P["vehicle"] else {}
    sched = schedule if schedule is not None else Schedule.random(duration_s, seed=seed, flights_per_hour=1.5,
                                                                  handlings_per_hour=2.0, **kw)
    sim = VehicleSimulator(P["model"], imus=int(imus or P["vehicle"].get("imus", 1)), seed=seed,
                           rate_hz=P["vehicle"].get("rate_hz"), schedule=sched, fault=fault, realism=P["realism"])
    return sim, (None if preset == "px4" else LSB)


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
