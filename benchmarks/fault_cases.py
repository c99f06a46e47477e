"""Fault cases of benchmarks/bench_faults.py: one case drawn from its seed (the fault, its size, the oracle's
delay), replayed through the real pipeline, and the delay to the first text that names it; the B x2 case with
a baseline from `companion analyze`; the realistic presets' simulators."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from companion import units
from companion.health import bias, disagreement, noise, stuck
from companion.health.evidence_rules import FaultLimits
from companion.mavlink.reporter import Reporter
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.replay import replay_vehicle
from companion.sim.vehicle import Fault, Flight, Schedule, VehicleSimulator, WarmUp

LIMITS = FaultLimits()

RATE = 100.0  #: Hz of the plain vehicle cases
LSB = 1e-3  #: rad/s, ArduPilot's int16 mrad/s rounding
DEG = math.pi / 180.0
AXES = ("gx", "gy", "gz")
SPIKE_AMPLITUDE = 0.3  #: rad/s: hundreds of robust sigmas on a still gyro, one spike is decisive


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


@dataclass
class CaseSpec:
    """One fault case as drawn: what the simulator injects and the oracle's delay to compare with."""

    fault_kind: str
    size: float
    limit: float
    desc: str
    imus: int = 1
    imu: int = 0
    schedule: Schedule = field(default_factory=Schedule)


def _stuck_spec(rng, sig, white, s_tot, rate, preset):
    size = float(rng.uniform(0.0, 0.3)) * white
    r = max((size * size + LSB * LSB / 12.0 * (size > 0)) / s_tot ** 2, 1e-12)
    limit = 1.0 / rate if size == 0 else stuck.H_ON / (rate * 0.5 * (r - 1 - math.log(r)))
    return CaseSpec("stuck", size, limit, f"dither {size / (s_tot if preset is None else white):.2f} sigma")


def _noise_spec(kind, rng, sig, s_tot, rate):
    size = {"N2": 2.0, "N1.5": 1.5}.get(kind) or float(math.exp(rng.uniform(math.log(3), math.log(100))))
    r = ((size * sig) ** 2 + LSB ** 2 / 12) / s_tot ** 2
    return CaseSpec("noise", size, noise.H_ON / (rate * 0.5 * (r - 1 - math.log(r))), f"x{size:.2f}")


def _bias_spec(rng, s_tot, rate):
    # a step at or above the floor (health.evidence_rules.FaultLimits.bias_jump_dps): smaller ones are wander
    size = float(rng.uniform(LIMITS.bias_jump_dps, 2.0)) * DEG * (1 if rng.random() < 0.5 else -1)
    return CaseSpec("bias", size, bias.H_ON / (rate * size * size / (2 * s_tot ** 2)), f"{size / DEG:+.2f} deg/s")


def _drift_spec(rng, s_tot, rate):
    size = float(rng.uniform(2e-5, 2e-4)) * (1 if rng.random() < 0.5 else -1)
    # oracle: a ramp D t: cumulative KL D^2 fs t^3 / (6 sigma^2) = h
    limit = (6 * bias.H_ON * s_tot ** 2 / (size * size * rate)) ** (1 / 3)
    return CaseSpec("drift", size, limit, f"{size / DEG:+.4f} deg/s per s")


def _spikes_spec(rng, rate):
    # oracle: a 0.3 rad/s spike on a still gyro is hundreds of robust sigmas, decisive alone to a test knowing
    # the fault: the limit is the wait for the first spike (measured on the case; its mean is 1 / (p fs)); the
    # detector asks for two (spikes.SPIKE_LLR_MAX): the second spike's time is printed
    size = float(rng.uniform(0.002, 0.01))
    return CaseSpec("spikes", size, 1.0 / (rate * size), f"{100 * size:.2f} % of {SPIKE_AMPLITUDE} rad/s")


def _saturate_spec(rng, t_f):
    size = float(rng.uniform(0.3, 1.0))
    return CaseSpec("saturate", size, float("nan"), f"clip +-{size:.2f} rad/s in flight",
                    schedule=Schedule(flights=(Flight(t_f - 60.0, t_f + 600.0),)))


def _flight_spec(kind, rng, s_tot, rate, t_f):
    imus = 2 if kind.endswith("2") else 3
    imu = int(rng.integers(imus))
    sched = Schedule(flights=(Flight(t_f - float(rng.uniform(30, 120)), t_f + 600.0),))
    if "stuck" in kind:
        return CaseSpec("stuck", 0.0, 1.0 / rate, f"{imus} IMUs, IMU{imu} frozen in flight", imus, imu, sched)
    # above the disagreement floor: 5 deg/s + 10 % of the flight's rms rate (~0.5 rad/s: 7.9 deg/s)
    size = float(rng.uniform(10.0, 15.0)) * DEG * (1 if rng.random() < 0.5 else -1)
    limit = disagreement.H_ON / (rate * size * size / (2 * 2 * s_tot ** 2))
    return CaseSpec("bias", size, limit, f"{imus} IMUs, IMU{imu} {size / DEG:+.0f} deg/s in flight", imus, imu, sched)


FLIGHT_KINDS = ("flight_stuck2", "flight_bias2", "flight_stuck3", "flight_bias3")


def draw_case(kind, rng, sig, white, s_tot, rate, t_f, preset) -> CaseSpec:
    """The fault of one case, its size drawn from ``rng`` (in this order, so a seed gives the same case)."""
    if kind == "stuck":
        return _stuck_spec(rng, sig, white, s_tot, rate, preset)
    if kind in ("noise", "N2", "N1.5"):
        return _noise_spec(kind, rng, sig, s_tot, rate)
    if kind == "bias":
        return _bias_spec(rng, s_tot, rate)
    if kind == "drift":
        return _drift_spec(rng, s_tot, rate)
    if kind == "spikes":
        return _spikes_spec(rng, rate)
    if kind == "saturate":
        return _saturate_spec(rng, t_f)
    if kind in FLIGHT_KINDS:
        return _flight_spec(kind, rng, s_tot, rate, t_f)
    raise ValueError(kind)


class Watch:
    """Reads the pipeline's transitions after each replayed chunk: the first text naming the fault after its
    onset (a hit), the first before it (early) and the first other fault text after it."""

    IGNORED = ("cleared", "back to normal", "learned")

    def __init__(self, pipeline, t0, words):
        self.p, self.t0, self.words = pipeline, t0, words
        self.found = {}

    def __call__(self, t) -> bool:
        for tt, text in self.p.transitions:
            if any(w in text for w in self.IGNORED):
                continue
            if tt < self.t0:
                self.found.setdefault("early", (tt, text))
            elif any(text.startswith(w) for w in self.words):
                self.found["hit"] = (tt, text)
                return True
            else:
                self.found.setdefault("other", (tt, text))
        return False


def case_result(kind, seed, spec: CaseSpec, axis, watch: Watch) -> dict:
    """The case's row: delay to the naming text (NaN if none), the oracle limit and what else was said."""
    found = watch.found
    out = {"kind": kind, "seed": seed, "desc": spec.desc, "limit": spec.limit, "axis": axis, "imu": spec.imu}
    if "hit" in found:
        out["delay"] = found["hit"][0] - watch.t0
        out["text"] = found["hit"][1]
    else:
        out["delay"] = math.nan
        out["text"] = (found.get("other") or found.get("early") or (None, "not flagged"))[1]
    out["early"] = found.get("early")
    out["other"] = found.get("other")
    return out


def run_case(kind, seed, max_delay, preset=None):
    """One fault case with fresh random parameters; returns a dict (delay, limit, named, text, params).
    ``preset``: on the realistic simulator with that preset's model and rate (the noise scale from
    :func:`preset_sigma`; the oracle limit then treats the filtered samples as white, a lower bound)."""
    rng = np.random.default_rng(10_000 + seed)
    if preset is None:
        rate = RATE
        model, sig = random_model(rng)
        white = sig
    else:
        model, sig, rate, white = preset_sigma(preset)
    axis = AXES[rng.integers(3)]
    s_tot = total_sigma(sig[axis])
    t_f = float(rng.uniform(360.0, 480.0))
    spec = draw_case(kind, rng, sig[axis], white[axis], s_tot, rate, t_f, preset)
    fault = Fault(spec.fault_kind, at=t_f, size=spec.size, imu=spec.imu, axis=axis, amplitude=SPIKE_AMPLITUDE)
    lsb = LSB
    if preset is None:
        sim = VehicleSimulator(model, imus=spec.imus, seed=seed, schedule=spec.schedule, fault=fault, warmup=WarmUp())
    else:
        sim, lsb = preset_simulator(preset, seed, 0.0, fault=fault, schedule=spec.schedule, imus=spec.imus)
    hits = _record_spikes(sim, fault) if kind == "spikes" else None
    p, _ = make_pipeline()
    words = expected_words("flight" if kind.startswith("flight") else spec.fault_kind, spec.imu, axis)
    watch = Watch(p, sim.t_start + t_f, words)
    replay_vehicle(sim, p, t_f + max_delay, lsb=lsb, on_chunk=watch, chunk_s=1.0)
    watch(0)
    if kind == "stuck" and preset is not None and lsb:
        spec.limit, where = quantised_stuck_limit(sim, sig[axis] / lsb, spec.size / lsb, lsb, rate)
        spec.desc += where
    if hits is not None:
        after = sorted(h - t_f for h in hits if h >= t_f)
        spec.limit = after[0] if after else math.nan
        spec.desc += f", spikes at +{', +'.join(f'{h:.1f}' for h in after[:3])} s" if after else ""
    return case_result(kind, seed, spec, axis, watch)


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

    frozen = sim._frozen if sim._frozen is not None else (sim._blk_frozen.value if sim._blk_frozen else math.nan)
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
