"""The companion in a real chain over loopback: `companion sim-autopilot` -> MAVProxy (from PyPI, as the
router) -> `companion run --gcs udpout:...` -> a pymavlink ground-station listener. MAVProxy does not
forward what its --out peer sends to its other outputs, so the reports reach the GCS through --gcs.
Every wait is for a signal with a generous deadline; every process is killed at the end.

Test model: white noise N = 3e-3 rad/s/sqrt(Hz) per gyro axis at 100 Hz; a stuck gyro X after the
baseline is learned gives alarm STATUSTEXTs besides the reports.
"""

from __future__ import annotations

import re
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest
from readiness import READY, wait_for_text

from loopback import free_udp_port, read_record, start, stop

pytestmark = [pytest.mark.network,
              pytest.mark.skipif(shutil.which("mavproxy.py") is None, reason="MAVProxy not installed")]

MODEL = """rate_hz: 100
axes:
  gx: [{effect: white_noise, N: 3e-3}]
  gy: [{effect: white_noise, N: 3e-3}]
  gz: [{effect: white_noise, N: 3e-3}]
"""
COMPANION = 191  # MAV_COMP_ID_ONBOARD_COMPUTER: the component id the companion sends with


class Listener:
    """A ground station: pymavlink on udpin:127.0.0.1:PORT in a thread, keeping every NAMED_VALUE_FLOAT
    name, STATUSTEXT text and HEARTBEAT of the companion (component 191) it receives, with its arrival time."""

    def __init__(self, port: int):
        from pymavlink import mavutil

        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, robust_parsing=True)
        self.names: dict[str, float] = {}
        self.texts: list[tuple[float, str]] = []
        self.heartbeats = 0
        self.health: list[tuple[float, float]] = []  # (arrival, IMU0G_HLTH value)
        self.lock = threading.Lock()
        self._stop = False
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self):
        while not self._stop:
            msg = self.conn.recv_match(blocking=True, timeout=0.2)
            if msg is None or msg.get_srcComponent() != COMPANION:
                continue
            with self.lock:
                t = msg.get_type()
                if t == "NAMED_VALUE_FLOAT":
                    self.names[msg.name] = msg.value
                    if msg.name == "IMU0G_HLTH":
                        self.health.append((time.monotonic(), msg.value))
                elif t == "STATUSTEXT":
                    self.texts.append((time.monotonic(), msg.text))
                elif t == "HEARTBEAT":
                    self.heartbeats += 1

    def wait_for(self, cond, timeout=60.0) -> bool:
        """Poll until ``cond(self)`` holds (True) or the deadline passes (False)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if cond(self):
                    return True
            time.sleep(0.05)  # polling interval, not a wait for another process
        with self.lock:
            return bool(cond(self))

    def close(self):
        self._stop = True
        self.thread.join(5)
        self.conn.close()


def start_mavproxy(tmp_path, master_port, out_port, default_streamrate=False, name="mavproxy.out"):
    """MAVProxy as the router: the vehicle on --master (udpin), the companion on --out (udpout)."""
    args = [shutil.which("mavproxy.py"), f"--master=udpin:127.0.0.1:{master_port}",
            f"--out=udpout:127.0.0.1:{out_port}", "--daemon", "--non-interactive", "--no-state",
            "--default-modules=", "--nowait"]
    if not default_streamrate:
        args.append("--streamrate=-1")
    return subprocess.Popen(args, cwd=tmp_path, stdout=open(tmp_path / name, "w"), stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, start_new_session=True)


def sent_by_companion(tlog: Path):
    """(NAMED_VALUE_FLOAT names, STATUSTEXT texts) the companion sent, decoded by pymavlink from its --out-tlog."""
    from pymavlink import mavutil

    names, texts = set(), []
    conn = mavutil.mavlink_connection(str(tlog), robust_parsing=True)
    while True:
        m = conn.recv_match(type=["NAMED_VALUE_FLOAT", "STATUSTEXT"])
        if m is None:
            break
        if m.get_srcComponent() != COMPANION:
            continue
        if m.get_type() == "NAMED_VALUE_FLOAT":
            names.add(m.name)
        else:
            texts.append(m.text)
    conn.close()
    return names, texts


def test_reports_reach_a_gcs_behind_mavproxy_through_gcs_output(tmp_path):
    (tmp_path / "model.yaml").write_text(MODEL)
    p_master, p_run, p_gcs = free_udp_port(), free_udp_port(), free_udp_port()
    gcs = Listener(p_gcs)
    procs = []
    duration, speedup = 170.0, 10.0
    try:
        procs.append(start_mavproxy(tmp_path, p_master, p_run))
        run = start(["run", "--source", f"udpin:127.0.0.1:{p_run}", "--gcs", f"udpout:127.0.0.1:{p_gcs}",
                     "--no-state", "--baseline-s", "60", "--duration", "300", "--out-tlog",
                     str(tmp_path / "run.tlog")], tmp_path, "run.out")
        procs.append(run)
        wait_for_text(tmp_path / "run.out", READY, run)
        sim = start(["sim-autopilot", "--model", "model.yaml", "--connect", f"udpout:127.0.0.1:{p_master}",
                     "--speedup", str(speedup), "--duration", str(duration), "--wait-request",
                     "--fault", "stuck", "--fault-at", "110", "--fault-axis", "gx", "--wall-limit", "120",
                     "--record", "rx.jsonl", "--quiet"], tmp_path, "sim.out")
        procs.append(sim)
        sim.wait(240)  # bounded by its --wall-limit
        assert sim.returncode == 0, (tmp_path / "sim.out").read_text()
        assert stop(run) == 0, (tmp_path / "run.out").read_text()
        names, texts = sent_by_companion(tmp_path / "run.tlog")
        assert {"IMU0GX_N", "IMU0G_HLTH", "IMU0G_FLT"} <= names, names
        assert any("stuck" in t for t in texts), texts  # an alarm was sent
        assert any("baseline learned" in t for t in texts), texts
        # everything the companion sent is at the GCS (UDP on loopback: wait for the listener to catch up)
        ok = gcs.wait_for(lambda g: names <= set(g.names) and sorted(texts) == sorted(t for _, t in g.texts))
        assert ok, (sorted(names - set(gcs.names)), texts, gcs.texts)
        assert gcs.heartbeats > 0
        # the last values the GCS got are those of the run summary (one source of truth)
        out = (tmp_path / "run.out").read_text()
        counted = re.search(r"stopping: \d+ messages sent, (\d+) NAMED_VALUE_FLOAT, (\d+) STATUSTEXT", out)
        assert counted and int(counted.group(2)) == len(texts), (counted, texts)  # the exit line counts right
        m = re.search(r"^  gy: N ([\d.]+) \+- [\d.]+ .*?; B (<? ?)([\d.e+]+) deg/h; K (<? ?)([\d.e+]+) deg/h\^1.5", out, re.M)
        assert m, out
        with gcs.lock:
            last = dict(gcs.names)
        assert last["IMU0GY_N"] == pytest.approx(float(m.group(1)), rel=2e-3, abs=1e-3)
        for param, bound, value in (("B", m.group(2), m.group(3)), ("K", m.group(4), m.group(5))):
            assert last[f"IMU0GY_{param}"] == pytest.approx(float(value), rel=1e-2, abs=0.5), (param, last, m.group(0))
            assert (last[f"IMU0GY_{param}S"] == -1.0) == bool(bound.strip())  # a bound is sent with sigma -1
    finally:
        for p in procs:
            stop(p, signal.SIGKILL)
        gcs.close()


FAULT_WORDS = ("stuck", "noise", "bias", "spike", "drift", "saturat", "rate", "timing", "disagree", "degrad")


def imu_times(tlog: Path):
    """Message times (s) of the RAW_IMU frames the companion received, decoded by pymavlink from its --out-tlog."""
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(tlog), robust_parsing=True)
    t = []
    while True:
        m = conn.recv_match(type="RAW_IMU")
        if m is None:
            break
        t.append(m.time_usec * 1e-6)
    conn.close()
    return t


def low_rate_episodes(t, rate_hz, min_s=1.0):
    """(start, length) in message time of the stretches where the stream ran below 0.8 x ``rate_hz``
    (intervals longer than 1.25 / rate), at least ``min_s`` long."""
    out, start, last = [], None, None
    for a, b in zip(t, t[1:]):
        slow = b - a > 1.25 / rate_hz
        if slow and start is None:
            start = a
        elif not slow and start is not None:
            if a - start >= min_s:
                out.append((start, a - start))
            start = None
        last = b
    if start is not None and last - start >= min_s:
        out.append((start, last - start))
    return out


def test_mavproxy_default_stream_rates_beside_the_companion_raise_no_alarm(tmp_path):
    """An autopilot that refuses SET_MESSAGE_INTERVAL, MAVProxy with its default stream-rate behaviour
    (REQUEST_DATA_STREAM of all streams at 4 Hz, again every 15 s of wall clock): the IMU rate falls from
    50 to 4 Hz; the companion asks again and gets it back within 10 s of wall clock each time, and no
    alarm is raised (a rate change is not a gyro fault)."""
    (tmp_path / "model.yaml").write_text(MODEL)
    p_master, p_run, p_gcs = free_udp_port(), free_udp_port(), free_udp_port()
    gcs = Listener(p_gcs)
    procs = []
    duration, speedup = 360.0, 8.0
    try:
        procs.append(start_mavproxy(tmp_path, p_master, p_run, default_streamrate=True))
        run = start(["run", "--source", f"udpin:127.0.0.1:{p_run}", "--gcs", f"udpout:127.0.0.1:{p_gcs}",
                     "--no-state", "--baseline-s", "60", "--duration", "300", "--out-tlog",
                     str(tmp_path / "run.tlog")], tmp_path, "run.out")
        procs.append(run)
        wait_for_text(tmp_path / "run.out", READY, run)
        sim = start(["sim-autopilot", "--model", "model.yaml", "--connect", f"udpout:127.0.0.1:{p_master}",
                     "--speedup", str(speedup), "--duration", str(duration), "--wait-request", "--refuse-interval",
                     "--wall-limit", "150", "--record", "rx.jsonl"], tmp_path, "sim.out")
        procs.append(sim)
        sim.wait(300)  # bounded by its --wall-limit
        assert sim.returncode == 0, (tmp_path / "sim.out").read_text()
        assert stop(run) == 0, (tmp_path / "run.out").read_text()
    finally:
        for p in procs:
            stop(p, signal.SIGKILL)
        gcs.close()
    out = (tmp_path / "run.out").read_text()
    sim_out = (tmp_path / "sim.out").read_text()
    assert "REQUEST_DATA_STREAM 0 at 4 Hz" in sim_out, sim_out  # MAVProxy did ask for 4 Hz
    t = imu_times(tmp_path / "run.tlog")
    assert t and t[-1] - t[0] > 0.8 * duration
    drops = low_rate_episodes(t, 50.0)
    assert drops, "MAVProxy's requests never lowered the rate: the test shows nothing"
    for start_t, length in drops:
        assert length / speedup < 10.0, (drops, out)  # wall-clock seconds at the reduced rate
    assert "asking again" in out
    texts = [d["text"] for d in read_record(tmp_path / "rx.jsonl")[1]]
    assert not [x for x in texts if any(w in x.lower() for w in FAULT_WORDS)], texts
    assert "IMU0 gyro baseline learned" in texts, texts


def test_router_outage_texts_reach_the_gcs_and_health_leaves_stale_at_once(tmp_path):
    """MAVProxy killed while data flow, restarted after two "data stopped" texts (>= 10 s): the GCS
    (behind --gcs) gets "IMU data stopped" while the router is down and "IMU data back" after it; the
    health IMU0G_HLTH it receives is 3 (stale) during the outage and leaves 3 within 2 s of "data back"."""
    (tmp_path / "model.yaml").write_text(MODEL)
    p_master, p_run, p_gcs = free_udp_port(), free_udp_port(), free_udp_port()
    gcs = Listener(p_gcs)
    procs = []
    try:
        proxy = start_mavproxy(tmp_path, p_master, p_run)
        procs.append(proxy)
        run = start(["run", "--source", f"udpin:127.0.0.1:{p_run}", "--gcs", f"udpout:127.0.0.1:{p_gcs}",
                     "--no-state", "--baseline-s", "60", "--duration", "300"], tmp_path, "run.out")
        procs.append(run)
        wait_for_text(tmp_path / "run.out", READY, run)
        sim = start(["sim-autopilot", "--model", "model.yaml", "--connect", f"udpout:127.0.0.1:{p_master}",
                     "--speedup", "4", "--wait-request", "--wall-limit", "200", "--quiet"], tmp_path, "sim.out")
        procs.append(sim)
        assert gcs.wait_for(lambda g: "IMU0G_HLTH" in g.names, 120), (tmp_path / "run.out").read_text()
        stop(proxy, signal.SIGKILL)
        t_kill = time.monotonic()
        stopped = lambda g: [t for t, x in g.texts if x.startswith("companion: IMU data stopped")]  # noqa: E731
        assert gcs.wait_for(lambda g: len(stopped(g)) >= 2, 120), (gcs.texts, (tmp_path / "run.out").read_text())
        assert gcs.wait_for(lambda g: any(v == 3.0 for _, v in g.health), 30)
        procs.append(start_mavproxy(tmp_path, p_master, p_run, name="mavproxy2.out"))
        back = lambda g: [t for t, x in g.texts if x.startswith("companion: IMU data back")]  # noqa: E731
        assert gcs.wait_for(lambda g: back(g), 120), (gcs.texts, (tmp_path / "run.out").read_text())
        t_back = back(gcs)[0]
        assert gcs.wait_for(lambda g: any(t >= t_back - 0.5 and v != 3.0 for t, v in g.health), 30)
        with gcs.lock:
            first_ok = min(t for t, v in gcs.health if t >= t_back - 0.5 and v != 3.0)
            later_stale = [t for t, v in gcs.health if t > first_ok and v == 3.0]
        assert first_ok - t_back < 2.0
        assert not later_stale
        assert stopped(gcs)[0] > t_kill
    finally:
        for p in procs:
            stop(p, signal.SIGKILL)
        gcs.close()
