"""`companion gap` end to end: a simulated RAW_IMU tlog (int16 mrad/s) against a model without
quantisation, JSON / out-model / plot outputs, the null case, and one-line user errors."""

import json
import math

import numpy as np
import pytest
import yaml

from companion.cli.main import main
from companion.mavlink.tlog_writer import write_imu_tlog
from companion.sim.synth import synthesize_axis

RATE = 50.0


def _model_yaml(path, terms, rate=RATE):
    path.write_text(yaml.safe_dump({"rate_hz": rate, "axes": {"gx": terms, "gy": [{"effect": "white_noise", "N": 2e-4}]}}))
    return path


def _write_csv(path, y, rate):
    """The same rate samples on all three gyro axes of a companion CSV, accelerometer at rest."""
    t = np.arange(y.shape[0]) / rate
    np.savetxt(path, np.column_stack([t, y, y, y, 0 * t, 0 * t, 0 * t - 9.8]), delimiter=",",
               header="time_s,gx,gy,gz,ax,ay,az", comments="", fmt="%.9g")
    return path


@pytest.fixture(scope="module")
def raw_imu_tlog(tmp_path_factory):
    d = tmp_path_factory.mktemp("gap")
    n = int(3600 * RATE)
    terms = [{"effect": "white_noise", "N": 9e-5}, {"effect": "bias_instability", "B": 5e-5}]
    rng = np.random.default_rng(7)
    gyro = np.column_stack([synthesize_axis(terms, RATE, n, rng) for _ in range(3)])
    t = np.arange(n) / RATE
    accel = np.zeros((n, 3))
    accel[:, 2] = -9.80665
    path = d / "raw.tlog"
    write_imu_tlog(path, t, gyro, accel, message="RAW_IMU")
    return path, terms


def test_raw_imu_tlog_names_rate_quantization(raw_imu_tlog, tmp_path, capsys):
    tlog, terms = raw_imu_tlog
    model = _model_yaml(tmp_path / "m.yaml", terms)
    out_json, out_model, png = tmp_path / "g.json", tmp_path / "new.yaml", tmp_path / "g.png"
    rc = main(["gap", str(tlog), "--model", str(model), "--axis", "gx", "--json", str(out_json),
               "--out-model", str(out_model), "--plot", str(png)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "rate quantisation" in text and "gap before" in text and "gap after" in text
    for path in (png, out_json, out_model):  # every file written is named
        assert f"wrote {path}" in text.splitlines()
    assert "  evidence for " in text and " needed: " in text  # the test behind each iteration's choice
    doc = json.loads(out_json.read_text())
    test = doc["iterations"][0]["test"]
    assert test["inflation"] >= 1.0 and test["lr"] == pytest.approx(test["lr_raw"] / test["inflation"])
    assert {"axis", "gap_before", "gap_after", "added", "iterations"} <= set(doc)
    assert doc["axis"] == "gx"
    assert [a["effect"] for a in doc["added"]] == ["quantization"]
    assert doc["added"][0]["lsb"] == pytest.approx(1e-3)
    assert doc["gap_after"] < doc["gap_before"]
    new = yaml.safe_load(out_model.read_text())
    assert new["axes"]["gy"] == [{"effect": "white_noise", "N": 2e-4}]  # other axes unchanged
    # the log's rounding is a term of the measurement: gap derives it from the log again, the sensor's
    # model does not carry it (tests/cli/test_gap_out_model.py: the round trip)
    nq = 1e-3 * math.sqrt(1 / (12 * RATE))
    assert {"effect": "white_noise", "N": pytest.approx(nq)} not in new["axes"]["gx"]
    assert new["rate_hz"] == RATE
    assert png.stat().st_size > 10_000


def test_model_that_fits_adds_nothing(tmp_path, capsys):
    n = int(1800 * 20)
    terms = [{"effect": "white_noise", "N": 1e-3}, {"effect": "random_walk", "K": 1e-5}]
    y = synthesize_axis(terms, 20.0, n, np.random.default_rng(3))
    csv = _write_csv(tmp_path / "d.csv", y, 20.0)
    model = _model_yaml(tmp_path / "m.yaml", terms, rate=20.0)
    assert main(["gap", str(csv), "--model", str(model), "--axis", "gx", "--json", "-"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["added"] == [] and doc["fits_within_noise"] is True
    assert doc["gap_after"] == doc["gap_before"]


@pytest.mark.parametrize("args,msg", [
    (["--axis", "gz"], "no terms for axis gz"),
    (["--axis", "gx", "--lsb", "-1"], "--lsb must be a positive number"),
])
def test_user_errors_are_one_line(raw_imu_tlog, tmp_path, capsys, args, msg):
    tlog, terms = raw_imu_tlog
    model = _model_yaml(tmp_path / "m.yaml", terms)
    assert main(["gap", str(tlog), "--model", str(model)] + args) == 2
    err = capsys.readouterr().err
    assert msg in err and err.count("\n") == 1


def test_datasheet_on_an_accel_axis_names_the_datasheet(tmp_path, capsys):
    # the data file does not exist: the axis is refused before the data are read
    assert main(["gap", str(tmp_path / "x.tlog"), "--datasheet", "MPU-6000", "--axis", "ax"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "None" not in err
    assert "datasheet MPU-6000: no terms for axis ax" in err and "gyro-only" in err


def test_missing_model_file(tmp_path, capsys):
    assert main(["gap", str(tmp_path / "x.csv"), "--model", str(tmp_path / "none.yaml"), "--axis", "gx"]) == 2
    assert "none.yaml" in capsys.readouterr().err


def test_report_gives_the_gauss_markov_alternative(tmp_path, capsys):
    """A Gauss-Markov with tau_c = T/24 (seed 1000, as in test_gap_workflow) reaches the user as a random walk
    plus the alternative, with the nested test that decided it printed."""
    n = int(7200 * 20)
    base = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 1e-4}]
    y = synthesize_axis(base + [{"effect": "gauss_markov", "sigma": 5e-4, "tau_c": 300.0}], 20.0, n,
                        np.random.default_rng(1000))
    csv = _write_csv(tmp_path / "d.csv", y, 20.0)
    model = _model_yaml(tmp_path / "m.yaml", base, rate=20.0)
    assert main(["gap", str(csv), "--model", str(model), "--axis", "gx"]) == 0
    text = capsys.readouterr().out
    assert "gauss_markov vs its random_walk limit: LR" in text and "random_walk kept" in text
    assert "added: random_walk" in text and "too short to tell a slow correlated bias" in text
    assert "explanations by score" in text and "  runner-up " in text  # weighed head to head, runner-up shown
