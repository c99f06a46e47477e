"""``companion inspect``: table, exact --json keys, exit codes, the real ArduSub log, a live UDP link."""

from __future__ import annotations

import json
import socket
import threading
import time

import numpy as np
import pytest

from companion.cli.main import main
from companion.mavlink.tlog_writer import TlogWriter, write_imu_tlog

STREAM_KEYS = {"message", "instance", "sysid", "compid", "samples", "rate_hz", "duration_s", "gaps", "is_imu"}


def test_inspect_json_exact_keys(tmp_path, capsys):
    n = 1000
    path = tmp_path / "a.tlog"
    write_imu_tlog(path, 2.0 + np.arange(n) / 200.0, np.full((n, 3), 0.01), np.full((n, 3), 0.3))
    out = tmp_path / "o.json"
    # a gyro constant at 0.01 rad/s is dead (health.dead): the table and JSON, then exit status 4 (faults found)
    assert main(["inspect", str(path), "--json", str(out)]) == 4
    text = capsys.readouterr().out
    assert "RAW_IMU" in text and "200.000" in text
    doc = json.loads(out.read_text())
    assert set(doc) == {"streams", "frames", "bad_bytes", "bad_frames"}
    assert [set(s) for s in doc["streams"]] == [STREAM_KEYS]
    s = doc["streams"][0]
    assert (s["message"], s["instance"], s["sysid"], s["compid"], s["samples"]) == ("RAW_IMU", 0, 1, 1, n)
    assert s["rate_hz"] == pytest.approx(200.0) and s["gaps"] == 0 and s["is_imu"] is True
    assert s["duration_s"] == pytest.approx((n - 1) / 200.0)
    assert doc["frames"] == n + 5 and doc["bad_bytes"] == 0  # 5 heartbeats at 1 Hz over 4.995 s


@pytest.mark.parametrize("rate, slow", [(49.6, False), (50.0, False), (20.0, True), (45.0, True)])
def test_a_nominal_50_hz_log_is_not_called_too_slow(tmp_path, capsys, rate, slow):
    """An autopilot's nominal 50 Hz log measures 49.6-49.9 Hz (log171: 49.6): N is estimated there like at 50.0
    Hz, so the 'log faster' note is for rates really below it."""
    n = 2000
    path = tmp_path / "a.tlog"
    rng = np.random.default_rng(1)
    write_imu_tlog(path, 2.0 + np.arange(n) / rate, rng.normal(0.0, 0.01, (n, 3)), np.full((n, 3), 0.3))
    assert main(["inspect", str(path)]) == 0
    text = capsys.readouterr().out
    assert ("aliased together" in text) is slow, text
    assert "even at rest throughout" in text  # 40-100 s: far from the hours B and K need

def test_inspect_no_imu_and_bad_inputs(tmp_path, capsys):
    path = tmp_path / "hb.tlog"
    with TlogWriter(path) as w:
        for k in range(5):
            w.write(w.mav.heartbeat_encode(2, 3, 0, 0, 3), t_unix=1.7e9 + k)
    assert main(["inspect", str(path)]) == 5  # read, but no usable data
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no IMU" in err
    for bad in [str(tmp_path / "none.tlog"), "udpfoo:1:2", str(tmp_path)]:
        assert main(["inspect", bad]) == 2
        err = capsys.readouterr().err
        assert err.startswith("companion: error:") and err.count("\n") == 1


def test_inspect_compass_only_reports_then_fails(tmp_path, capsys):
    path = tmp_path / "c.tlog"
    n = 50
    write_imu_tlog(path, np.arange(n) / 10.0, np.zeros((n, 3)), np.zeros((n, 3)), message="SCALED_IMU2")
    assert main(["inspect", str(path)]) == 5  # no usable data
    cap = capsys.readouterr()
    assert "SCALED_IMU2" in cap.out and "compass-only" in cap.out  # partial data reported
    assert "no IMU" in cap.err


@pytest.mark.shared
def test_inspect_real_ardusub_log(shared_data, tmp_path, capsys):
    log = shared_data / "tlogs" / "ardusub_2023-04-18.tlog"
    out = tmp_path / "a.json"
    assert main(["inspect", str(log), "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    by = {s["message"]: s for s in doc["streams"]}
    assert set(by) == {"RAW_IMU", "SCALED_IMU2"}
    assert by["RAW_IMU"]["samples"] == 627 and by["RAW_IMU"]["is_imu"] is True
    # 626 intervals over 313.0 s of time_usec (pymavlink): 2.000 Hz; a few late messages split a period into
    # 0.12 + 0.88 s, which must not pull the rate up
    assert by["RAW_IMU"]["rate_hz"] == pytest.approx(2.0, rel=0.001)
    assert by["SCALED_IMU2"]["samples"] == 627 and by["SCALED_IMU2"]["is_imu"] is False
    assert doc["frames"] == 50136  # pymavlink: 50136 valid messages and 1967 BAD_DATA on this file
    assert 1900 <= doc["bad_frames"] <= 2100
    text = capsys.readouterr().out
    assert "compass-only" in text and "only 2 Hz" in text


def _free_udp_port():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


@pytest.mark.network
def test_inspect_live_udp_loopback(tmp_path, capsys):
    from pymavlink.dialects.v20 import ardupilotmega as dialect

    port = _free_udp_port()
    stop = threading.Event()

    def sender():
        mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        k = 0
        t_end = time.monotonic() + 120.0  # until the test stops it; bounded
        while not stop.is_set() and time.monotonic() < t_end:
            m = mav.raw_imu_encode(1_000_000 + k * 20_000, 0, 0, -1000, 1, 2, 3 + (k % 5), 0, 0, 0, 0, 4000)
            sock.sendto(m.pack(mav), ("127.0.0.1", port))
            mav.seq = (mav.seq + 1) % 256
            k += 1
            time.sleep(0.01)  # the sender's pacing (100 Hz)
        sock.close()

    th = threading.Thread(target=sender, daemon=True)
    th.start()
    out = tmp_path / "live.json"
    t0 = time.monotonic()
    try:
        rc = main(["inspect", f"udpin:127.0.0.1:{port}", "--duration", "1.5", "--json", str(out)])
    finally:
        stop.set()
        th.join(5)
    assert time.monotonic() - t0 < 120  # --duration 1.5 bounds it; generous for a busy machine
    assert rc == 4  # the sender's gyro X and Y are constant (1, 2 mrad/s): dead, a fault found
    doc = json.loads(out.read_text())
    s = doc["streams"][0]
    assert s["message"] == "RAW_IMU" and s["samples"] > 20
    assert s["rate_hz"] == pytest.approx(50.0, rel=1e-6)  # from time_usec (20 ms steps), not arrival time
