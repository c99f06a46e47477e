"""`run`'s in-flight figures (service/inflight_live.py) against `analyze`'s (analysis/inflight.py) on the same
simulated flights written as DataFlash logs: the same method (the whole flight, the offline cluster time with
the filters' shape divided out, the three-cornered hat), so each IMU's N agrees with the offline one within
their intervals and both with the truth."""

from __future__ import annotations

import contextlib
import io
import json
import math

import numpy as np
import pytest

from companion.cli.main import main
from companion.mavlink.reporter import Reporter
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.replay import replay_log
from companion.sim.dataflash_writer import write_imu_log
from companion.sim.vehicle import Flight, Schedule, VehicleSimulator
from tests.support.sinks import RecordingSink

N_TRUE = 2.0e-4
MODEL = {"rate_hz": 100.0, "axes": {a: [{"effect": "white_noise", "N": N_TRUE},
                                       {"effect": "bias_instability", "B": 2.0e-5}] for a in ("gx", "gy", "gz")}}


def _log(path, seed):
    sim = VehicleSimulator(MODEL, imus=3, seed=seed, schedule=Schedule(flights=(Flight(30.0, 430.0, max_rate=1.0),)))
    blk = sim.run(450.0)
    k = np.flatnonzero(np.diff(blk.armed.astype(int)))
    events = [(float(blk.t[i + 1]), bool(blk.armed[i + 1])) for i in k]
    write_imu_log(path, blk.t, np.array(blk.gyro), np.array(blk.accel), layout="4.x", armed=events)


def _offline(path, tmp_path):
    out = tmp_path / "r.json"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["analyze", str(path), "--quiet", "--json", str(out)]) == 0
    got = {}
    for st in json.loads(out.read_text())["streams"]:
        for ax, e in st["flight"]["axes"].items():
            (w,) = [t for t in e["terms"] if t["effect"] == "white_noise"]
            got[(st["instance"], ax)] = (w["N"], *w["ci95"]["N"])
    return got


@pytest.mark.parametrize("seed", [3, pytest.param(4, marks=pytest.mark.soak), pytest.param(5, marks=pytest.mark.soak)])
def test_live_figures_agree_with_analyze(seed, tmp_path):
    path = tmp_path / "flight.bin"
    _log(path, seed)
    off = _offline(path, tmp_path)
    p = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
    replay_log(path, p)
    live = p.inflight.noise.figures["flight"]
    assert sorted(live) == [0, 1, 2] and len(off) == 9
    outside = 0
    for imu in range(3):
        for ax in ("gx", "gy", "gz"):
            n1, s1, bound = live[imu][ax]
            n0, lo, hi = off[(imu, ax)]
            assert not bound and abs(n1 / N_TRUE - 1.0) < 0.15, (imu, ax, n1)
            outside += abs(n1 - n0) > math.hypot(1.96 * s1, 0.5 * (hi - lo))
    assert outside <= 1  # 9 axes, each within its 95 % intervals
