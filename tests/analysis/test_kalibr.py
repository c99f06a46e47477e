"""The Kalibr imu.yaml's random walks come from the analysis' own K: the fitted K, or its 95 % upper bound where
the fit leaves K out, the largest over each sensor's axes; never below a bound the report gives."""

import json

import numpy as np
import pytest
import yaml

from companion.analysis.axis import analyze_axis
from companion.analysis.kalibr import axis_random_walk, kalibr_yaml
from companion.samples import ACCEL_AXES, GYRO_AXES
from companion.sim.synth import synthesize_axis


def _report_k(entry: dict) -> tuple[float | None, float | None]:
    """(fitted K, 95 % upper bound of K) of one axis entry (None where absent)."""
    k = next((t["K"] for t in entry["terms"] if t["effect"] == "random_walk"), None)
    b = next((x["K"] for x in entry.get("bounds", []) if x["effect"] == "random_walk"), None)
    return k, b


def test_sample_log_random_walks_not_below_the_reports_bounds(tmp_path):
    """tlogs/sample.tlog: K is resolved on gx only; the file's random walks are >= every axis' fitted K and
    95 % bound (gy 8.7e-5 and az 1.5e-4, where sqrt(3 AVAR(tau_max) / tau_max) of the last point gave 5.8e-5
    and 5.4e-5)."""
    from companion.cli.main import main

    js, ky = tmp_path / "r.json", tmp_path / "k.yaml"
    assert main(["analyze", "tlogs/sample.tlog", "--quiet", "--json", str(js), "--kalibr", str(ky)]) in (0, None)
    report = json.loads(js.read_text())
    k = yaml.safe_load(ky.read_text())
    st = max(report["streams"], key=lambda s: s["samples"])
    for sensor, axes in (("gyroscope", GYRO_AXES), ("accelerometer", ACCEL_AXES)):
        values = [v for a in axes if st["axes"][a]["status"] == "ok" for v in _report_k(st["axes"][a])
                  if v is not None]
        assert values, sensor
        # the file holds 7 significant digits: the largest axis' value, rounded
        assert k[f"{sensor}_random_walk"] == pytest.approx(max(values), rel=1e-6), (sensor, k, values)


def test_simulated_random_walk_is_the_fitted_k_inside_its_interval():
    """2 h at 50 Hz of white noise + a rate random walk strong enough to resolve: the Kalibr K is the fit's K,
    and the known K lies inside the fit's 95 % interval."""
    fs, n = 50.0, int(2 * 3600 * 50)
    truth = {"N": 1.0e-3, "K": 2.0e-4}
    terms = [{"effect": "white_noise", "N": truth["N"]}, {"effect": "random_walk", "K": truth["K"]}]
    entry = analyze_axis(synthesize_axis(terms, fs, n, np.random.default_rng(4_901)), fs)
    fitted = next(t for t in entry["terms"] if t["effect"] == "random_walk")
    lo, hi = fitted["ci95"]["K"]
    assert lo <= truth["K"] <= hi, (truth["K"], lo, hi)
    rw = axis_random_walk(entry)
    assert rw.value == fitted["K"] and rw.note is None
    report = {"streams": [{"samples": n, "message": "SIM", "instance": 0, "sysid": 1, "rate_hz": fs,
                           "axes": {"gx": entry}}]}
    assert yaml.safe_load(kalibr_yaml(report))["gyroscope_random_walk"] == float(f"{fitted['K']:.6e}")


def test_unresolved_random_walk_takes_the_reports_bound():
    """An axis whose fit leaves K out reports a 95 % bound of K: that bound is the axis' Kalibr value."""
    entry = {"status": "ok", "tau": [1.0, 2.0], "adev": [1e-3, 7e-4],
             "terms": [{"effect": "white_noise", "N": 1e-3}],
             "bounds": [{"effect": "random_walk", "K": 3e-5, "bound": True}]}
    rw = axis_random_walk(entry)
    assert rw.value == 3e-5 and "upper bound" in rw.note
    entry["bounds"] = []
    rw = axis_random_walk(entry)
    assert rw.value == np.sqrt(3.0 * 7e-4**2 / 2.0) and "no bound" in rw.note


def test_kalibr_is_refused_where_a_sensor_would_get_noise_0(tmp_path, capsys):
    # --axes gx,gy,gz: no accelerometer figure; a 0 noise density tells Kalibr the sensor is perfect
    from companion.cli.main import main

    ky = tmp_path / "imu.yaml"
    assert main(["analyze", "tlogs/sample.tlog", "--quiet", "--axes", "gx,gy,gz", "--kalibr", str(ky)]) == 2
    err = capsys.readouterr().err
    assert "accelerometer" in err and "written as 0" in err and not ky.exists(), err
    assert main(["analyze", "tlogs/sample.tlog", "--quiet", "--axes", "gx,gy,gz", "--kalibr", str(ky), "--force"]) == 0
    assert "accelerometer: no usable axis" in ky.read_text()
