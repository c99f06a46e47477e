"""`companion simulate --vehicle` and the vehicle/fault options of `companion sim-autopilot`: what they write,
and one error line for every bad combination (checked before any file or socket is opened)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from companion.cli.main import main

MODEL = """rate_hz: 100
axes:
  gx: [{effect: white_noise, N: 3.0e-3}]
  gy: [{effect: white_noise, N: 3.0e-3}]
  gz: [{effect: white_noise, N: 3.0e-3}]
"""


def test_simulate_vehicle_writes_the_imus_heartbeats_and_the_fault(tmp_path, capsys):
    from companion.sim.model import load_model
    from companion.sim.vehicle import Fault, Flight, Schedule, VehicleSimulator
    from companion.sources import load
    from tests.support.pymavlink_reference import pymavlink_messages

    (tmp_path / "m.yaml").write_text(MODEL)
    out = tmp_path / "v.tlog"
    rc = main(["simulate", str(tmp_path / "m.yaml"), "--duration", "90", "--out", str(out), "--vehicle", "--imus", "3",
               "--arm-at", "30", "--disarm-at", "70", "--fault", "bias", "--fault-at", "50", "--fault-size", "0.02",
               "--fault-imu", "2", "--fault-axis", "gz", "--seed", "4"])
    assert rc == 0
    said = capsys.readouterr().out
    assert "9000 RAW_IMU + 9000 SCALED_IMU2 + 9000 SCALED_IMU3 and 90 HEARTBEAT" in said and "IMU2 gz bias" in said
    truth = VehicleSimulator(load_model(tmp_path / "m.yaml"), imus=3, seed=4, schedule=Schedule(flights=(Flight(30, 70),)),
                             fault=Fault("bias", 50, 0.02, imu=2, axis="gz")).run(90)
    streams = {s.key.instance: s for s in load(str(out)).imu_streams()}
    assert sorted(streams) == [0, 1, 2]
    for i in range(3):
        assert np.array_equal(streams[i].gyro, np.rint(truth.gyro[i] / 1e-3) * 1e-3)
    armed = [bool(m.base_mode & 128) for m in pymavlink_messages(out) if m.get_type() == "HEARTBEAT"]
    assert armed == [30 <= k < 70 for k in range(90)]


@pytest.mark.parametrize("argv, msg", [
    (["--fault", "stuck"], "--fault needs --fault-at"),
    (["--fault-size", "2"], "--fault-size needs --fault"),
    (["--fault", "bias", "--fault-at", "5", "--fault-imu", "1"], "raise --imus"),
    (["--fault", "spikes", "--fault-at", "5", "--fault-size", "2"], "--fault-size"),
    (["--fault", "saturate", "--fault-at", "5", "--fault-size", "0"], "> 0"),
    (["--arm-at", "10", "--disarm-at", "12"], "at least 4 s"),
    (["--arm-at", "10", "--disarm-at", "40", "--arm-s", "30"], "not both"),
    (["--disarm-at", "5"], "--disarm-at needs --arm-at"),
    (["--imus", "4"], "1, 2 or 3"),
    (["--arm-at", "10", "--disarm-at", "100", "--handle-at", "50"], "overlaps"),
    (["--warmup-deg-s", "-1"], "--warmup-deg-s"),
    (["--scale-spread", "0.5"], "scale-factor"),
])
def test_bad_vehicle_options_give_one_line(argv, msg, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.yaml").write_text(MODEL)
    for cmd in (["sim-autopilot", "--model", "m.yaml", "--connect", "udpout:127.0.0.1:9", "--duration", "1"],
                ["simulate", "m.yaml", "--duration", "10", "--out", "x.tlog", "--vehicle"]):
        rc = main(cmd + argv)
        err = capsys.readouterr().err
        assert rc == 2 and msg in err and len(err.strip().splitlines()) == 1, (cmd, err)
    assert not (tmp_path / "x.tlog").exists()


def test_simulate_without_vehicle_refuses_vehicle_options(tmp_path, capsys):
    (tmp_path / "m.yaml").write_text(MODEL)
    rc = main(["simulate", str(tmp_path / "m.yaml"), "--duration", "10", "--out", str(tmp_path / "x.tlog"), "--imus", "2"])
    assert rc == 2 and "--imus needs --vehicle" in capsys.readouterr().err


def test_vehicle_tlog_replayed_by_run_sees_the_flight_as_motion(tmp_path, capsys):
    """`run --source` on a simulated vehicle tlog: both IMUs decoded, the armed flight (HEARTBEAT armed bit)
    and the handling are not learned from (moving blocks), the rest is; no flag on the healthy vehicle."""
    (tmp_path / "m.yaml").write_text(MODEL)
    out = tmp_path / "v.tlog"
    assert main(["simulate", str(tmp_path / "m.yaml"), "--duration", "400", "--out", str(out), "--vehicle", "--imus", "2",
                 "--handle-at", "100", "--handle-s", "20", "--arm-at", "200", "--disarm-at", "320", "--seed", "2"]) == 0
    capsys.readouterr()
    assert main(["run", "--source", str(out), "--baseline-s", "60", "--quiet", "--no-state"]) == 0
    said = capsys.readouterr().out
    rows = re.findall(r"^IMU(\d) \((\w+), 100.0 Hz\): (\w+); (\d+) s still data used; (\d+) samples, (\d+) moving blocks", said, re.M)
    assert [(r[0], r[1]) for r in rows] == [("0", "RAW_IMU"), ("1", "SCALED_IMU2")], said
    for _, _, health, still_s, samples, moving in rows:
        assert health == "healthy" and int(samples) == 40_000
        assert 120 + 10 <= int(moving) <= 120 + 20 + 2 * 12  # flight, handling, look-ahead/settling edges
        assert 200 <= int(still_s) <= 400 - 120 - 20
