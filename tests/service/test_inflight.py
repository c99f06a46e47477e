"""`run`'s in-flight noise (companion/service/inflight_live.py, estimators/pair_calibration.py) against known truth:
the running relative calibration recovers a drawn scale/misalignment, bias and time offset; on the simulated
vehicle each IMU's in-flight N comes out at the model's; a doubled noise on one IMU is named within 120 s and
no other IMU is; the baseline survives the state file and a state file without it still loads."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from companion.estimators.pair_calibration import PairCalibration
from companion.mavlink.reporter import NAME_RE, Reporter
from companion.service.inflight_report import inflight_name
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.replay import replay_vehicle
from companion.sim.vehicle import Fault, Flight, Schedule, VehicleSimulator
from tests.support.sinks import RecordingSink

N_TRUE = 2.0e-4  # rad/s/sqrt(Hz): 2 LSB per sample at 100 Hz
MODEL = {"rate_hz": 100.0, "axes": {a: [{"effect": "white_noise", "N": N_TRUE},
                                       {"effect": "bias_instability", "B": 2.0e-5}] for a in ("gx", "gy", "gz")}}


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_pair_calibration_recovers_drawn_truth(seed):
    rng = np.random.default_rng(seed)
    fs, T = 200.0, 120.0
    t = np.arange(int(T * fs)) / fs

    def motion(tt):  # smooth body rates, ~1 rad/s, a few sinusoids per axis
        return np.column_stack([sum(0.4 * np.sin(2 * np.pi * f * tt + ph) for f, ph in zip(fr, phs))
                                for fr, phs in (rng_f, rng_f2, rng_f3)])

    rng_f, rng_f2, rng_f3 = ((rng.uniform(0.1, 2.0, 3), rng.uniform(0, 6, 3)) for _ in range(3))
    M = np.eye(3) + rng.uniform(-0.005, 0.005, (3, 3))
    b = rng.normal(0, 2e-3, 3)
    d = rng.uniform(-2e-3, 2e-3)
    sig = 3e-3
    gj = motion(t) + rng.normal(0, sig, (t.size, 3))
    gi = motion(t + d) @ M.T + b + rng.normal(0, sig, (t.size, 3))
    cal = PairCalibration(memory_s=1e9)
    res = [cal.update(t[k:k + 200], gi[k:k + 200], gj[k:k + 200]) for k in range(0, t.size, 200)]
    np.testing.assert_allclose(cal.matrix, M, atol=5e-4)
    np.testing.assert_allclose(cal.bias, b, atol=2e-4)
    np.testing.assert_allclose(cal.time_offset, d, atol=2e-4)
    e = np.concatenate([r for r in res if r is not None])
    # what is left is the two IMUs' noise: sig^2 (1 + |M row|^2)
    expect = sig * np.sqrt(1.0 + np.sum(M * M, axis=1))
    np.testing.assert_allclose(e[len(e) // 2:].std(axis=0), expect, rtol=0.05)


def _fly(seed, fault=None, imus=3, duration=700.0):
    sim = VehicleSimulator(MODEL, imus=imus, seed=seed, schedule=Schedule(flights=(Flight(30.0, duration - 20.0),)),
                           fault=fault)
    sink = RecordingSink()
    p = Pipeline(PipelineConfig(), Reporter(sink, 1.0))
    replay_vehicle(sim, p, duration, lsb=1e-3)
    return p, sink


@functools.lru_cache(maxsize=None)
def healthy(seed):
    return _fly(seed)


@pytest.mark.parametrize("seed", [11, pytest.param(12, marks=pytest.mark.soak)])
def test_inflight_n_per_imu_matches_the_model(seed):
    p, _ = healthy(seed)
    learned = p.inflight.noise.baseline["flight"]["imus"]  # 240 s of flight, no forgetting
    now = p.inflight.noise.figures["flight"]  # the last 30 s memory
    assert sorted(learned) == sorted(now) == [0, 1, 2]
    for imu in range(3):
        for ax in ("gx", "gy", "gz"):
            n, s, bound = learned[imu][ax]
            assert not bound and abs(n / N_TRUE - 1.0) < 0.10, (imu, ax, n)
            n, s, bound = now[imu][ax]
            assert not bound and 0 < s < 0.1 * n and abs(n - N_TRUE) < 4 * s, (imu, ax, n, s)
    # the figures go out under their names, next to the at-rest ones (not removed by them)
    assert p.reporter.values["IMU1GYFN"] == pytest.approx(p.inflight.noise.figures["flight"][1]["gy"][0]
                                                          * 180 / math.pi * 60, rel=1e-9)
    assert "IMU1GYFNS" in p.reporter.values


@pytest.mark.parametrize("seed", [11, pytest.param(12, marks=pytest.mark.soak)])
def test_healthy_flight_names_nobody(seed):
    p, _ = healthy(seed)
    assert p.inflight.noise.baseline["flight"], "the in-flight baseline was learned"
    assert not [x for _, x in p.transitions if "noise changed" in x]
    assert not any(p.inflight.degrading(i) for i in range(3))


@pytest.mark.parametrize("seed,imu,axis", [(21, 1, "gy"), pytest.param(22, 2, "gx", marks=pytest.mark.soak)])
def test_doubled_noise_named_within_120_s_others_silent(seed, imu, axis):
    at = 450.0
    p, sink = _fly(seed, Fault("noise", at=at, size=2.0, imu=imu, axis=axis))
    named = [(t, x) for t, x in p.transitions if "noise changed" in x]
    want = f"IMU{imu} gyro {axis[1].upper()} flight noise changed"
    hits = [t for t, x in named if want in x]
    assert hits and hits[0] - (1.0 + at) <= 120.0, named
    assert all(want in x for _, x in named), named
    assert p.health(p.channels[imu]) == 1
    assert any(want in text for _, text in sink.texts)


def test_two_imus_pair_figure_bounds_each():
    p, _ = _fly(31, imus=2, duration=400.0)
    assert list(p.inflight.noise.figures["flight"]) == [(0, 1)]
    (who, axes), = p.inflight.noise.baseline["flight"]["imus"].items()  # 240 s of flight, no forgetting
    assert who == (0, 1)
    for ax, (n, s, _) in axes.items():  # the pair's N = sqrt(N0^2 + N1^2)
        assert abs(n / (math.sqrt(2) * N_TRUE) - 1.0) < 0.10
    assert p.reporter.values["IMU0GXFNS"] == -1.0 and p.reporter.values["IMU1GXFNS"] == -1.0


def test_baseline_kept_in_state_and_old_state_loads():
    p, _ = healthy(11)
    d = p.state_dict()
    assert d["version"] == 2
    q = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
    q.load_state_dict(d)
    assert q.inflight.noise.baseline == p.inflight.noise.baseline
    old = {k: v for k, v in d.items() if k != "inflight"}
    old["version"] = 1
    r = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
    r.load_state_dict(old)
    assert r.inflight.noise.baseline == {"ground": {}, "flight": {}}


def test_names_fit_mavlink():
    for imu in range(3):
        for ax in ("gx", "gy", "gz"):
            for cond in ("flight", "ground"):
                for sigma in (False, True):
                    assert NAME_RE.match(inflight_name(imu, ax, cond, sigma))
    assert inflight_name(2, "gz", "flight", True) == "IMU2GZFNS"
