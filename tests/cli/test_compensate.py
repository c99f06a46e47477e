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
    # what the code does: the longest still piece (not merely gap-free), a deg/s table cut at a tenth of the record
    assert "still" in text and "deg/s" in text and "tenth of the record" in text


def _write_csv(path, gyro_col, n=4000, rate=100.0, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    a = np.tile([0.0, 0.0, -9.81], (n, 1)) + 0.01 * rng.standard_normal((n, 3))
    g = np.column_stack([gyro_col, 1e-3 * rng.standard_normal(n), 1e-3 * rng.standard_normal(n)])
    np.savetxt(path, np.column_stack([t, g, a]), delimiter=",", header="time_s,gx,gy,gz,ax,ay,az", comments="")
    return path


def _table_taus(printed):
    import re

    head = next(line for line in printed.splitlines() if line.startswith("method"))
    return [float(v) for v in re.findall(r"@\s*([0-9.eE+-]+) s", head)]


def _white_plus_walk(tmp_path, n=4000, sigma=0.01, seed=4):
    rng = np.random.default_rng(seed)
    gx = sigma * rng.standard_normal(n) + np.cumsum(2e-4 * rng.standard_normal(n))
    return _write_csv(tmp_path / "w.csv", gx, n=n)


def test_table_stops_at_a_tenth_of_the_record(tmp_path, capsys):
    """40 s of data: no tau beyond T/10 = 4 s (fewer than 10 clusters: too few for an Allan estimate) is printed,
    and the long-tau column is the longest one allowed."""
    path = _white_plus_walk(tmp_path)
    assert main(["compensate", str(path), "--axis", "gx", "--quiet"]) == 0
    taus = _table_taus(capsys.readouterr().out)
    assert taus and max(taus) <= 4.0 + 1e-9 and max(taus) > 2.0, taus


def test_table_is_in_deg_per_s(tmp_path, capsys):
    """White noise of 0.01 rad/s = 0.5730 deg/s plus a slow random walk: the printed raw ADEV at tau0 and the
    fitted sqrt(R) are in deg/s (the ADEV at tau0 of white noise is its standard deviation; relative standard
    error about 1/sqrt(2 n) = 1.1 % for n = 4000, so 5 % is a safe bound)."""
    sigma = 0.01
    path = _white_plus_walk(tmp_path, sigma=sigma)
    assert main(["compensate", str(path), "--axis", "gx", "--quiet"]) == 0
    printed = capsys.readouterr().out
    raw_line = next(line for line in printed.splitlines() if line.startswith("raw ADEV"))
    assert "deg/s" in raw_line
    adev0 = float(raw_line.split(")")[-1].split()[0])
    deg = sigma * 180.0 / np.pi
    assert abs(adev0 / deg - 1.0) < 0.05, (adev0, deg)
    import re

    sqrt_r = float(re.search(r"sqrt\(R\)=([0-9.eE+-]+) deg/s", printed).group(1))
    assert abs(sqrt_r / deg - 1.0) < 0.05, (sqrt_r, deg)


def test_warns_when_no_method_reduces_the_noise(tmp_path, capsys):
    """A random walk seen through a two-tap moving average (as an autopilot's low-pass filter shapes motion) has a
    spectral zero at Nyquist, hence no white component at all: nothing can be removed, every ratio at tau0 is about
    1, and the user is told so instead of reading a table of ones. Data with white noise give no such warning."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(6)
    walk = _write_csv(tmp_path / "rw.csv", lfilter([1.0, 1.0], [1.0, -1.0], 1e-3 * rng.standard_normal(4000)))
    assert main(["compensate", str(walk), "--axis", "gx", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "warning" in err and "0.9" in err and "tau0" in err
    noisy = _write_csv(tmp_path / "wn.csv",
                       np.cumsum(1e-4 * rng.standard_normal(4000)) + 5e-3 * rng.standard_normal(4000))
    assert main(["compensate", str(noisy), "--axis", "gx", "--quiet"]) == 0
    assert "warning" not in capsys.readouterr().err


def _streams_result(tmp_path):
    """A LoadResult with one accel-only stream (a DataFlash ISB_ACCEL burst: gyro NaN by design) before two IMUs."""
    from companion.samples import ImuStream, StreamKey, TimingReport
    from companion.sources import LoadResult

    rng = np.random.default_rng(2)
    n = 3000
    t = np.arange(n) / 100.0
    acc = np.tile([0.0, 0.0, -9.81], (n, 1)) + 0.01 * rng.standard_normal((n, 3))

    def stream(msg, inst, gyro):
        return ImuStream(StreamKey(0, 0, msg, inst), t, gyro, acc, segments=[(0, n)],
                         timing=TimingReport(rate_hz=100.0, duration_s=n / 100.0))

    nan = np.full((n, 3), np.nan)
    gyro = 5e-3 * rng.standard_normal((n, 3))
    return LoadResult(str(tmp_path / "log.bin"), [stream("IMU", 0, gyro), stream("IMU", 1, gyro),
                                                   stream("ISB_ACCEL", 0, nan)])


def test_accel_only_stream_names_the_gyro_streams(tmp_path, capsys, monkeypatch):
    import companion.sources

    monkeypatch.setattr(companion.sources, "load", lambda *a, **k: _streams_result(tmp_path))
    assert main(["compensate", str(tmp_path / "log.bin"), "--axis", "gx", "--stream", "2", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("companion: error:") and "\n" not in err
    assert "ISB_ACCEL[0]" in err and "no gyro" in err
    assert "0: IMU[0]" in err and "1: IMU[1]" in err  # the gyro streams the user can pick instead


def test_accel_only_shared_dataflash(shared_data, tmp_path, capsys):
    """The real methodic log with its batch-sampler header turned into accel (type 0): ISB_ACCEL[0] is stream 2."""
    from companion.sources import dataflash

    data = bytearray((shared_data / "ardupilot" / "methodic_backend_log_80k.bin").read_bytes())
    log = dataflash.index(np.frombuffer(bytes(data), dtype=np.uint8))
    f = log.formats[log.names["ISBH"]]
    at = 3 + f.dtype.fields["type"][1]
    for pos in log.offsets[log.names["ISBH"]]:
        data[int(pos) + at] = 0
    p = tmp_path / "isb_accel.bin"
    p.write_bytes(bytes(data))
    assert main(["compensate", str(p), "--axis", "gx", "--stream", "2", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "no gyro" in err and "IMU[0]" in err and "IMU[1]" in err


def test_too_short_record_names_the_stream_and_its_length(tmp_path, capsys):
    rng = np.random.default_rng(3)
    path = _write_csv(tmp_path / "short.csv", 5e-3 * rng.standard_normal(150), n=150)
    assert main(["compensate", str(path), "--axis", "gx", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("companion: error:") and "\n" not in err
    assert "CSV[0]" in err and "150 samples" in err and "1.5 s" in err and "200" in err


def test_plot_allan_panel_in_deg_per_s_and_cut_at_a_tenth(tmp_path, monkeypatch):
    """The plot's Allan panel draws the same numbers as the JSON, times 180/pi (deg/s), and like the table stops
    at T/10 = 4 s of the 40-s record."""
    import companion.plots.compensation_plot as cp

    figs = []
    monkeypatch.setattr(cp, "save_figure", lambda fig, path, plt: figs.append(fig))
    path = _white_plus_walk(tmp_path)
    out_json = tmp_path / "c.json"
    assert main(["compensate", str(path), "--axis", "gx", "--plot", str(tmp_path / "c.png"),
                 "--json", str(out_json), "--quiet"]) == 0
    rep = json.loads(out_json.read_text())
    allan = [ax for ax in figs[0].axes if ax.get_xscale() == "log"][0]
    raw = allan.get_lines()[0]
    assert "deg/s" in allan.get_ylabel()
    tau, adev = raw.get_xdata(), raw.get_ydata()
    assert max(tau) <= 4.0 + 1e-9
    assert np.allclose(adev, np.array(rep["raw"]["adev"][: len(adev)]) * 180.0 / np.pi)
    import matplotlib.pyplot as plt

    plt.close(figs[0])


@pytest.mark.parametrize("split", ["canonical", "auto"])
def test_json_is_strict_and_names_the_split(imu_csv, tmp_path, split):
    """The JSON parses without NaN/Infinity constants (the free fit's white share is null when there was none)."""
    path, _ = imu_csv
    out_json = tmp_path / "c.json"
    assert main(["compensate", str(path), "--axis", "gx", "--method", "stf", "--split", split,
                 "--json", str(out_json), "--quiet"]) == 0

    def refuse(name):
        raise ValueError(f"non-standard JSON constant {name}")

    rep = json.loads(out_json.read_text(), parse_constant=refuse)
    share = rep["arima"]["free_white_share"]
    assert (share is None) if split == "canonical" else (0.0 <= share <= 1.0)


def test_constant_axis_names_the_stream_and_value(tmp_path, capsys):
    """An all-zero gyro axis (real 2014 rover logs carry one) is one error line naming the stream, the axis, the
    sample count and the value, instead of an anonymous 'the series is constant'."""
    path = _write_csv(tmp_path / "dead.csv", np.zeros(1000), n=1000)
    assert main(["compensate", str(path), "--axis", "gx", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("companion: error:") and "\n" not in err
    assert "CSV[0]" in err and "gx" in err and "1000 samples are 0 deg/s" in err
