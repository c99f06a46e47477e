"""`companion gap` on the shared real logs and on multi-segment input: any format analyze reads, the
still selection pooled over segments, --imu/--stream, --datasheet, and the datasheet verdict first."""

import json

import numpy as np
import pytest

from companion.cli.main import main
from companion.gap.explain import datasheet_verdict
from companion.sim.synth import synthesize_axis


def test_verdict_names_the_contradicted_term_in_plain_words():
    rec = [{"effect": "white_noise", "param": "N", "model": 5.818e-4, "fitted": 5.818e-4 * 1.25, "lr": 60.0,
            "verdict": "too small"},
           {"effect": "bias_instability", "param": "B", "model": 1.84e-4, "fitted": 1.9e-4, "lr": 1.0,
            "verdict": "consistent"}]
    line = datasheet_verdict(rec, "ADIS16405", "gy", [{"effect": "lowpass", "cutoff_hz": 35.0}])
    assert line.startswith("ADIS16405 datasheet contradicted on gy: white_noise N above the datasheet: 2.5 vs 2 "
                           "deg/sqrt(h), x1.25")
    assert "bias_instability B agrees with the datasheet" in line and "lowpass 35 Hz" in line
    rec[0]["verdict"] = "consistent"
    assert "no datasheet term is contradicted" in datasheet_verdict(rec, "ADIS16405", "gy")
    # the analysis' white level of the same data decides for N: above / below where the datasheet's value lies
    # outside its interval, whatever the workflow's own verdict
    n_sheet = 5.818e-4
    above = datasheet_verdict(rec, "ADIS16405", "gy", white={"N": 10 * n_sheet, "ci95": [8 * n_sheet, 12 * n_sheet]})
    assert "white_noise N above the datasheet: 20 vs 2 deg/sqrt(h), x10" in above
    below = datasheet_verdict(rec, "ADIS16405", "gy", white={"N": 0.5 * n_sheet, "ci95": [0.4 * n_sheet, 0.6 * n_sheet]})
    assert "white_noise N below the datasheet: 1 vs 2 deg/sqrt(h), x0.5" in below
    inside = datasheet_verdict(rec, "ADIS16405", "gy", white={"N": 1.1 * n_sheet, "ci95": [0.9 * n_sheet, 1.3 * n_sheet]})
    assert "no datasheet term is contradicted" in inside and "white_noise N agrees" in inside


def test_still_segments_pooled_and_named(tmp_path, capsys):
    """Two still stretches with a turn between them: both used (pooled), the report says which."""
    rate = 50.0
    n = int(400 * rate)
    terms = [{"effect": "white_noise", "N": 1e-3}]
    rng = np.random.default_rng(4)
    g = np.column_stack([synthesize_axis(terms, rate, 3 * n, rng) for _ in range(3)])
    g[n:2 * n, 2] += 0.5  # a 0.5 rad/s turn in the middle third
    t = np.arange(3 * n) / rate
    a = np.zeros((3 * n, 3))
    a[:, 2] = -9.80665
    path = tmp_path / "two.csv"
    np.savetxt(path, np.column_stack([t, g, a]), delimiter=",", header="time_s,gx,gy,gz,ax,ay,az", comments="",
               fmt="%.9g")
    model = tmp_path / "m.yaml"
    model.write_text("rate_hz: 50\naxes:\n  gx:\n  - {effect: white_noise, N: 0.001}\n")
    out = tmp_path / "g.json"
    assert main(["gap", str(path), "--model", str(model), "--axis", "gx", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "still data used: 2 still segments" in text and "2 segment(s)" in text
    doc = json.loads(out.read_text())
    assert len(doc["ranges_s"]) == 2 and doc["ranges_s"][0][1] < 400 < doc["ranges_s"][1][0]
    assert doc["added"] == [] and doc["fits_within_noise"]
    assert main(["gap", str(path), "--model", str(model), "--stream", "IMU[4]"]) == 2
    assert "no IMU stream 'IMU[4]'" in capsys.readouterr().err


@pytest.mark.shared
def test_ardupilot_bin_against_mpu6000_datasheet(shared_data, tmp_path, capsys):
    """dronekit log171 IMU[0], gx: the datasheet N is 33 % optimistic, the 20 Hz INS_GYRO_FILTER is named
    from the log's parameter, and the gap closes to the noise floor (docs/gap.md)."""
    out = tmp_path / "ap.json"
    assert main(["gap", str(shared_data / "ardupilot" / "dronekit_log171.bin"), "--datasheet", "MPU-6000",
                 "--imu", "0", "--axis", "gx", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    first = text.splitlines()[0]
    assert first.startswith("MPU-6000 datasheet contradicted on gx: white_noise N above the datasheet: ")
    assert "vs 0.212 deg/sqrt(h), x1.3" in first
    doc = json.loads(out.read_text())
    lp = [a for a in doc["added"] if a["effect"] == "lowpass"]
    assert lp and lp[0]["cutoff_hz"] == 20.0 and lp[0]["source"] == "the log's parameter"
    assert doc["gap_after"] <= 2.0 < doc["gap_before"]
    assert all(t["tau_c"] >= 3 / doc["measured"]["rate_hz"] for t in doc["terms_after"]
               if t["effect"] == "gauss_markov")


@pytest.mark.shared
def test_ardupilot_gz_short_record_model_after_refitted_into_the_band(shared_data, tmp_path, capsys):
    """dronekit log171 IMU[0], gz (33 s at rest): the filter is named from the log's parameter and nothing else
    reaches its level. With the terms held at the values the steps left, a gap stayed (G 2.47, the two octaves
    beyond a tenth of the record); every term refitted together at the end (N held at the analysis' white
    level) puts the model after within the noise floor, over every cluster time and the resolved ones."""
    out = tmp_path / "gz.json"
    assert main(["gap", str(shared_data / "ardupilot" / "dronekit_log171.bin"), "--datasheet", "MPU-6000",
                 "--imu", "0", "--axis", "gz", "--json", str(out)]) == 0
    capsys.readouterr()
    doc = json.loads(out.read_text())
    assert [a["effect"] for a in doc["added"]] == ["lowpass"] and doc["added"][0]["cutoff_hz"] == 20.0
    assert doc["resolved_tau_max"] == pytest.approx(3.3, rel=0.02)
    assert doc["gap_after"] <= 2.0 and doc["gap_after_resolved"] <= 2.0
    assert any("every term refitted to the data together" in n for n in doc["notes"])
    n_after = sum(t["N"] ** 2 for t in doc["terms_after"] if t["effect"] == "white_noise") ** 0.5
    assert n_after == pytest.approx(doc["white"]["N"], rel=1e-6)


@pytest.mark.shared
def test_px4_ulog_gx_filter_near_the_onchip_setting_and_the_line(shared_data, tmp_path, capsys):
    """pyulog sample, sensor_combined gx (averaged samples at 248.6 Hz, no cut-off parameter in the log):
    the 116.5 Hz line the periodogram shows is named, and with it in the model the fitted cut-off is
    within 20 % of the MPU-6000 driver's 42 Hz on-chip filter (66 Hz before the cut-off was refitted after
    the line); the gap closes (docs/gap.md)."""
    out = tmp_path / "px4.json"
    assert main(["gap", str(shared_data / "px4" / "pyulog_sample.ulg"), "--datasheet", "MPU-6000", "--axis", "gx",
                 "--json", str(out)]) == 0
    capsys.readouterr()
    doc = json.loads(out.read_text())
    added = {a["effect"]: a for a in doc["added"]}
    assert "sinusoid" in added and abs(added["sinusoid"]["freq_hz"] / 116.5 - 1) < 0.1
    assert added["sinusoid"]["spectral"]["confirmed"]
    assert abs(added["lowpass"]["cutoff_hz"] / 42.0 - 1) <= 0.2
    assert doc["gap_after"] <= 2.0 < doc["gap_before"]
