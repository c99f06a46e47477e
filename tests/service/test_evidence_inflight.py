"""The evidence of the alarms of the in-flight noise test (service/inflight_live.py) and of the sample-level
frozen watch (health/frozen_watch.py), against a simulated 3-IMU flight with the fault injected: the item of
the right IMU, axis and kind, its statistic crossing its threshold at the alarm, the twin IMUs' gyro, the
spectrum and the sentence."""

from __future__ import annotations


import numpy as np
import pytest

from companion.health.frozen_watch import NEED
from companion.mavlink.reporter import Reporter
from companion.service.inflight_live import InflightConfig, InflightTest
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.replay import replay_vehicle
from companion.sim.vehicle import Fault, Flight, Schedule, VehicleSimulator
from tests.support.sinks import RecordingSink

N_TRUE = 2.0e-4
MODEL = {"rate_hz": 100.0, "axes": {a: [{"effect": "white_noise", "N": N_TRUE},
                                       {"effect": "bias_instability", "B": 2.0e-5}] for a in ("gx", "gy", "gz")}}


class DeadFrom:
    """A simulator whose IMU ``imu`` axis ``axis`` reads exactly 0 from ``at`` s on (a dead gyro in flight)."""

    def __init__(self, sim, imu: int, axis: int, at: float):
        self.sim, self.imu, self.axis, self.at = sim, imu, axis, at

    def __getattr__(self, name):
        return getattr(self.sim, name)

    def take_until(self, t_end):
        blk = self.sim.take_until(t_end)
        if blk.n:
            blk.gyro[self.imu][blk.t >= self.at, self.axis] = 0.0
        return blk


def _fly(sim, duration):
    p = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
    replay_vehicle(sim, p, duration, lsb=1e-3)
    p.evidence.finish()
    return p


def _item(p, kind, imu, axis):
    """The first item of ``kind``; every item of that kind is of ``imu``, ``axis``."""
    items = [i for i in p.evidence.all_items() if i["kind"] == kind]
    assert items and {(i["imu"], i["axis"]) for i in items} == {(imu, axis)}, [i["text"] for i in
                                                                              p.evidence.all_items()]
    return items[0]


def _crosses(it, bar, hold_s):
    """The statistic is below ``bar`` in the window before the alarm, passes it at most ``hold_s`` before
    the alarm (the checks in a row a debounced test needs) and is at or above it at the alarm's block."""
    st = it["statistic"]
    t = np.array(st["t_s"], dtype=float)
    v = np.array([np.nan if x is None else x for x in st["value"]], dtype=float)
    below = t[(t < it["t_s"]) & (v < bar)]
    assert below.size and below[-1] >= it["t_s"] - hold_s, (it["t_s"], list(zip(t, v)))
    at = v[(t >= it["t_s"] - 1e-6) & (t <= it["t_s"] + 6.0)]
    assert at.size and np.nanmax(at) >= bar, (at, bar)
    assert np.allclose(st["threshold"], bar)


def _twins(it):
    roles = {s["imu"]: s["role"] for s in it["series"]}
    assert roles[it["imu"]] == "alarm" and sorted(i for i, r in roles.items() if r == "twin") == sorted(
        {0, 1, 2} - {it["imu"]})
    for s in it["series"]:
        assert len(s["t_s"]) > 100 and set(s["lo"]) == {"gx", "gy", "gz"}


def test_flight_noise_alarm_evidence():
    at, imu, axis = 450.0, 1, "gy"
    sim = VehicleSimulator(MODEL, imus=3, seed=21, schedule=Schedule(flights=(Flight(30.0, 680.0),)),
                           fault=Fault("flight_noise", at=at, size=2.0, imu=imu, axis=axis))
    p = _fly(sim, 700.0)
    it = _item(p, "flight_noise", imu, axis)
    assert at < it["t_s"] < at + 120 and "flight noise changed" in it["text"]
    assert it["statistic"]["key"] == "flight_noise/gy" and it["statistic"]["unit"] == "sigma"
    z_on = p.inflight.noise.z_on()
    assert 3.5 < z_on < 5.0 and z_on == round(z_on, 2)
    _crosses(it, z_on, (InflightTest().hold_on + 1) * InflightConfig().check_s + 1.0)
    _twins(it)
    assert it["spectrum"] and set(it["spectrum"]["psd"]) == {"gx", "gy", "gz"}
    assert "in flight" in it["sentence"] and "rose to" in it["sentence"] and f"beyond {z_on:g} standard deviations" in it["sentence"]


def test_dead_gyro_in_flight_evidence():
    at, imu = 200.0, 2
    sim = VehicleSimulator(MODEL, imus=3, seed=5, schedule=Schedule(flights=(Flight(30.0, 300.0),)))
    p = _fly(DeadFrom(sim, imu, 0, at), 320.0)
    it = _item(p, "dead", imu, "gx")
    assert at <= it["t_s"] < at + 10
    assert it["statistic"]["key"] == "frozen/gx" and it["statistic"]["unit"] == "pairs"
    _crosses(it, float(NEED), 2.0)
    _twins(it)
    alarm = next(s for s in it["series"] if s["role"] == "alarm")
    t = np.array(alarm["t_s"])
    after = (t > at + 1) & (t < at + 60)
    assert after.any() and not np.any(np.array(alarm["hi"]["gx"])[after]) and not np.any(
        np.array(alarm["lo"]["gx"])[after])
    assert "exactly 0" in it["sentence"] and "turning: dead" in it["sentence"]
