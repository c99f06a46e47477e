"""The per-log task is `companion analyze`'s analysis; failures come back as one-line reasons."""

from __future__ import annotations

import json

import pytest

from companion.cli.main import main
from companion.fleet.discover import discover, hash_file
from companion.fleet.synthetic_fleet import simulate_fleet
from companion.fleet.task import analyze_log
from companion.errors import CompanionError


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet")
    truth = simulate_fleet(d, 2, 2, imus=2, degrading=1, duration_s=40, rate_hz=50, seed=5)
    return d, truth


def test_same_numbers_as_companion_analyze(fleet, tmp_path, capsys):
    d, truth = fleet
    log = str(d / truth["logs"][0]["path"])
    res = analyze_log(log)
    assert res["status"] == "ok", res["error"]
    out = tmp_path / "a.json"
    assert main(["analyze", log, "--axes", "gx,gy,gz", "--json", str(out)]) == 0
    rep = json.loads(out.read_text())
    rows = {(r["message"], r["imu"], r["axis"]): r for r in res["rows"]}
    assert len(rows) == 6
    for st in rep["streams"]:
        for axis, r in st["axes"].items():
            row = rows[(st["message"], st["instance"], axis)]
            terms = {t["effect"]: t for t in r["terms"]}
            assert row["N"] == terms["white_noise"]["N"]
            assert [row["N_lo"], row["N_hi"]] == terms["white_noise"]["ci95"]["N"]
            assert row["still_s"] == st["duration_s"] and row["rate_hz"] == st["rate_hz"]
    veh = truth["vehicles"][0]
    assert res["log"]["vehicle"] == veh["board_id"] and res["log"]["sysid"] == veh["sysid"]
    assert res["log"]["imu_ids"] == {i["imu"]: i["gyro_id"] for i in veh["imus"]}
    assert abs(res["log"]["start_time"] - truth["logs"][0]["start_time"]) < 0.01
    assert all(15 <= r["temp_min"] <= r["temp_max"] <= 41 for r in res["rows"])


def test_simulated_parameters_recovered(fleet):
    d, truth = fleet
    res = analyze_log(str(d / truth["logs"][1]["path"]))
    veh = truth["vehicles"][0]
    hits = 0
    for r in res["rows"]:
        n_true = veh["imus"][r["imu"]]["axes"][r["axis"]]["N"]
        if veh["imus"][r["imu"]]["degrading"]:
            n_true *= 1.5  # flight 1 of 2 is the last one
        hits += r["N_lo"] <= n_true <= r["N_hi"]
    assert hits >= 4  # 95 % intervals, 6 axes (the 1-mrad/s rounding adds a little white noise)


@pytest.mark.parametrize("content, reason", [
    (b"", "empty file (0 bytes)"),
    (b"\x00garbage" * 1000, "no IMU messages"),
])
def test_bad_log_fails_with_one_line(tmp_path, content, reason):
    p = tmp_path / "bad.tlog"
    p.write_bytes(content)
    res = analyze_log(str(p))
    assert res["status"] == "failed" and reason in res["error"] and "\n" not in res["error"]
    assert res["rows"] == []


def test_missing_file_and_csv(tmp_path):
    res = analyze_log(str(tmp_path / "nope.tlog"))
    assert res["status"] == "failed" and "no such file" in res["error"]
    csv = tmp_path / "x.csv"
    csv.write_text("time_s,gx,gy\n0,1,2\n")
    res = analyze_log(str(csv))
    assert res["status"] == "failed" and "missing column" in res["error"]


def test_discover_files_folders_globs(fleet, tmp_path):
    d, truth = fleet
    logs = discover([str(d)])
    assert len(logs) == len(truth["logs"])
    assert [x.path for x in discover([str(d / "*" / "flight_000.tlog")])] == sorted(
        str((d / x["path"]).resolve()) for x in truth["logs"] if x["flight"] == 0)
    assert len(discover([str(d), str(d / truth["logs"][0]["path"])])) == len(logs)  # no duplicates
    assert hash_file(logs[0].path) != hash_file(logs[1].path)
    for bad in ([str(tmp_path / "missing")], [str(tmp_path / "*.tlog")], [str(tmp_path)]):
        with pytest.raises(CompanionError):
            discover(bad)
