"""Helpers for the chain tests and benchmarks: `companion sim-autopilot` -> a router (MAVProxy from PyPI) ->
`companion run --gcs udpout:...` -> a pymavlink ground-station listener, all over UDP on 127.0.0.1.

Not a test file: tests/loopback/test_chain.py and benchmarks/bench_chain.py import from here. Every wait is for a
signal with a deadline; every process started here is the caller's to stop.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from tests.support.readiness import READY, wait_for_text

from tests.support.loopback import MODEL, free_udp_port, start, stop

COMPANION = 191  # MAV_COMP_ID_ONBOARD_COMPUTER: the component id the companion sends with
FAULT_WORDS = ("stuck", "dead", "noise", "bias", "spike", "drift", "saturat", "rate", "timing", "disagree", "degrad")


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
        self.received = 0  # the companion's messages received so far: an arrival order free of the wall clock
        #: (arrival order, IMU0G_HLTH value, its message time in s); texts as (arrival order, text)
        self.health_seq: list[tuple[int, float, float]] = []
        self.texts_seq: list[tuple[int, str]] = []
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
                self.received += 1
                t = msg.get_type()
                if t == "NAMED_VALUE_FLOAT":
                    self.names[msg.name] = msg.value
                    if msg.name == "IMU0G_HLTH":
                        self.health.append((time.monotonic(), msg.value))
                        self.health_seq.append((self.received, msg.value, msg.time_boot_ms / 1000.0))
                elif t == "STATUSTEXT":
                    self.texts.append((time.monotonic(), msg.text))
                    self.texts_seq.append((self.received, msg.text))
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
    return subprocess.Popen(args, cwd=tmp_path, stdout=open(Path(tmp_path) / name, "w"), stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, start_new_session=True)


def mavlink_routerd() -> str | None:
    """The mavlink-router binary: $MAVLINK_ROUTERD, else ``mavlink-routerd`` on PATH (no Debian or PyPI
    package carries it: built from its source)."""
    import os

    path = os.environ.get("MAVLINK_ROUTERD") or shutil.which("mavlink-routerd")
    return path if path and os.access(path, os.X_OK) else None


def start_mavlink_router(tmp_path, master_port, endpoint_ports, name="router.out"):
    """mavlink-router as the router on the companion computer: the vehicle on a UDP server port (``master_port``),
    each of ``endpoint_ports`` a UDP client endpoint (the companion, the GCS); no TCP port."""
    args = [mavlink_routerd(), "-t", "0"]
    for port in endpoint_ports:
        args += ["-e", f"127.0.0.1:{port}"]
    args.append(f"127.0.0.1:{master_port}")
    return subprocess.Popen(args, cwd=tmp_path, stdout=open(Path(tmp_path) / name, "w"), stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, start_new_session=True)


@dataclass
class Chain:
    """The processes and ports of one chain; ``procs`` holds every process started, for the caller to stop."""

    tmp_path: Path
    p_master: int
    p_run: int
    p_gcs: int
    gcs: Listener
    proxy: subprocess.Popen
    run: subprocess.Popen
    procs: list = field(default_factory=list)

    def restart_proxy(self, default_streamrate=False, name="mavproxy2.out"):
        """MAVProxy again on the same ports (after the caller killed ``proxy``)."""
        self.proxy = start_mavproxy(self.tmp_path, self.p_master, self.p_run, default_streamrate, name)
        self.procs.append(self.proxy)
        return self.proxy

    def start_sim(self, sim_args, name="sim.out"):
        """``companion sim-autopilot --model model.yaml --connect`` MAVProxy's master port, with ``sim_args``."""
        sim = start(["sim-autopilot", "--model", "model.yaml", "--connect", f"udpout:127.0.0.1:{self.p_master}",
                     *sim_args], self.tmp_path, name)
        self.procs.append(sim)
        return sim

    def close(self):
        for p in self.procs:
            stop(p, signal.SIGKILL)
        self.gcs.close()


def start_chain(tmp_path, run_args=(), default_streamrate=False, model=MODEL) -> Chain:
    """MAVProxy (the router), `companion run --source` its --out port ``--gcs`` a Listener, ``run_args``
    added; returns once run listens. The caller starts the vehicle (``Chain.start_sim``) and calls
    ``Chain.close`` in a ``finally``."""
    tmp_path = Path(tmp_path)
    (tmp_path / "model.yaml").write_text(model)
    p_master, p_run, p_gcs = free_udp_port(), free_udp_port(), free_udp_port()
    gcs = Listener(p_gcs)
    procs = []
    try:
        proxy = start_mavproxy(tmp_path, p_master, p_run, default_streamrate)
        procs.append(proxy)
        run = start(["run", "--source", f"udpin:127.0.0.1:{p_run}", "--gcs", f"udpout:127.0.0.1:{p_gcs}",
                     "--no-state", *run_args], tmp_path, "run.out")
        procs.append(run)
        wait_for_text(tmp_path / "run.out", READY, run)
    except BaseException:
        Chain(tmp_path, p_master, p_run, p_gcs, gcs, procs[0] if procs else None, None, procs).close()
        raise
    return Chain(tmp_path, p_master, p_run, p_gcs, gcs, proxy, run, procs)


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


def low_rate_episodes(t, rate_hz, min_s=1.0, gap_s=None):
    """(start, length) in message time of the stretches where the stream ran below 0.8 x ``rate_hz``
    (intervals longer than 1.25 / rate), at least ``min_s`` long. With ``gap_s``, an interval longer than
    that (an outage: no data at all) ends a stretch and is not counted in it."""
    out, start_t, last = [], None, None
    for a, b in zip(t, t[1:]):
        dt = b - a
        slow = dt > 1.25 / rate_hz and (gap_s is None or dt <= gap_s)
        if slow and start_t is None:
            start_t = a
        elif not slow and start_t is not None:
            if a - start_t >= min_s:
                out.append((start_t, a - start_t))
            start_t = None
        last = b
    if start_t is not None and last - start_t >= min_s:
        out.append((start_t, last - start_t))
    return out
