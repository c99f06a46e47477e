"""MAVLink 2 signing end to end over loopback: `companion sim-autopilot --signing-key` (an autopilot with
signing set up: it ignores unsigned frames) against `companion run --signing-key`, with the right key, a
wrong key and an unsigned vehicle; plus the key file checks."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from tests.support.loopback import pacing
from tests.support.readiness import DEADLINE_S, READY, kill_left, wait_for_text, wait_until_read

from companion.cli.main import main
from tests.support.run_status import expected_run_status

ROOT = Path(__file__).resolve().parents[2]
MODEL = "rate_hz: 100.0\naxes:\n" + "".join(f"  {a}: [{{effect: white_noise, N: 3.0e-3}}]\n" for a in ("gx", "gy", "gz"))


def env():
    e = dict(os.environ)
    e["PYTHONPATH"] = str(ROOT) + os.pathsep + e.get("PYTHONPATH", "")
    e.pop("MAVLINK20", None)
    return e


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def session(tmp_path, run_key=None, sim_key=None, wait_request=False):
    (tmp_path / "model.yaml").write_text(MODEL)
    (tmp_path / "cfg.yaml").write_text("run:\n  retry_s: 1.0\n")  # ask again every wall second while no data
    port = free_udp_port()
    run_cmd = [sys.executable, "-m", "companion", "run", "--source", f"udpin:127.0.0.1:{port}", "--no-state",
               "--duration", "600", "--config", "cfg.yaml"]
    if run_key:
        run_cmd += ["--signing-key", str(run_key)]
    run_out = open(tmp_path / "run.out", "w")
    run = subprocess.Popen(run_cmd, cwd=tmp_path, env=env(), stdout=run_out, stderr=subprocess.STDOUT)
    sim = None
    try:
        wait_for_text(tmp_path / "run.out", READY, run)
        sim_cmd = [sys.executable, "-m", "companion", "sim-autopilot", "--model", "model.yaml", "--connect",
                   f"udpout:127.0.0.1:{port}", *pacing(10.0), "--duration", "100", "--wall-limit", "60", "--quiet"]
        if sim_key:
            sim_cmd += ["--signing-key", str(sim_key)]
        if wait_request:
            sim_cmd.append("--wait-request")
        sim = subprocess.Popen(sim_cmd, cwd=tmp_path, env=env(), stdout=open(tmp_path / "sim.out", "w"),
                               stderr=subprocess.STDOUT)
        sim.wait(DEADLINE_S)
        wait_until_read(port, run)  # run has read all the vehicle sent (a condition, not a fixed wait)
        run.send_signal(signal.SIGTERM)
        run.wait(DEADLINE_S)
    finally:
        kill_left(sim, run)
        run_out.close()
    out, sim_out = (tmp_path / "run.out").read_text(), (tmp_path / "sim.out").read_text()
    assert run.returncode == expected_run_status(out) and sim.returncode == 0, out + sim_out
    return out, sim_out


def rejected(out) -> int:
    m = re.search(r"(\d+) rejected for their signature", out)
    return int(m.group(1)) if m else 0


@pytest.fixture
def keys(tmp_path):
    good, wrong = tmp_path / "good.key", tmp_path / "wrong.key"
    good.write_bytes(bytes(range(32)))
    wrong.write_text(bytes(range(1, 33)).hex() + "\n")  # the hex form
    good.chmod(0o600)
    wrong.chmod(0o600)
    return good, wrong


@pytest.mark.network
def test_signed_link_end_to_end(tmp_path, keys):
    good, _ = keys
    out, sim_out = session(tmp_path, run_key=good, sim_key=good, wait_request=True)
    # the vehicle ignores unsigned frames and sends nothing until asked (--wait-request): it took our
    # signed requests, and we took its signed data
    m = re.search(r"sent (\d+) RAW_IMU .* (\d+) requests", sim_out)
    assert m and int(m.group(1)) > 1000 and int(m.group(2)) >= 1, sim_out
    assert "IMU0 (RAW_IMU, 100.0 Hz)" in out and rejected(out) == 0
    r = re.search(r"link from 1/1: (\d+) frames received, 0 lost", out)
    assert r and int(r.group(1)) >= int(m.group(1)), out
    assert "signing on" in out


@pytest.mark.network
@pytest.mark.parametrize("vehicle", ["wrong key", "unsigned"])
def test_wrong_key_or_unsigned_vehicle_is_refused_and_counted(tmp_path, keys, vehicle):
    good, wrong = keys
    out, sim_out = session(tmp_path, run_key=good, sim_key=wrong if vehicle == "wrong key" else None)
    assert "no IMU data from the vehicle" in out
    assert rejected(out) > 1000, out  # 10000 RAW_IMU and 100 HEARTBEAT sent, none accepted
    # said while running, not only at exit: a stderr warning (and once a STATUSTEXT)
    live = re.search(r"warning: (\d+) frames rejected for their signature so far", out)
    assert live and 0 < int(live.group(1)) <= rejected(out), out
    assert out.index("frames rejected for their signature so far") < out.index("stopping:")
    if vehicle == "wrong key":  # and the vehicle did not take our (differently signed) frames either
        assert re.search(r"received 0 NAMED_VALUE_FLOAT, 0 STATUSTEXT, 0 requests", sim_out), sim_out


@pytest.mark.parametrize("content, msg", [(b"short", "expected a 32-byte key"), (b"z" * 64, "expected a 32-byte key")])
def test_bad_key_files_are_one_line(tmp_path, capsys, content, msg):
    k = tmp_path / "k"
    k.write_bytes(content)
    assert main(["run", "--source", "udpin:127.0.0.1:14999", "--no-state", "--signing-key", str(k)]) == 2
    err = capsys.readouterr().err
    assert msg in err and len(err.strip().splitlines()) == 1
    assert main(["run", "--source", "udpin:127.0.0.1:14999", "--no-state", "--signing-key", str(tmp_path / "none")]) == 2
    assert "no such file" in capsys.readouterr().err


@pytest.mark.network
def test_accept_unsigned_lets_unsigned_in_but_never_a_wrong_signature(monkeypatch):
    import time

    from pymavlink.dialects.v20 import ardupilotmega as m2

    from companion.mavlink.link import LinkStats
    from companion.mavlink.signing import setup_signing
    from companion.sources.connection import open_connection

    monkeypatch.setenv("MAVLINK20", "1")
    key, wrong = bytes(range(32)), bytes(range(1, 33))
    port = free_udp_port()
    conn = open_connection(f"udpin:127.0.0.1:{port}", mavlink2=True)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def encoder(k, sysid):
        mav = m2.MAVLink(None, sysid, 1)
        if k is not None:
            mav.signing.secret_key, mav.signing.sign_outgoing = k, True
            mav.signing.timestamp = int((time.time() - 1420070400) * 1e5)
        return mav

    try:
        setup_signing(conn, key, accept_unsigned=True)
        stats = LinkStats()
        for sysid, k in ((1, None), (2, wrong), (3, key), (4, None)):
            mav = encoder(k, sysid)
            tx.sendto(mav.heartbeat_encode(2, 3, 0, 0, 3).pack(mav), ("127.0.0.1", port))
        got = []
        deadline = time.monotonic() + DEADLINE_S
        while len(got) < 4 and time.monotonic() < deadline:
            msg = conn.recv_match(blocking=True, timeout=0.2)
            if msg is not None:
                stats.on_message(msg)
                got.append(msg)
        assert sorted(m.get_srcSystem() for m in got if m.get_type() == "HEARTBEAT") == [1, 3, 4]
        assert stats.rejected_signature == 1
    finally:
        tx.close()
        conn.close()
