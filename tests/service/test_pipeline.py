"""`companion run` pipeline: still detection, reboots, duplicates, other systems, state, signals, the link."""

from __future__ import annotations

import copy
import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from companion.cli.main import main
from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.state import load_state, save_state
from tests.support.readiness import DEADLINE_S, READY, wait_for_text
from tests.support.sinks import RecordingSink

ROOT = Path(__file__).resolve().parents[2]
KEY = StreamKey(1, 1, "RAW_IMU", 0)
N = 3e-3
FS = 100.0
G = np.array([0.0, 0.0, -9.80665])


def make_pipeline(**cfg):
    sink = RecordingSink()
    p = Pipeline(PipelineConfig.from_mapping({"baseline_s": 200, **cfg}), Reporter(sink, 1.0))
    return p, sink


def still(rng, n):
    return rng.normal(0, N * math.sqrt(FS), (n, 3)), G + rng.normal(0, 0.02, (n, 3))


def feed(p, t, g, a, key=KEY):
    for k in range(t.size):
        p.on_sample(key, t[k], g[k], a[k])


def n_estimate(p, ax="gx"):
    ch = p.channels[0]
    return p.current_params(ch, ax)["N"][0]


@pytest.mark.soak
def test_flight_and_handling_neither_corrupt_nor_flag():
    rng = np.random.default_rng(3)
    p, sink = make_pipeline()
    t0 = 1.0
    segs = []
    g, a = still(rng, 30_000)  # 300 s still: baseline
    segs.append((g, a, False))
    g, a = still(rng, 12_000)  # 120 s armed flight: turning, vibrating
    tt = np.arange(12_000) / FS
    g = g + 0.5 * np.sin(2 * np.pi * 0.3 * tt)[:, None]
    a = a + rng.normal(0, 2.0, a.shape)
    segs.append((g, a, True))
    g, a = still(rng, 6_000)  # 60 s disarmed handling: picked up, tilted, put down in another attitude
    tilt = np.clip(np.arange(6_000) / 3_000.0, 0, 1)[:, None]
    a = a + tilt * np.array([3.0, 0.0, 0.5]) + rng.normal(0, 0.8, a.shape) * (tilt < 1)
    g = g + 0.3 * np.sin(2 * np.pi * 0.2 * np.arange(6_000) / FS)[:, None] * (tilt < 1)
    segs.append((g, a, False))
    g, a = still(rng, 60_000)  # 600 s still again, in the new attitude
    a = a + np.array([3.0, 0.0, 0.5])
    segs.append((g, a, False))
    for g, a, armed in segs:
        p.on_heartbeat(1, 2, 3, 128 if armed else 0)
        t = t0 + np.arange(g.shape[0]) / FS
        t0 = t[-1] + 1 / FS
        feed(p, t, g, a)
    ch = p.channels[0]
    assert ch.counts["blocks_moving"] >= 150 - 2  # flight (120 s) + handling (30 s) seen as moving
    assert ch.fed_s < 300 + 30 + 600 + 1  # the still parts only (the last 30 s of handling are still)
    assert p.transitions == [] and not any("degrading" in t for _, t in sink.texts)
    n_true = math.sqrt(N**2 + 0.0)  # no rounding here
    for ax in ("gx", "gy", "gz"):
        assert n_estimate(p, ax) == pytest.approx(n_true, rel=0.03)
    assert sink.values["IMU0G_HLTH"] == 0.0


def test_reboot_duplicates_and_other_systems():
    rng = np.random.default_rng(5)
    p, sink = make_pipeline()
    g, a = still(rng, 40_000)
    t = 1.0 + np.arange(40_000) / FS
    t[25_000:] -= t[25_000] - 0.5  # autopilot reboot: time since boot starts again
    other = StreamKey(2, 1, "RAW_IMU", 0)
    for k in range(t.size):
        p.on_sample(KEY, t[k], g[k], a[k])
        if k % 1000 == 0:
            p.on_sample(KEY, t[k], g[k], a[k])  # duplicated packet
        if k % 3 == 0:  # another vehicle on the same link, ten times noisier
            p.on_sample(other, t[k], 10 * g[k], a[k])
    p.on_sample(StreamKey(1, 1, "SCALED_IMU", 0), 500.0, (9.0, 9.0, 9.0), G)  # same IMU, other message: ignored
    c = p.channels[0].counts
    assert c["resets"] == 1 and c["duplicates"] == 40
    assert p.ignored["other_sysid"] == math.ceil(40_000 / 3) and p.ignored["other_message"] == 1
    assert n_estimate(p) == pytest.approx(N, rel=0.03)
    assert p.transitions == []


def test_health_leaves_learning_when_the_baseline_is_learned_not_at_the_next_check():
    """HLTH 2 is 'no baseline yet': the first HLTH sent after 'baseline learned' is the IMU's health (0 here),
    not 2 until the next check_s of message time."""
    rng = np.random.default_rng(12)
    g, a = still(rng, 26_000)
    p, sink = make_pipeline()
    feed(p, 1.0 + np.arange(26_000) / FS, g, a)
    k = next(i for i, m in enumerate(sink.msgs) if m[0] == "T" and "baseline learned" in m[2])
    after = [m[2] for m in sink.msgs[k:] if m[0] != "T" and m[1] == "IMU0G_HLTH"]
    assert after and after[0] == 0.0, after[:5]


def test_state_round_trip_keeps_baseline_and_estimates(tmp_path):
    # a 100-s baseline learned in the first 150 s (the state's contents do not depend on its length)
    rng = np.random.default_rng(11)
    g, a = still(rng, 30_000)
    t = 1.0 + np.arange(30_000) / FS
    p1, _ = make_pipeline(baseline_s=100)
    feed(p1, t[:15_000], g[:15_000], a[:15_000])
    # the same data without a restart: a copy of p1 before its state is taken (the pipeline is deterministic,
    # so this is exactly a fresh pipeline fed the first half; its second half is fed below)
    p3 = copy.deepcopy(p1)
    save_state(tmp_path / "s.json", p1.state_dict())
    p2, sink2 = make_pipeline(baseline_s=100)
    assert load_state(tmp_path / "s.json", p2.load_state_dict, warn=pytest.fail)
    assert p2.baseline is not None and p2.baseline.get(0, "gx")["N"] == p1.baseline.get(0, "gx")["N"]
    assert p2.channels[0].learn == {}
    feed(p2, t[15_000:], g[15_000:], a[15_000:])
    feed(p3, t[15_000:], g[15_000:], a[15_000:])
    assert n_estimate(p2) == pytest.approx(n_estimate(p3), rel=0.01)
    assert not any("baseline learned" in s for _, s in sink2.texts)  # not learned again
    assert sink2.values["IMU0G_HLTH"] == 0.0


def test_corrupt_and_foreign_state_give_a_warning_and_a_fresh_start(tmp_path):
    warnings = []
    for name, text in (("garbage.json", "{not json"), ("foreign.json", json.dumps({"format": "other", "x": 1})),
                       ("bad.json", json.dumps({"format": "companion-run-state", "version": 1,
                                                "channels": {"0": {"message": "RAW_IMU"}}}))):
        f = tmp_path / name
        f.write_text(text)
        p, _ = make_pipeline()
        assert not load_state(f, p.load_state_dict, warnings.append)
        assert p.channels == {} and p.baseline is None
        assert (tmp_path / (name + ".bad")).exists() and not f.exists()
    assert len(warnings) == 3 and all("starting fresh" in w for w in warnings)


def test_replay_cli_with_corrupt_state_file(tmp_path, capsys):
    from companion.mavlink.tlog_writer import write_imu_tlog

    rng = np.random.default_rng(2)
    # 90 s with a 60 s baseline: the fresh start learns its baseline and is judged healthy against it (the
    # state is read before the first sample; a longer record only repeats the checks)
    g, a = still(rng, 9_000)
    write_imu_tlog(tmp_path / "x.tlog", 1.0 + np.arange(9_000) / FS, g, a)
    (tmp_path / "state.json").write_text("\x00\x01garbage")
    rc = main(["run", "--source", str(tmp_path / "x.tlog"), "--state", str(tmp_path / "state.json"), "--quiet",
               "--baseline-s", "60"])
    cap = capsys.readouterr()
    assert rc == 0
    assert "not usable" in cap.err and "Traceback" not in cap.err
    assert "IMU0 (RAW_IMU, 100.0 Hz): healthy" in cap.out
    assert json.loads((tmp_path / "state.json").read_text())["format"] == "companion-run-state"
    # second run, the next log: restored from the state, the baseline is kept (no second "baseline learned")
    g, a = still(rng, 9_000)
    write_imu_tlog(tmp_path / "y.tlog", 1.0 + np.arange(9_000) / FS, g, a)
    rc = main(["run", "--source", str(tmp_path / "y.tlog"), "--state", str(tmp_path / "state.json")])
    cap = capsys.readouterr()
    assert rc == 0 and "state restored" in cap.err and "baseline learned" not in cap.out


def test_a_log_replayed_again_into_its_state_is_refused(tmp_path, capsys):
    """The same log (or a renamed copy) replayed into the state that holds it would feed every sample twice
    (the still time doubles, the intervals narrow by sqrt(2)): one error line, the state untouched."""
    from companion.mavlink.tlog_writer import write_imu_tlog

    rng = np.random.default_rng(3)
    g, a = still(rng, 6_000)
    write_imu_tlog(tmp_path / "x.tlog", 1.0 + np.arange(6_000) / FS, g, a)
    state = tmp_path / "state.json"
    assert main(["run", "--source", str(tmp_path / "x.tlog"), "--state", str(state), "--quiet", "--baseline-s", "30"]) == 0
    capsys.readouterr()
    before = state.read_bytes()
    (tmp_path / "copy.tlog").write_bytes((tmp_path / "x.tlog").read_bytes())
    for name in ("x.tlog", "copy.tlog"):
        rc = main(["run", "--source", str(tmp_path / name), "--state", str(state), "--quiet"])
        cap = capsys.readouterr()
        lines = [x for x in cap.err.splitlines() if x.startswith("companion: error")]
        assert rc == 2 and len(lines) == 1 and "already holds this log" in lines[0], cap.err
        assert "Traceback" not in cap.err
        assert state.read_bytes() == before
    # without the state it replays as any log
    assert main(["run", "--source", str(tmp_path / "x.tlog"), "--no-state", "--quiet"]) == 0


def test_run_baseline_learned_line_in_datasheet_units(tmp_path, capsys):
    from companion.mavlink.tlog_writer import write_imu_tlog
    from companion.units import to_datasheet

    rng = np.random.default_rng(2)
    g, a = still(rng, 9_000)
    write_imu_tlog(tmp_path / "x.tlog", 1.0 + np.arange(9_000) / FS, g, a)
    assert main(["run", "--source", str(tmp_path / "x.tlog"), "--no-state", "--baseline-s", "60"]) == 0
    cap = capsys.readouterr()
    line = next(x for x in (cap.out + cap.err).splitlines() if "baseline learned from" in x)
    # deg/sqrt(h) first, as every other console figure; SI only in brackets
    head, si = line.split(" deg/sqrt(h) [")
    assert si.endswith(" rad/s/sqrt(Hz)])")
    n_si = float(si.split()[0])
    n_deg = float(head.rsplit("gx N ", 1)[1])
    assert n_deg == pytest.approx(to_datasheet("N", n_si), rel=2e-2)
    assert n_deg == pytest.approx(to_datasheet("N", N), rel=0.1)  # the simulated white noise


@pytest.mark.parametrize("argv, msg", [
    (["run", "--source", "nonsense"], "unknown source"),
    (["run", "--source", "missing.tlog"], "no such file"),
    (["run", "--source", "x.tlog", "--baseline", "missing.json"], "no such file"),
    (["run", "--source", "udpin:127.0.0.1:99999"], "port"),
    (["sim-autopilot", "--model", "missing.yaml", "--connect", "udpout:127.0.0.1:14550"], "missing.yaml"),
])
def test_user_errors_are_one_line(argv, msg, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2 and msg in err and len(err.strip().splitlines()) == 1


@pytest.mark.network
def test_sigterm_saves_state_and_exits_cleanly(tmp_path):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    errf = tmp_path / "err.txt"
    with open(errf, "w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "companion", "run", "--source", f"udpin:127.0.0.1:{port}",
                                 "--state", str(tmp_path / "st.json"), "--duration", "600", "--quiet"], env=env,
                                stdout=subprocess.DEVNULL, stderr=fh, text=True)
    try:
        wait_for_text(errf, READY, proc)  # readiness line, not a fixed sleep
        proc.send_signal(signal.SIGTERM)
        proc.wait(DEADLINE_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
    err = errf.read_text()
    assert proc.returncode == 5, err  # a normal end from its summary: nothing arrived (EXIT_NO_DATA)
    assert "Traceback" not in err
    assert json.loads((tmp_path / "st.json").read_text())["format"] == "companion-run-state"


@pytest.mark.network
def test_link_identity_and_replies_only_to_the_imu_sender():
    """udpin: the vehicle (MAVLink 2, so pymavlink switches its encoder) gets our HEARTBEAT as onboard
    controller 191 with its own sysid and our reports; another peer writing to the port gets nothing."""
    from pymavlink.dialects.v20 import ardupilotmega as m2

    from companion.mavlink.link import Link, LinkConfig
    from companion.sources.connection import open_connection

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    conn = open_connection(f"udpin:127.0.0.1:{port}")
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    intruder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.settimeout(0.3)
    intruder.settimeout(0.5)
    enc_v, enc_i = m2.MAVLink(None, 7, 1), m2.MAVLink(None, 9, 1)
    try:
        link = Link(conn, LinkConfig(), sysid=None)
        intruder.sendto(enc_i.heartbeat_encode(6, 8, 0, 0, 4).pack(enc_i), ("127.0.0.1", port))
        time.sleep(0.05)  # pacing: the intruder's datagram queued first (same process; no wait for another)
        vehicle.sendto(enc_v.heartbeat_encode(2, 3, 0, 0, 3).pack(enc_v), ("127.0.0.1", port))
        vehicle.sendto(enc_v.raw_imu_encode(1_000_000, 0, 0, -1000, 1, 2, 3, 0, 0, 0).pack(enc_v), ("127.0.0.1", port))
        got = []
        deadline = time.monotonic() + 5
        while len(got) < 3 and time.monotonic() < deadline:
            m = conn.recv_match(blocking=True, timeout=0.2)
            if m is not None:
                got.append(m)
                link.on_message(m, is_vehicle_imu=m.get_type() == "RAW_IMU")
        assert [m.get_type() for m in got] == ["HEARTBEAT", "HEARTBEAT", "RAW_IMU"]
        assert link.sysid == 7 and link.autopilot_compid == 1
        link.service()  # our heartbeat (and a request for IMU data)
        link.send_named_value_float(1000, "IMU0GX_N", 1.5)
        dec = m2.MAVLink(None)
        rx = []
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline and not any(m.get_type() == "NAMED_VALUE_FLOAT" for m in rx):
            try:
                data = vehicle.recv(4096)
            except socket.timeout:
                continue
            rx.extend(dec.parse_buffer(data) or [])
        hb = [m for m in rx if m.get_type() == "HEARTBEAT"][0]
        assert hb.type == 18 and hb.get_srcSystem() == 7 and hb.get_srcComponent() == 191
        assert any(m.get_type() == "NAMED_VALUE_FLOAT" and m.name == "IMU0GX_N" for m in rx)
        with pytest.raises(socket.timeout):
            intruder.recv(4096)  # nothing for the other peer
    finally:
        conn.close()
        vehicle.close()
        intruder.close()


@pytest.mark.network
def test_a_first_rate_below_the_request_is_not_yet_a_drop_and_a_later_one_is():
    """The first IMU data may come before the first request took effect: said as 'not yet', not counted as a
    rate drop nor blamed on another client; once the rate was as asked, a fall below it is both."""
    from companion.mavlink.link import Link, LinkConfig
    from companion.sources.connection import open_connection

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    conn = open_connection(f"udpin:127.0.0.1:{port}")
    now, said = [0.0], []
    try:
        link = Link(conn, LinkConfig(rate_hz=100.0, retry_s=5.0), sysid=1, clock=lambda: now[0], log=said.append)
        link.acked = True  # SET_MESSAGE_INTERVAL accepted: 100 Hz is what is asked
        for t, hz in ((1.0, 50.0), (2.0, 100.0), (10.0, 100.0), (11.0, 40.0), (20.0, 100.0)):
            now[0] = t
            link.last_imu_wall = t
            link.check_rate(hz)
        assert link.rate_drops == 1, said
        assert [x.split(":")[0] for x in said] == ["IMU rate 50.0 Hz, not yet the 100 Hz asked for",
                                                   "IMU rate 100 Hz, as asked",
                                                   "IMU rate 40.0 Hz, below the 100 Hz asked for (another client's stream request?)",
                                                   "IMU rate back to 100 Hz"]
        # the data stop (an autopilot reboot) and come back at its default rate: "not yet" again, no drop
        said.clear()
        now[0] = 40.0
        link.service()  # 20 s without IMU data: stale
        for t, hz in ((42.0, 50.0), (44.0, 100.0)):
            now[0] = t
            link.last_imu_wall = t
            link.check_rate(hz)
        assert link.rate_drops == 1, said
        assert [x.split(":")[0] for x in said if x.startswith("IMU rate")] == [
            "IMU rate 50.0 Hz, not yet the 100 Hz asked for", "IMU rate 100 Hz, as asked"], said
    finally:
        conn.close()


@pytest.mark.network
def test_link_asks_again_when_data_stops_and_falls_back():
    """Wall-clock logic of the link with a fake clock: heartbeat every second, requests every retry_s while
    there is no data, REQUEST_DATA_STREAM added to the third request when two went unanswered, quiet while data flows."""
    from companion.mavlink.link import Link, LinkConfig
    from companion.sources.connection import open_connection

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    conn = open_connection(f"udpin:127.0.0.1:{port}")
    now = [0.0]
    try:
        link = Link(conn, LinkConfig(stale_s=3.0, retry_s=5.0), sysid=1, clock=lambda: now[0])
        seq = []
        for t in (0.0, 2.0, 5.0, 6.0, 7.0, 8.5, 12.0, 13.0):
            now[0] = t
            if t in (6.0, 7.0, 8.5):
                link.last_imu_wall = t  # data flowing
            link.service()
            seq.append((t, link.requests, link.use_data_stream))
        assert seq == [(0.0, 1, False), (2.0, 1, False), (5.0, 2, False), (6.0, 2, False), (7.0, 2, False),
                       (8.5, 2, False), (12.0, 3, True), (13.0, 3, True)]
        assert link.sent == 8 + 3 * 3 + 1  # 8 heartbeats, 3 requests x 3 messages, 1 REQUEST_DATA_STREAM
    finally:
        conn.close()
