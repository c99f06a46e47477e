"""Still selection and the pooled fit on simulated flight logs (DataFlash, ULog), and the inputs a newcomer
brings (shuffled CSV, ms time, 2 Hz tlog, several sources, bad files)."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import pytest

from companion.cli.main import main
from companion.sim.dataflash_writer import write_imu_log
from companion.sources.still import select_still


def _flight_log(rng, N, rate=100.0, still=(900.0, 700.0), flight=120.0, gap=15.0, fc=20.0, internal=400,
                average=False):
    """Still - (armed) flight - gap - still at ``rate``; gyro white noise of density N through a 2-pole
    Butterworth at ``fc`` at ``internal`` Hz, then decimated (as ArduPilot logs its IMU) or, with
    ``average``, averaged over each output interval (PX4's sensor_combined)."""
    from scipy.signal import butter, lfilter

    dec = int(internal // rate)
    total = still[0] + flight + gap + still[1]
    n_int = int(total * internal)
    sd = N * np.sqrt(internal)
    b, a = butter(2, fc / (internal / 2))
    def out(x):
        if average:
            return x[: x.shape[0] // dec * dec].reshape(-1, dec, 3).mean(axis=1)
        return x[::dec]

    g = out(lfilter(b, a, rng.normal(0, sd, (n_int, 3)), axis=0))
    acc = out(lfilter(b, a, rng.normal(0, 0.02, (n_int, 3)), axis=0)) + [0.0, 0.0, -9.80665]
    t = 1.0 + np.arange(g.shape[0]) / rate
    t0f = 1.0 + still[0]
    fl = (t >= t0f) & (t < t0f + flight)
    tf = t[fl] - t0f
    g[fl] += 0.5 * np.sin(2 * np.pi * 0.3 * tf)[:, None] * [1.0, 0.7, 0.4]
    acc[fl] += 2.0 * np.sin(2 * np.pi * 0.5 * tf)[:, None] * [1.0, 1.0, 0.5]
    keep = ~((t >= t0f + flight) & (t < t0f + flight + gap))
    armed = [(t0f - 5.0, True), (t0f + flight + 1.0, False)]
    return t[keep], g[keep], acc[keep], armed


@pytest.mark.parametrize("layout", ["2015", "4.x"])
def test_still_flight_still_gives_N_within_3_percent(tmp_path, layout):
    from companion.analysis.source import analyze_source

    errs = []
    seeds = range(6)
    for seed in seeds:
        rng = np.random.default_rng(100 + seed)
        N = 10 ** rng.uniform(-4, -3)
        t, g, acc, armed = _flight_log(rng, N)
        p = tmp_path / f"s{seed}.bin"
        write_imu_log(p, t, g[None], acc[None], layout=layout, params={"INS_GYRO_FILTER": 20.0}, armed=armed)
        entries, summary = analyze_source(str(p), ["gx", "gy", "gz"], "octave")
        sel = summary["selection"]
        assert len(sel["intervals"]) == 2, sel["description"]
        assert 1550 <= sel["still_s"] <= 1605  # 1600 s still, minus guards
        assert sel["moving_s"] >= 120 and sel["gap_s"] >= 10
        (st,) = entries
        for ax in ("gx", "gy", "gz"):
            terms = {t_["effect"]: t_ for t_ in st["axes"][ax]["terms"]}
            errs.append(terms["white_noise"]["N"] / N - 1)
            assert "bias_instability" not in terms or terms["bias_instability"]["B"] < 0.3 * N  # the filter is not B
    errs = np.array(errs)
    assert np.max(np.abs(errs)) < 0.03, errs
    assert abs(np.mean(errs)) < 0.01


@pytest.mark.soak
def test_px4_still_flight_still_gives_N_within_3_percent(tmp_path):
    from companion.analysis.source import analyze_source
    from companion.sim.ulog_writer import write_ulog

    errs = []
    for seed in range(4):
        rng = np.random.default_rng(200 + seed)
        N = 10 ** rng.uniform(-4, -3)
        t, g, acc, armed = _flight_log(rng, N)
        tc, gc, ac, _ = _flight_log(rng, N, average=True)
        n = min(t.shape[0], tc.shape[0])
        p = tmp_path / f"s{seed}.ulg"
        write_ulog(p, t[:n], g[None, :n], acc[None, :n], combined=(gc[:n], ac[:n]),
                   params={"IMU_GYRO_CUTOFF": 20.0}, armed=armed)
        entries, summary = analyze_source(str(p), ["gx", "gy", "gz"], "octave")
        assert len(summary["selection"]["intervals"]) == 2, summary["selection"]["description"]
        assert summary["selection"]["method"] == "armed state + motion"
        assert sorted(e["message"] for e in entries) == ["sensor_combined", "sensor_gyro"]
        for st in entries:
            assert st["filters_hz"] == {"gyro": 20.0}
            for ax in ("gx", "gy", "gz"):
                terms = {t_["effect"]: t_ for t_ in st["axes"][ax]["terms"]}
                errs.append(terms["white_noise"]["N"] / N - 1)
    errs = np.array(errs)
    assert np.max(np.abs(errs)) < 0.03, errs
    assert abs(np.mean(errs)) < 0.01


def test_still_selection_uses_armed_state_and_motion():
    from companion.samples import StreamKey
    from companion.sources import build_stream
    from companion.sources.decode import RawStream

    rng = np.random.default_rng(3)
    t = np.arange(0, 300, 0.01)
    g = rng.normal(0, 1e-3, (t.size, 3))
    a = rng.normal(0, 1e-2, (t.size, 3)) + [0, 0, -9.8]
    handled = (t > 100) & (t < 130)  # carried by hand, never armed
    g[handled] += 0.2 * np.sin(t[handled])[:, None]
    st = build_stream(RawStream(StreamKey(0, 0, "IMU", 0), t, g, a, None, True, None, None, 1e-6))
    sel = select_still([st], {"armed": [(200.0, True), (250.0, False)], "has_armed_state": True})
    iv = sel.intervals
    assert len(iv) == 3
    assert iv[0][1] <= 100 and iv[1][0] >= 130 and iv[1][1] <= 200 and iv[2][0] >= 250
    assert "3 still segments" in sel.describe()
    allsel = select_still([st], {"armed": [(200.0, True), (250.0, False)]}, use_all=True)
    assert len(allsel.intervals) == 1 and allsel.still_s > 299
    win = select_still([st], {}, start=140, end=190)
    assert win.intervals[0][0] >= 140 and win.intervals[-1][1] <= 190.01


def test_still_selection_of_a_record_shorter_than_the_guard():
    # a 6 s record has 6 windows, fewer than the 7 a 3 s guard spans on each side of a moving window:
    # the widened motion mask must keep the record's length (it came out one longer and the selection failed)
    from companion.samples import StreamKey
    from companion.sources import build_stream
    from companion.sources.decode import RawStream
    from companion.sources.still import _dilate

    rng = np.random.default_rng(5)
    for k in range(0, 9):
        for n in range(1, 16):
            m = rng.random(n) < 0.2
            want = np.array([m[max(0, i - k):i + k + 1].any() for i in range(n)])
            assert np.array_equal(_dilate(m, k), want), (n, k)
    t = np.arange(0, 6, 0.01)
    g = rng.normal(0, 1e-3, (t.size, 3))
    a = rng.normal(0, 1e-2, (t.size, 3)) + [0, 0, -9.8]
    g[(t > 2) & (t < 3)] += 0.3  # a turn in the third second
    st = build_stream(RawStream(StreamKey(0, 0, "IMU", 0), t, g, a, None, True, None, None, 1e-6))
    sel = select_still([st], {"armed": [(1.0, True)], "has_armed_state": True})
    assert sel.intervals == [] and sel.moving_s == pytest.approx(6.0)
    sel = select_still([st], {})  # no armed state: the moving second widened by the guard covers it all
    assert sel.intervals == [] and sel.moving_s == pytest.approx(6.0)
    quiet = build_stream(RawStream(StreamKey(0, 0, "IMU", 0), t, rng.normal(0, 1e-3, (t.size, 3)), a, None, True,
                                   None, None, 1e-6))
    sel = select_still([quiet], {})  # a short record still throughout is kept whole
    assert len(sel.intervals) == 1 and sel.still_s > 5.9


def _csv(path, t, d):
    with open(path, "w") as f:
        f.write("time_s,gx,gy,gz,ax,ay,az\n")
        np.savetxt(f, np.column_stack([t, d]), delimiter=",", fmt="%.10g")


def test_newcomer_csv_cases(tmp_path, capsys):
    rng = np.random.default_rng(5)
    n = 12000
    t = np.arange(n) / 100.0
    d = rng.normal(0, 1e-3, (n, 6))
    _csv(tmp_path / "ms.csv", t * 1000, d)
    assert main(["analyze", str(tmp_path / "ms.csv"), "--axes", "gx"]) == 2
    assert "milliseconds" in capsys.readouterr().err
    _csv(tmp_path / "us.csv", t * 1e6, d)
    assert main(["analyze", str(tmp_path / "us.csv"), "--axes", "gx"]) == 2
    assert "microseconds" in capsys.readouterr().err
    o = rng.permutation(n)
    _csv(tmp_path / "shuf.csv", t[o], d[o])
    out = tmp_path / "r.json"
    assert main(["analyze", str(tmp_path / "shuf.csv"), "--axes", "gx", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "sorted by time_s" in text
    rep = json.loads(out.read_text())
    assert rep["streams"][0]["samples"] == n
    N = rep["streams"][0]["axes"]["gx"]["terms"][0]["N"]
    assert N == pytest.approx(1e-3 / 10, rel=0.1)


def test_short_or_slow_stream_warns_and_refuses_kalibr(tmp_path, capsys):
    rng = np.random.default_rng(9)
    t = np.arange(0, 40, 0.01)
    _csv(tmp_path / "short.csv", t, rng.normal(0, 1e-3, (t.size, 6)))
    kal = tmp_path / "imu.yaml"
    out = tmp_path / "r.json"
    assert main(["analyze", str(tmp_path / "short.csv"), "--json", str(out), "--kalibr", str(kal)]) == 2
    cap = capsys.readouterr()
    assert "WARNING: only 40 s analysed" in cap.out and "--force" in cap.err
    assert not kal.exists()
    assert json.loads(out.read_text())["warnings"]
    assert main(["analyze", str(tmp_path / "short.csv"), "--kalibr", str(kal), "--force"]) == 0
    assert kal.exists()


def test_ardusub_tlog_2hz_warns(shared_data, tmp_path, capsys):
    kal = tmp_path / "imu.yaml"
    rc = main(["analyze", str(shared_data / "tlogs" / "ardusub_2023-04-18.tlog"), "--kalibr", str(kal)])
    cap = capsys.readouterr()
    assert rc == 2 and not kal.exists()
    assert "WARNING: only 2 Hz" in cap.out
    assert "1 still segment" in cap.out and "flight/motion" in cap.out


def test_dronekit_log_uses_still_pre_arm_part(shared_data, capsys):
    assert main(["analyze", str(shared_data / "ardupilot" / "dronekit_log171.bin"), "--axes", "gx,gy,gz"]) == 0
    out = capsys.readouterr().out
    assert "armed state + motion" in out and "armed) " in out
    for i in range(3):
        assert f"IMU[{i}]" in out
    # the log's INS_GYRO_FILTER is modelled, not cut: no cluster time is left out, no Gauss-Markov stand-in
    assert "low-pass 20 Hz (the log's, 2-pole, point-sampled) modelled" in out
    assert "left out of the fit" not in out and "gauss_markov" not in out


def test_run_replays_a_dataflash_log(tmp_path, capsys):
    rng = np.random.default_rng(11)
    t, g, acc, armed = _flight_log(rng, 3e-4, still=(60.0, 30.0), flight=20.0, gap=5.0)
    p = tmp_path / "f.bin"
    write_imu_log(p, t, g[None], acc[None], layout="4.x", armed=armed)
    assert main(["run", "--source", str(p), "--baseline-s", "30"]) == 0
    out = capsys.readouterr()
    assert "replayed" in (out.out + out.err) and "IMU0" in (out.out + out.err)


def test_N_survives_model_misfit():
    """White noise plus a square-wave bias and a slow line the model lacks: the global fit misfits and moves
    N by about 2 %; the local refit of the white-noise region keeps N within 1 % of the truth."""
    from companion.analysis.axis import analyze_axis

    for seed in range(4):
        rng = np.random.default_rng(seed)
        n, fs, N = 400_000, 100.0, 1e-3
        t = np.arange(n) / fs
        y = (rng.normal(0, N * np.sqrt(fs), n) + 2e-4 * np.sign(np.sin(2 * np.pi * t / 200 + 1))
             + 1e-4 * np.sin(2 * np.pi * t / 37))
        r = analyze_axis(y, fs)
        assert r["fit"]["model_error"] > 0
        assert any(s.startswith("N from a local weighted fit") for s in r["fit"]["notes"])
        got = next(x["N"] for x in r["terms"] if x["effect"] == "white_noise")
        assert abs(got / N - 1) < 0.01


def test_plot_overlays_every_imu_and_several_logs(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    rng = np.random.default_rng(21)
    paths = []
    for k, N in enumerate((2e-4, 4e-4)):
        n = 8000
        t = 1.0 + np.arange(n) / 100.0
        g = rng.normal(0, N * 10, (2, n, 3))
        a = rng.normal(0, 0.01, (2, n, 3)) + [0, 0, -9.8]
        p = tmp_path / f"log{k}.bin"
        write_imu_log(p, t, g, a, layout="3.4")
        paths.append(str(p))
    png = tmp_path / "cmp.png"
    rc = main(["analyze", *paths, "--axes", "gx,gy", "--plot", str(png), "--json", str(tmp_path / "r.json")])
    assert rc == 0
    out = capsys.readouterr().out
    assert png.exists() and png.stat().st_size > 10_000
    written = [line.split(" ", 1)[1] for line in out.splitlines() if line.startswith("wrote ") and "cmp" in line]
    assert len(written) == 1 + 4  # the overlay and one detailed figure per stream (2 logs x 2 IMUs)
    rep = json.loads((tmp_path / "r.json").read_text())
    assert {st["source"] for st in rep["streams"]} == set(paths)
    assert len(rep["sources"]) == 2


def test_several_sources_one_without_still_data(tmp_path, capsys):
    rng = np.random.default_rng(4)
    n = 8000
    t = 1.0 + np.arange(n) / 100.0
    g, a = rng.normal(0, 1e-3, (1, n, 3)), rng.normal(0, 0.01, (1, n, 3)) + [0, 0, -9.8]
    good, armed = tmp_path / "good.bin", tmp_path / "armed.bin"
    write_imu_log(good, t, g, a)
    # armed and moving throughout with one IMU: neither still data nor a ground or flight figure
    moving = g + 0.3 * np.sin(2 * np.pi * 0.5 * t)[None, :, None]
    write_imu_log(armed, t, moving, a, armed=[(0.5, True)])
    assert main(["analyze", str(good), str(armed), "--axes", "gx"]) == 2
    cap = capsys.readouterr()
    assert "good.bin: 1 still segment" in cap.out and "1 of 2 sources not analysed" in cap.err
    assert main(["analyze", str(armed), "--axes", "gx", "--all"]) == 0


def test_bad_log_files_are_one_line_errors(tmp_path, capsys):
    bad_bin = tmp_path / "x.bin"
    bad_bin.write_bytes(b"this is not a log" * 20)
    bad_ulg = tmp_path / "x.ulg"
    bad_ulg.write_bytes(b"\x00" * 100)
    bad_gz = tmp_path / "x.bin.gz"
    bad_gz.write_bytes(b"not gzip")
    for p, msg in ((bad_bin, "not a DataFlash log"), (bad_ulg, "not a readable ULog"), (bad_gz, "gzip"),
                   (tmp_path / "missing.ulg", "no such file")):
        assert main(["inspect", str(p)]) == 2
        err = capsys.readouterr().err
        assert msg in err and err.count("\n") == 1, err


def test_start_end_and_tlog_gz(tmp_path, capsys):
    rng = np.random.default_rng(12)
    n = 12000
    t = 1.0 + np.arange(n) / 100.0
    p = tmp_path / "a.bin"
    write_imu_log(p, t, rng.normal(0, 1e-3, (1, n, 3)), rng.normal(0, 0.01, (1, n, 3)) + [0, 0, -9.8])
    out = tmp_path / "r.json"
    assert main(["analyze", str(p), "--axes", "gx", "--start", "20", "--end", "90", "--json", str(out)]) == 0
    st = json.loads(out.read_text())["streams"][0]
    assert st["ranges_s"][0][0] >= 20 and st["ranges_s"][-1][1] <= 90
    assert 69 <= st["duration_s"] <= 70.5
    capsys.readouterr()
    tl = Path(__file__).resolve().parents[2] / "tlogs" / "sample.tlog"
    if tl.exists():
        gz = tmp_path / "s.tlog.gz"
        gz.write_bytes(gzip.compress(tl.read_bytes()))
        assert main(["inspect", str(gz)]) == 0
        assert "RAW_IMU" in capsys.readouterr().out
