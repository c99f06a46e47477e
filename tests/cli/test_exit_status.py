"""The bad inputs of docs/errors.md, each with what it gets: one error line and its exit status before any
work, or correct figures, and the exit statuses of README "Exit status" (companion.errors): 0 healthy,
2 usage/bad input, 4 a gyro fault found, 5 no usable data. Written data have known parameters (white noise
N = 1e-3 rad/s/sqrt(Hz) at 100 Hz), so the figures are checked against the truth."""

from __future__ import annotations

import json
import os
import socket
from pathlib import Path

import numpy as np
import pytest

from companion.cli.main import main
from companion.errors import EXIT_NO_DATA, EXIT_USAGE
from companion.mavlink.tlog_writer import TlogWriter

N_TRUE = 1e-3  # rad/s/sqrt(Hz)


def write_csv(path, t, seed=1, n_true=N_TRUE, rate=100.0):
    """A CSV with white gyro noise of density ``n_true`` at ``rate`` (the rows' true rate), times as given."""
    rng = np.random.default_rng(seed)
    n = len(t)
    g = rng.normal(0.0, n_true * np.sqrt(rate), (n, 3))
    a = rng.normal(0.0, 0.01, (n, 3)) + [0.0, 0.0, -9.80665]
    with open(path, "w") as fh:
        fh.write("time_s,gx,gy,gz,ax,ay,az\n")
        for i in range(n):
            fh.write(",".join(repr(float(x)) for x in (t[i], *g[i], *a[i])) + "\n")
    return str(path)


def ms_with_float_noise(n=6000):
    """0.0, 10.0, 20.0, 30.000000000000004, ...: a 100 Hz clock in ms computed as (i * 0.01) * 1000."""
    return [(i * 0.01) * 1000 for i in range(n)]


def error_line(capsys, argv, code, *needles):
    rc = main(argv)
    cap = capsys.readouterr()
    assert rc == code, cap
    lines = cap.err.strip().splitlines()
    assert lines and lines[-1].startswith("companion: error: "), cap.err
    for n in needles:
        assert n in lines[-1], lines[-1]
    assert "Traceback" not in cap.err
    return cap


def usage_error(capsys, argv, *needles):
    """One line, status 2, and no work done (nothing on stdout)."""
    cap = error_line(capsys, argv, EXIT_USAGE, *needles)
    assert len(cap.err.strip().splitlines()) == 1, cap.err
    assert cap.out == "", cap.out
    return cap


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# --- exit statuses --------------------------------------------------------------------------------------------
def test_live_run_with_nothing_on_the_link_is_no_usable_data(capsys):
    rc = main(["run", "--source", f"udpout:127.0.0.1:{free_udp_port()}", "--duration", "2", "--no-state", "--quiet"])
    cap = capsys.readouterr()
    assert rc == EXIT_NO_DATA, cap
    assert "no IMU data from the vehicle" in cap.out
    assert "companion run: no IMU data (exit status 5)" in cap.err


def test_replayed_csv_whose_stream_is_unusable_is_no_usable_data(tmp_path, capsys):
    # a ms clock declared seconds: 0.1 Hz rows 10 s apart, every step a gap, no block for the detectors
    p = write_csv(tmp_path / "ms.csv", ms_with_float_noise(600))
    rc = main(["run", "--source", p, "--time-unit", "s", "--quiet"])
    cap = capsys.readouterr()
    assert rc == EXIT_NO_DATA, cap
    assert "rate unknown" in cap.out and "no usable IMU data: IMU0" in cap.err


def test_healthy_replay_is_0_and_log_without_imu_is_5(tmp_path, capsys):
    p = write_csv(tmp_path / "ok.csv", np.arange(3000) / 100.0)
    assert main(["run", "--source", p, "--quiet"]) == 0
    capsys.readouterr()
    hb = tmp_path / "hb.tlog"
    with TlogWriter(hb) as w:
        for k in range(5):
            w.write(w.mav.heartbeat_encode(2, 3, 0, 0, 3), t_unix=1.7e9 + k)
    error_line(capsys, ["run", "--source", str(hb), "--quiet"], EXIT_NO_DATA, "no IMU data to replay")
    error_line(capsys, ["analyze", str(hb)], EXIT_NO_DATA, "no IMU messages")
    # several sources, all without IMU data: no usable data; one readable with data: analysed, one unreadable: 2
    error_line(capsys, ["analyze", str(hb), str(hb), "--quiet"], EXIT_NO_DATA, "no IMU messages")
    error_line(capsys, ["analyze", p, str(tmp_path / "missing.csv"), "--quiet"], EXIT_USAGE, "1 of 2 sources")


def test_fleet_with_every_log_failed_is_no_usable_data(tmp_path, capsys):
    logs = tmp_path / "logs"
    logs.mkdir()
    with TlogWriter(logs / "hb.tlog") as w:
        for k in range(5):
            w.write(w.mav.heartbeat_encode(2, 3, 0, 0, 3), t_unix=1.7e9 + k)
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--quiet"]) == EXIT_NO_DATA
    assert "no log analysed" in capsys.readouterr().err
    error_line(capsys, ["fleet", "report", "--db", db], EXIT_NO_DATA, "no IMU to rank", "all 1 log(s) failed")


# --- outputs and option ranges, checked before any work --------------------------------------------------------
@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux /proc (unwritable even for root)")
def test_unwritable_outputs_refused_before_the_work(tmp_path, capsys):
    p = write_csv(tmp_path / "a.csv", np.arange(3000) / 100.0)
    usage_error(capsys, ["analyze", p, "--json", "/proc/x.json"], "--json /proc/x.json: cannot write")
    usage_error(capsys, ["run", "--source", p, "--state", "/proc/s.json"], "--state /proc/s.json: cannot write")
    usage_error(capsys, ["inspect", p, "--json", "/proc/x.json"], "cannot write")
    assert not os.path.exists("/proc/x.json")


def test_state_with_no_state_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", "--source", "x.csv", "--state", str(tmp_path / "s.json"), "--no-state"])
    assert exc.value.code == EXIT_USAGE
    assert "--no-state: not allowed with argument --state" in capsys.readouterr().err


def test_compensate_refuses_csv_text_under_a_log_name(tmp_path, capsys):
    p = write_csv(tmp_path / "a.csv", np.arange(3000) / 100.0)
    usage_error(capsys, ["compensate", p, "--axis", "gx", "--out", str(tmp_path / "c.tlog")], "give a .csv")
    assert not (tmp_path / "c.tlog").exists()
    usage_error(capsys, ["compensate", p, "--axis", "gx", "--max-samples", "0"], "--max-samples must be >= 1")


def test_gap_cutoff_above_nyquist_refused_before_the_fits(tmp_path, capsys):
    p = write_csv(tmp_path / "fifty.csv", np.arange(3000) / 50.0, rate=50.0)
    cap = error_line(capsys, ["gap", p, "--datasheet", "MPU-6000", "--cutoff", "1000"], EXIT_USAGE,
                     "--cutoff 1000 Hz: at or above the Nyquist frequency", "at most 25 Hz")
    assert cap.out == ""


def test_fleet_simulate_size_guard(tmp_path, capsys):
    out = tmp_path / "big"
    usage_error(capsys, ["fleet", "simulate", str(out), "--vehicles", "100000", "--flights", "1000"],
                "the fleet would take about", "limit 200 GB")
    assert not out.exists()


@pytest.mark.parametrize("argv, needle", [
    (["simulate", "MODEL", "--duration", "10", "--out", "OUT/x.tlog", "--sysid", "300"], "--sysid must be 1-255"),
    (["simulate", "MODEL", "--duration", "10", "--out", "OUT/x.tlog", "--seed", "-1"], "--seed must be >= 0"),
    (["sim-autopilot", "--model", "MODEL", "--connect", "udpout:127.0.0.1:9", "--sysid", "300"], "--sysid must be 1-255"),
    (["sim-autopilot", "--model", "MODEL", "--connect", "udpout:127.0.0.1:9", "--record", "/proc/r.jsonl"],
     "--record /proc/r.jsonl"),
    (["sim-autopilot", "--model", "MODEL", "--connect", "udpout:127.0.0.1:9", "--flow-control", "--flow-port",
      "70000"], "a UDP port is 1-65535"),
    (["run", "--source", "OUT/a.csv", "--sysid", "999"], "--sysid must be 0-255"),
])
def test_out_of_range_options_are_one_line(tmp_path, capsys, argv, needle):
    model = tmp_path / "m.yaml"
    model.write_text("rate_hz: 50.0\naxes:\n  gx:\n    - {effect: white_noise, N: 1.0e-3}\n")
    write_csv(tmp_path / "a.csv", np.arange(300) / 100.0)
    argv = [a.replace("MODEL", str(model)).replace("OUT", str(tmp_path)) for a in argv]
    usage_error(capsys, argv, needle)
    assert not (tmp_path / "x.tlog").exists()


# --- a state file of another setup --------------------------------------------------------------------------------
def test_state_of_another_setup_is_refused_with_the_difference(tmp_path, capsys):
    def model(rate):
        m = tmp_path / f"m{rate}.yaml"
        m.write_text(f"rate_hz: {rate}\naxes:\n" + "".join(f"  {a}:\n    - {{effect: white_noise, N: 3.0e-3}}\n"
                                                          for a in ("gx", "gy", "gz")))
        return str(m)

    three, two = str(tmp_path / "three.tlog"), str(tmp_path / "two.tlog")
    assert main(["simulate", model(100), "--duration", "60", "--out", three, "--vehicle", "--imus", "3"]) == 0
    assert main(["simulate", model(250), "--duration", "30", "--out", two, "--vehicle", "--imus", "2"]) == 0
    state = str(tmp_path / "st.json")
    assert main(["run", "--source", three, "--state", state, "--quiet"]) == 0
    capsys.readouterr()
    before = Path(state).read_bytes()
    error_line(capsys, ["run", "--source", two, "--state", state, "--quiet"], EXIT_USAGE,
               "does not match the state file", "the state has IMU0, IMU1, IMU2, the source IMU0, IMU1",
               "IMU0: 100 Hz in the state, 250 Hz in the source", "--no-state")
    assert Path(state).read_bytes() == before  # the state is left as it was
    assert main(["run", "--source", two, "--no-state", "--quiet"]) == 0  # the way out works


# --- CSV time columns ----------------------------------------------------------------------------------------------
def test_csv_ms_with_float_noise_refused_then_correct_with_the_unit(tmp_path, capsys):
    p = write_csv(tmp_path / "ms.csv", ms_with_float_noise())
    error_line(capsys, ["analyze", p], EXIT_USAGE, "looks like milliseconds", "--time-unit ms")
    out = tmp_path / "r.json"
    assert main(["analyze", p, "--time-unit", "ms", "--axes", "gx,gy,gz", "--json", str(out), "--quiet"]) == 0
    s = json.loads(out.read_text())["streams"][0]
    assert s["rate_hz"] == pytest.approx(100.0, rel=1e-9) and s["samples"] == 6000
    for ax in ("gx", "gy", "gz"):
        n = [t["N"] for t in s["axes"][ax]["terms"] if t["effect"] == "white_noise"][0]
        assert n == pytest.approx(N_TRUE, rel=0.06)  # 60 s at 100 Hz: N to about 1 % (1 sigma)


def test_csv_whole_second_times_refused_not_thinned(tmp_path, capsys):
    p = write_csv(tmp_path / "whole.csv", np.floor(np.arange(6000) / 100.0))
    for extra in ([], ["--time-unit", "s"]):
        error_line(capsys, ["analyze", p, *extra], EXIT_USAGE, "6000 rows carry only 60 distinct times",
                   "100 rows per time value")
        error_line(capsys, ["run", "--source", p, *extra, "--quiet"], EXIT_USAGE, "60 distinct times")


def test_csv_time_stepping_back_is_a_new_segment_not_interleaved(tmp_path, capsys):
    t = np.r_[np.arange(3000) / 100.0, 5.0 + np.arange(3000) / 100.0]  # a second series from 5 s
    p = write_csv(tmp_path / "back.csv", t)
    out = tmp_path / "i.json"
    assert main(["inspect", p, "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "time_s restarts 1 time(s) (line 3002)" in text and "2 segments" in text
    s = json.loads(out.read_text())["streams"][0]
    assert s["rate_hz"] == pytest.approx(100.0, rel=1e-6)  # interleaved, the two series would read as 200 Hz
    assert s["samples"] == 6000



def test_compensate_covariance_lost_validity_is_status_6(tmp_path, capsys, monkeypatch):
    """A filter whose covariance factor lost validity (forced here on the real result of STF): the results are
    written, a warning names the method, and the status is 6, apart from faults (4) and bad input (2)."""
    import companion.compensation.compare_methods as cm

    real = cm.compensate

    def lost(*args, **kwargs):
        result = real(*args, **kwargs)
        result.methods["stf"].factor_valid = False
        return result

    monkeypatch.setattr(cm, "compensate", lost)
    p = write_csv(tmp_path / "a.csv", np.arange(3000) / 100.0)
    out = tmp_path / "c.csv"
    rc = main(["compensate", p, "--axis", "gx", "--method", "stf", "--out", str(out), "--quiet"])
    cap = capsys.readouterr()
    assert rc == 6, cap
    assert "covariance factor lost validity in stf (exit status 6)" in cap.err and out.exists()
