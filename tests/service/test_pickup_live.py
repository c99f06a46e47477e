"""`run`'s vibration pick-up test (companion/service/pickup_hook.py, companion/health/pickup.py) through the
whole pipeline: the PX4 preset's IMU0 Z, whose pick-up (0.63 of its twins') doubles in flight, named by a
STATUSTEXT within 120 s with its health set; the pick-up baseline kept in the state file."""

from __future__ import annotations

from companion.mavlink.reporter import Reporter
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.replay import replay_vehicle
from companion.sim.preset import load_preset
from companion.sim.vehicle import Fault, Flight, Schedule, VehicleSimulator
from tests.support.sinks import RecordingSink


def test_px4_pickup_named_by_run_and_kept_in_state():
    P = load_preset("px4")
    at = 30.0 + 340.0
    sim = VehicleSimulator(P["model"], imus=3, seed=100, rate_hz=250.0, realism=P["realism"],
                           schedule=Schedule(flights=(Flight(30.0, 560.0, max_rate=1.0),)),
                           fault=Fault("flight_noise", at=at, size=2.0, imu=0, axis="gz"))
    sink = RecordingSink()
    p = Pipeline(PipelineConfig(), Reporter(sink, 1.0))
    replay_vehicle(sim, p, at + 130.0, lsb=1e-3)
    named = [(t, x) for t, x in p.transitions if "vibration pick-up" in x]
    assert named and named[0][1].startswith("IMU0 gyro Z vibration pick-up ") and named[0][1].endswith("x vs twins")
    assert named[0][0] - (sim.t_start + at) <= 120.0, named
    assert all(x.startswith("IMU0 gyro Z") for _, x in named), named
    assert any(x == named[0][1] for _, x in sink.texts)
    assert p.health(p.channels[0]) == 1 and p.health(p.channels[1]) != 1
    d = p.state_dict()
    assert set(d["inflight"]["pickup"]["pairs"]) == {"0-1", "0-2", "1-2"}
    q = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
    q.load_state_dict(d)
    assert q.inflight.pickup.watch.base.keys() == p.inflight.pickup.watch.base.keys()
