"""A gyro frozen in flight (docs/vehicle.md's stuck example, shortened): `analyze` names it with its span and
exit status 4 and leaves its span out of the flight figures, `fleet` flags it, `run` names only that IMU (the
in-flight noise test suspends its pairs instead of naming the healthy twin); the same flight without the fault
stays silent in all three."""

from __future__ import annotations

import json
import re

import pytest

from companion.cli.main import main
from companion.errors import EXIT_FAULTS

FLIGHT = ["--duration", "440", "--vehicle", "--imus", "2", "--arm-at", "60", "--disarm-at", "420"]
FAULT = ["--fault", "stuck", "--fault-at", "340", "--fault-imu", "1"]  # after the in-flight baseline (240 s)


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("frozen")
    assert main(["example", "model", "--out", str(d / "model.yaml")]) == 0
    out = {}
    for name, extra in (("stuck", FAULT), ("healthy", [])):
        out[name] = str(d / f"{name}.tlog")
        assert main(["simulate", str(d / "model.yaml"), "--out", out[name], *FLIGHT, *extra]) == 0
    return d, out


def _n(entry: dict, cond: str, ax: str) -> float:
    axis = entry[cond]["axes"][ax] if cond else entry["axes"][ax]
    return next(t["N"] for t in list(axis.get("terms", [])) + list(axis.get("bounds", []))
                if t["effect"] == "white_noise")


def test_analyze_names_the_gyro_frozen_in_flight_and_its_span(logs, capsys):
    d, tl = logs
    capsys.readouterr()
    rc = main(["analyze", tl["stuck"], "--axes", "gx,gy,gz", "--json", str(d / "stuck.json")])
    err = capsys.readouterr().err
    assert rc == EXIT_FAULTS
    said = re.search(r"SCALED_IMU2\[1\] sys1/comp1: gyro X frozen: .* from (\d+) to (\d+) s", err)
    assert said, err
    assert 338 <= int(said.group(1)) <= 345 and int(said.group(2)) >= 435  # frozen from 340 s to the end
    assert "RAW_IMU[0] sys1/comp1: gyro" not in err and "gyro Y frozen" not in err and "gyro Z frozen" not in err
    rep = json.loads((d / "stuck.json").read_text())
    for e in rep["streams"]:  # the twin's motion is not split onto either IMU: flight N near the still N
        assert any("frozen" in n for n in e["flight"]["notes"])
        for ax in ("gx", "gy", "gz"):
            assert _n(e, "flight", ax) < 3.0 * _n(rep["streams"][0], None, ax), (e["message"], ax)


def test_analyze_of_the_healthy_flight_names_nothing(logs, capsys):
    _, tl = logs
    capsys.readouterr()
    assert main(["analyze", tl["healthy"], "--axes", "gx,gy,gz"]) == 0
    assert "frozen:" not in capsys.readouterr().err


def test_fleet_flags_the_frozen_gyro_only(logs):
    from companion.fleet.task import FAULT_STATUSES, analyze_log

    _, tl = logs
    rows = analyze_log(tl["stuck"])["rows"]
    flagged = {(r["imu"], r["axis"], r["status"]) for r in rows if r["status"] in FAULT_STATUSES}
    assert flagged == {(1, "gx", "stuck")}
    assert not [r for r in analyze_log(tl["healthy"])["rows"] if r["status"] in FAULT_STATUSES]


def test_run_names_only_the_frozen_imu(logs, capsys):
    _, tl = logs
    capsys.readouterr()
    rc = main(["run", "--source", tl["stuck"], "--baseline-s", "40"])
    out = capsys.readouterr()
    text = out.out + out.err
    assert rc == EXIT_FAULTS
    assert "IMU1 gyro X stuck" in text
    assert not re.search(r"at \d+ s: IMU0 ", text), text  # nothing said of the healthy twin
    assert re.search(r"IMU0 \(RAW_IMU, 50.0 Hz\): healthy", text)
    assert "noise changed" not in text


def test_run_of_the_healthy_flight_names_nothing(logs, capsys):
    _, tl = logs
    capsys.readouterr()
    assert main(["run", "--source", tl["healthy"], "--baseline-s", "40"]) == 0
    out = capsys.readouterr()
    assert not re.search(r"at \d+ s: IMU", out.out + out.err)
