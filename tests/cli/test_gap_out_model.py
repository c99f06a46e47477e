"""`companion gap --out-model` round trip: the model written is the sensor's, at the data's rate, and gap
run again with it on the same log gives the first run's "after" gap.

Data: a known sensor (white N, bias instability, a hidden Gauss-Markov term) at 100 Hz, written as an
ArduPilot RAW_IMU tlog (int16 mrad/s: the rounding adds white N_q = 1e-3 sqrt(1 / (12 x 100)) = 2.9e-5,
17 % of the sensor's N^2); the model handed to gap is at 50 Hz and lacks the Gauss-Markov term."""

import json
import math

import numpy as np
import pytest

from companion.allan.adev import oavar
from companion.cli.main import main
from companion.mavlink.tlog_writer import write_imu_tlog
from companion.sim.model import NoiseModel, load_model, save_model
from companion.sim.synth import synthesize_axis
from companion.sources import load

RATE = 100.0
LSB = 1e-3
N_Q = LSB * math.sqrt(1.0 / (12.0 * RATE))


def _tlog(path, terms, seconds, seed):
    n = int(seconds * RATE)
    rng = np.random.default_rng(seed)
    gyro = np.column_stack([synthesize_axis(terms, RATE, n, rng) for _ in range(3)])
    acc = np.zeros((n, 3))
    acc[:, 2] = -9.80665
    write_imu_tlog(path, np.arange(n) / RATE, gyro, acc, message="RAW_IMU")
    return path


def _gap(capsys, data, model, out_json, out_model=None):
    args = ["gap", str(data), "--model", str(model), "--axis", "gx", "--json", str(out_json)]
    assert main(args + (["--out-model", str(out_model)] if out_model else [])) == 0
    return capsys.readouterr().out, json.loads(out_json.read_text())


def _white_n(path):
    """N of the log's gx from its shortest cluster times (ADEV sqrt(tau) at 4-8 samples, where the white
    noise dominates here), and the log's rate."""
    st = load(str(path)).streams[0]
    tau, avar, _, _ = oavar(st.axis("gx"), st.rate_hz, m=np.array([4, 8]))
    return float(np.sqrt(np.mean(avar * tau))), st.rate_hz


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    d = tmp_path_factory.mktemp("outmodel")
    sensor = [{"effect": "white_noise", "N": 7e-5}, {"effect": "bias_instability", "B": 2e-5}]
    data = _tlog(d / "x.tlog", sensor + [{"effect": "gauss_markov", "sigma": 2e-4, "tau_c": 10.0}], 900, 11)
    model = d / "m.yaml"
    save_model(NoiseModel(rate_hz=50.0, axes={"gx": sensor, "gy": [{"effect": "white_noise", "N": 2e-4}]}), model)
    return d, data, model


def test_written_model_is_the_sensors_at_the_datas_rate(case, capsys):
    d, data, model = case
    text, first = _gap(capsys, data, model, d / "r1.json", d / "new.yaml")
    assert [a["effect"] for a in first["added"]] == ["quantization", "gauss_markov"]
    new = load_model(d / "new.yaml")
    assert new.rate_hz == RATE  # the data's rate, not the input model's 50 Hz
    assert new.axes["gy"] == [{"effect": "white_noise", "N": 2e-4}]  # other axes unchanged
    whites = [t["N"] for t in new.axes["gx"] if t["effect"] == "white_noise"]
    # the sensor's white noise only: the log's rounding N_q is not in it (with it the level was 8 % high)
    assert len(whites) == 1 and whites[0] == pytest.approx(7e-5, rel=0.03)
    assert "not written: gx: rate rounding to the log's LSB 0.001" in text

    # gap run again with the written model on the same log: the first run's "after"
    text2, second = _gap(capsys, data, d / "new.yaml", d / "r2.json")
    assert f"gap after: G = {first['gap_after']:.3g};" in text2
    assert second["gap_after"] == pytest.approx(first["gap_after"], rel=1e-9)
    assert [a["effect"] for a in second["added"]] == ["quantization"]  # the log's rounding, derived again
    assert not [r for r in second["recalibrated"] if r["verdict"] != "consistent"]


def test_simulating_the_written_model_gives_the_logs_white_level(case, capsys, tmp_path):
    """`companion simulate` of the written model as RAW_IMU rounds its output like the log: the rounding is
    in the simulated log once, at the log's rate (written with N_q and at 50 Hz, it was counted twice at
    the wrong rate)."""
    d, data, model = case
    _gap(capsys, data, model, tmp_path / "r.json", tmp_path / "new.yaml")
    sim = tmp_path / "sim.tlog"
    assert main(["simulate", str(tmp_path / "new.yaml"), "--duration", "300", "--out", str(sim), "--seed", "4"]) == 0
    n_log, rate_log = _white_n(data)
    n_sim, rate_sim = _white_n(sim)
    assert rate_sim == pytest.approx(rate_log, rel=1e-3)
    assert math.hypot(7e-5, N_Q) == pytest.approx(n_log, rel=0.03)  # the log: sensor + its rounding
    assert n_sim == pytest.approx(n_log, rel=0.03)


def test_rounding_that_a_rerun_cannot_derive_is_written(tmp_path, capsys):
    """A rounding term that passed its level only beside a model N that was then recalibrated (N 0.8x the
    sensor's) falls short of it against the written terms: it is written as its white term, and the re-run
    reproduces the first run's gap without adding it twice."""
    sensor = [{"effect": "white_noise", "N": 1.5e-4}, {"effect": "bias_instability", "B": 2e-5}]
    data = _tlog(tmp_path / "x.tlog", sensor, 600, 3)
    model = tmp_path / "m.yaml"
    save_model(NoiseModel(rate_hz=50.0, axes={"gx": [dict(sensor[0], N=1.2e-4), sensor[1]]}), model)
    _, first = _gap(capsys, data, model, tmp_path / "r1.json", tmp_path / "new.yaml")
    assert "quantization" in [a["effect"] for a in first["added"]]
    new = load_model(tmp_path / "new.yaml")
    assert {"effect": "white_noise", "N": pytest.approx(N_Q)} in new.axes["gx"]
    _, second = _gap(capsys, data, tmp_path / "new.yaml", tmp_path / "r2.json")
    assert second["added"] == [] and second["gap_before"] == pytest.approx(first["gap_after"], rel=1e-9)
