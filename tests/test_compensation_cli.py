"""``companion compensate`` end to end on a CSV of simulated data, and its one-line user errors."""

import json

import numpy as np
import pytest
from scipy.signal import lfilter

from companion.cli.main import main


@pytest.fixture
def imu_csv(tmp_path):
    rng = np.random.default_rng(8)
    n = 4000
    t = np.arange(n) / 100.0
    g = np.column_stack([np.cumsum(lfilter([1e-3, -3e-4], [1, -0.8], rng.standard_normal(n))) + 5e-3 * rng.standard_normal(n)
                         for _ in range(3)])
    a = np.tile([0.0, 0.0, -9.81], (n, 1)) + 0.01 * rng.standard_normal((n, 3))
    path = tmp_path / "imu.csv"
    np.savetxt(path, np.column_stack([t, g, a]), delimiter=",", header="time_s,gx,gy,gz,ax,ay,az", comments="")
    return path, g


def test_compensate_writes_json_csv_and_plot(imu_csv, tmp_path, capsys):
    path, g = imu_csv
    out_json, out_csv, out_png = tmp_path / "c.json", tmp_path / "c.csv", tmp_path / "c.png"
    rc = main(["compensate", str(path), "--axis", "gy", "--json", str(out_json), "--out", str(out_csv),
               "--plot", str(out_png), "--quiet"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "SR-RSUKF" in printed and "ADEV ratio" in printed
    for f in (out_json, out_csv, out_png):  # every file written is named, as the other commands do
        assert f"wrote {f}\n" in printed
    rep = json.loads(out_json.read_text())
    assert rep["axis"] == "gy" and set(rep["methods"]) == {"stf", "srukf", "srrsukf"}
    from companion.allan.adev import oadev

    tau, adev, _, _ = oadev(g[:, 1], 100.0)
    assert np.allclose(rep["raw"]["tau"], tau) and np.allclose(rep["raw"]["adev"], adev)
    for m in rep["methods"].values():
        assert len(m["tau"]) == len(m["adev"]) == len(tau) and m["factor_valid"]
        assert m["adev"][0] < rep["raw"]["adev"][0]  # the white measurement noise is reduced
    table = np.loadtxt(out_csv, delimiter=",", skiprows=1)
    assert table.shape == (4000, 5) and np.allclose(table[:, 1], g[:, 1])
    assert out_png.stat().st_size > 10_000


def test_compensate_single_method_and_max_samples(imu_csv, tmp_path):
    path, _ = imu_csv
    out_json = tmp_path / "c.json"
    assert main(["compensate", str(path), "--axis", "gx", "--method", "stf", "--max-samples", "3000",
                 "--json", str(out_json), "--quiet"]) == 0
    rep = json.loads(out_json.read_text())
    assert list(rep["methods"]) == ["stf"] and rep["samples"] == 3000


@pytest.mark.parametrize("argv,msg", [
    (["--axis", "gq"], "unknown --axis"),
    (["--axis", "gx", "--method", "ekf"], "unknown --method"),
    (["--axis", "gx", "--stream", "3"], "out of range"),
    (["--axis", "gx", "--max-samples", "50"], "too few"),
])
def test_compensate_user_errors_are_one_line(imu_csv, capsys, argv, msg):
    path, _ = imu_csv
    assert main(["compensate", str(path), *argv, "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and "\n" not in err and err.startswith("companion: error:")


def test_compensate_missing_file(tmp_path, capsys):
    assert main(["compensate", str(tmp_path / "none.csv"), "--axis", "gx"]) == 2
    assert "no such file" in capsys.readouterr().err


def test_compensate_help_teaches(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["compensate", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "examples:" in text and "srrsukf" in text and "--max-samples" in text
