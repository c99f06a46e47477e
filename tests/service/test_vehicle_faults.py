"""`companion run` pipeline against the vehicle simulator: faults named (STATUSTEXT, IMU{i}G_HLTH, IMU{i}G_FLT,
severity), a healthy handled/flown vehicle never flagged, the motion gate never hiding a fault, state kept."""

from __future__ import annotations

import copy
import functools
import hashlib
import io
import math

import pytest

from companion import units
from companion.cli.run import print_summary
from companion.health.faults import KIND_CODE
from companion.mavlink.reporter import MAV_SEVERITY_CRITICAL, MAV_SEVERITY_WARNING, Reporter
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.replay import replay_vehicle
from companion.sim.vehicle import Fault, Flight, Handling, Schedule, VehicleSimulator, WarmUp
from tests.support.sinks import RecordingSink

LSB = 1e-3
DEG = math.pi / 180


def model(sigma_lsb=2.0):
    return {"rate_hz": 100.0, "axes": {a: [
        {"effect": "white_noise", "N": sigma_lsb * LSB / 10.0},
        {"effect": "bias_instability", "B": units.from_datasheet("B", 30.0)},
        {"effect": "random_walk", "K": units.from_datasheet("K", 40.0)}] for a in ("gx", "gy", "gz")}}


def run(duration, imus=1, fault=None, schedule=None, seed=1, sigma_lsb=2.0, baseline_s=200.0):
    sim = VehicleSimulator(model(sigma_lsb), imus=imus, seed=seed, schedule=schedule or Schedule(), fault=fault,
                           warmup=WarmUp())
    sink = RecordingSink()
    p = Pipeline(PipelineConfig(baseline_s=baseline_s), Reporter(sink, 1.0))
    replay_vehicle(sim, p, duration, lsb=LSB)
    return p, sink


#: tests of seed 1 with the same IMUs and schedule share the first ``prefix_s`` seconds, before their faults
#: (260 s and later at rest, 300 s in flight): the simulator's fault draws from its own generator and acts from
#: its time on, so before it the samples are the healthy vehicle's (run_faulty checks it), and the pipeline is
#: deterministic. Each prefix is replayed once per test process; each test continues a copy of it with its own
#: faulty simulator: the same messages, bit for bit, as run(duration, imus, fault, schedule).
PREFIX_S = 250.0


class _Digest:
    """A pipeline stand-in for replay_vehicle that only hashes what it is fed (forwarded to ``pipeline`` too)."""

    def __init__(self, pipeline=None):
        self.pipeline, self.hash = pipeline, hashlib.sha256()

    def on_heartbeat(self, *args):
        self.hash.update(repr(args).encode())
        if self.pipeline is not None:
            self.pipeline.on_heartbeat(*args)

    def on_samples(self, key, t, gyro, accel, temperature=None):
        for x in (t, gyro, accel) + (() if temperature is None else (temperature,)):
            self.hash.update(repr(key).encode() + memoryview(x).tobytes())
        return 0 if self.pipeline is None else self.pipeline.on_samples(key, t, gyro, accel, temperature=temperature)


@functools.lru_cache(maxsize=None)
def _prefix(prefix_s, imus, schedule):
    """(pipeline, sink) after the first ``prefix_s`` seconds of the healthy vehicle, and the digest of what it was
    fed."""
    sim = VehicleSimulator(model(), imus=imus, seed=1, schedule=schedule, fault=None, warmup=WarmUp())
    sink = RecordingSink()
    p = Pipeline(PipelineConfig(baseline_s=200.0), Reporter(sink, 1.0))
    fed = _Digest(p)
    replay_vehicle(sim, fed, prefix_s, lsb=LSB)
    return (p, sink), fed.hash.hexdigest()


def run_faulty(duration, fault, imus=1, schedule=Schedule(), prefix_s=PREFIX_S):
    """``run(duration, imus, fault, schedule)`` (seed 1), its first ``prefix_s`` seconds from the shared prefix."""
    assert fault.at > prefix_s
    sim = VehicleSimulator(model(), imus=imus, seed=1, schedule=schedule, fault=fault, warmup=WarmUp())
    skipped = _Digest()
    replay_vehicle(sim, skipped, prefix_s, lsb=LSB)  # in replay_vehicle's own chunks: the state it would have
    state, digest = _prefix(prefix_s, imus, schedule)
    assert skipped.hash.hexdigest() == digest, "the faulty vehicle's first seconds are not the healthy one's"
    p, sink = copy.deepcopy(state)
    replay_vehicle(sim, p, duration, lsb=LSB)
    return p, sink


def fault_texts(sink):
    return [(s, t) for s, t in sink.texts if "learned" not in t]


def test_healthy_handled_and_flown_two_imus_no_alarm():
    sched = Schedule(flights=(Flight(330.0, 560.0),), handlings=(Handling(250.0, 25.0), Handling(620.0, 20.0)))
    p, sink = run(800.0, imus=2, schedule=sched, sigma_lsb=0.7)
    assert fault_texts(sink) == []
    assert sink.values["IMU0G_HLTH"] == 0.0 and sink.values["IMU1G_HLTH"] == 0.0
    assert sink.values["IMU0G_FLT"] == 0.0 and sink.values["IMU1G_FLT"] == 0.0
    assert sink.values["IMU0G_FLM"] == 0.0 and sink.values["IMU1G_FLM"] == 0.0
    assert p.channels[0].counts["blocks_moving"] >= 230 + 40  # flight and handlings seen as motion


@pytest.mark.parametrize("kind, size, words, code, severity", [
    ("stuck", 0.0, "IMU0 gyro Y stuck", "stuck", MAV_SEVERITY_CRITICAL),
    ("noise", 6.0, "IMU0 gyro Y noise", "noise", MAV_SEVERITY_WARNING),
    ("bias", 1.0 * DEG, "IMU0 gyro Y bias jump +", "bias_jump", MAV_SEVERITY_WARNING),
    ("spikes", 0.005, "IMU0 gyro Y spikes", "spikes", MAV_SEVERITY_WARNING),
])
def test_each_fault_is_named_with_its_code_and_severity(kind, size, words, code, severity):
    p, sink = run_faulty(330.0, Fault(kind, at=280.0, size=size, axis="gy"))
    texts = fault_texts(sink)
    assert texts, "not flagged"
    sev, text = texts[0]
    assert text.startswith(words) and sev == severity
    t_flag = p.transitions[[t for _, t in p.transitions].index(text)][0]
    assert t_flag - 281.0 <= 15.0
    assert sink.values["IMU0G_HLTH"] == 1.0 and sink.values["IMU0G_FLT"] == KIND_CODE[code]
    out = io.StringIO()
    print_summary(p, out)
    assert "FAULT: " + words in out.getvalue()


def test_noise_jump_is_not_hidden_by_the_motion_gate():
    """x30 noise on one axis: the accel and the other axes stay quiet, so the blocks stay still."""
    p, sink = run_faulty(320.0, Fault("noise", at=270.0, size=30.0, axis="gx"))
    assert fault_texts(sink)[0][1].startswith("IMU0 gyro X noise")
    assert p.channels[0].counts["blocks_moving"] <= 3


def test_stuck_during_baseline_learning_is_flagged_before_any_baseline():
    p, sink = run(120.0, fault=Fault("stuck", at=60.0, size=0.0, axis="gz"), baseline_s=600.0)
    assert fault_texts(sink)[0] == (MAV_SEVERITY_CRITICAL, "IMU0 gyro Z stuck")
    assert sink.values["IMU0G_HLTH"] == 1.0  # a fault overrides "learning"


@pytest.mark.parametrize("imus, kind", [(3, "stuck"), (3, "bias"), (2, "stuck")])
def test_in_flight_fault_named_from_the_disagreement(imus, kind):
    # a bias above the disagreement floor (5 deg/s + 10 % of the rms rate of the flight)
    fault = Fault(kind, at=300.0, size=0.0 if kind == "stuck" else 10.0 * DEG, imu=imus - 1, axis="gx")
    sched = Schedule(flights=(Flight(240.0, 600.0),))
    # the two three-IMU cases share their first 290 s (the two-IMU one has no partner: replayed whole)
    p, sink = (run_faulty(312.0, fault, imus=imus, schedule=sched, prefix_s=290.0) if imus == 3 else
               run(312.0, imus=imus, fault=fault, schedule=sched))
    texts = fault_texts(sink)
    odd = imus - 1
    others = "/".join(f"IMU{k}" for k in range(imus) if k != odd)
    assert (MAV_SEVERITY_CRITICAL, f"IMU{odd} gyro X disagrees with {others}") in texts
    if kind == "stuck":
        assert (MAV_SEVERITY_CRITICAL, f"IMU{odd} gyro X stuck") in texts
        # both faults at once: the code is the most severe, the mask holds both
        assert sink.values[f"IMU{odd}G_FLT"] == KIND_CODE["stuck"]
        assert sink.values[f"IMU{odd}G_FLM"] == (1 << KIND_CODE["stuck"]) | (1 << KIND_CODE["disagree"])
    assert not any(t.startswith("IMU0") for _, t in texts if imus == 3)
    assert sink.values[f"IMU{odd}G_HLTH"] == 1.0
    t_first = min(t for t, text in p.transitions if text.startswith(f"IMU{odd}"))
    assert t_first - 301.0 <= 10.0


def test_fault_state_survives_a_restart():
    p, sink = run_faulty(300.0, Fault("stuck", at=260.0, size=0.0, axis="gx"))
    state = p.state_dict()
    sink2 = RecordingSink()
    p2 = Pipeline(PipelineConfig(baseline_s=200.0), Reporter(sink2, 1.0))
    p2.load_state_dict(state)
    ch = p2.channels[0]
    assert ch.faults.active()[0] == ("stuck", "gx")  # the most severe first
    assert ch.faults.noise_ref("gy") is not None and p2.health(ch) == 1  # the still references kept


@pytest.mark.parametrize("seed, at, size_deg", [(1, 280.5, 1.0), (2, 280.3, -1.5)])
def test_bias_jump_size_is_reported_within_10_percent_once_confirmed(seed, at, size_deg):
    """A step part-way into a block is first sized from that block (a fraction of the step); once
    confirmed the STATUSTEXT says the size again and the summary quotes it, both within 10 % of the step."""
    import re

    fault = Fault("bias", at=at, size=size_deg * DEG, axis="gy")
    p, sink = run_faulty(330.0, fault) if seed == 1 else run(330.0, fault=fault, seed=seed)
    said = [float(m.group(1)) for _, t in fault_texts(sink) for m in [re.match(r"IMU0 gyro Y bias jump ([-+]\d+\.\d+) deg/s$", t)] if m]
    assert said, fault_texts(sink)
    assert said[-1] == pytest.approx(size_deg, rel=0.10), said
    out = io.StringIO()
    print_summary(p, out)
    m = re.search(r"FAULT: IMU0 gyro Y bias jump ([-+]\d+\.\d+) deg/s", out.getvalue())
    assert m and float(m.group(1)) == pytest.approx(size_deg, rel=0.10), out.getvalue()
