"""A lossy UDP relay between `companion sim-autopilot` and `companion run` on 127.0.0.1, and the loop through
it: what tests/mavlink/test_link.py checks and benchmarks/bench_loss.py measures (not a test file, so both
can import it).

Test model: white noise N = 3e-3 rad/s/sqrt(Hz) per gyro axis at 100 Hz with 1 mrad/s rounding.
"""

from __future__ import annotations

import collections
import math
import random
import signal
import socket
import subprocess
import sys
import threading
import time

from tests.support.readiness import DEADLINE_S, READY, kill_left, udp_rx_queue, wait_for_text

from tests.support.loopback import MODEL, N_SI, RATE, env, free_udp_port
from tests.support.run_status import expected_run_status

N_TRUE = math.sqrt(N_SI**2 + 1e-6 / (12 * RATE)) * 180 / math.pi * 60  # deg/sqrt(h), with the LSB rounding


class LossyRelay(threading.Thread):
    """Forwards datagrams between the vehicle (sim-autopilot) and `companion run`, dropping vehicle->run
    datagrams: independently with ``p`` (random) or in bursts (Gilbert model: good->bad ``p_gb``,
    bad->good ``p_bg``, everything lost while bad). Counts what it dropped. What it keeps is queued and
    handed on as fast as `run` reads it (its socket's receive queue stays under 64 KiB), so on a busy
    machine the only losses are the relay's own, and the test knows exactly how many there were."""

    QUEUE_LIMIT = 64 << 10

    def __init__(self, run_port: int, seed: int, p: float = 0.0, burst: tuple[float, float] | None = None):
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.run_port = run_port
        self.run_addr = ("127.0.0.1", run_port)
        self.rng = random.Random(seed)
        self.p, self.burst = p, burst
        self.bad = False
        self.vehicle = None
        self.forwarded = self.dropped = 0
        self.pending = collections.deque()
        self.stop = threading.Event()

    def lose(self) -> bool:
        if self.burst is None:
            return self.rng.random() < self.p
        p_gb, p_bg = self.burst
        self.bad = (self.rng.random() >= p_bg) if self.bad else (self.rng.random() < p_gb)
        return self.bad

    def forward(self) -> None:
        """Second thread: hands the kept datagrams on as fast as run reads them."""
        while not self.stop.is_set():
            if not self.pending:
                time.sleep(0.002)  # polling interval
                continue
            q = udp_rx_queue(self.run_port)
            n = len(self.pending) if q is None else max(0, (self.QUEUE_LIMIT - q) // 1024)
            if n == 0:
                time.sleep(0.002)
            for _ in range(min(n, len(self.pending))):
                try:
                    self.sock.sendto(self.pending.popleft(), self.run_addr)
                except OSError:
                    return
                self.forwarded += 1

    def run(self):
        fwd = threading.Thread(target=self.forward, daemon=True)
        fwd.start()
        while not self.stop.is_set():
            try:
                data, addr = self.sock.recvfrom(65536)
            except socket.timeout:
                continue
            except OSError:
                break
            if addr == self.run_addr:
                if self.vehicle is not None:
                    self.sock.sendto(data, self.vehicle)
            else:
                self.vehicle = addr
                if self.lose():
                    self.dropped += 1
                else:
                    self.pending.append(data)
        fwd.join(5)

    def drained(self) -> bool:
        return not self.pending and udp_rx_queue(self.run_port) in (0, None)


def loop_through_relay(tmp_path, speedup: float = 10.0, **relay_kw):
    """150 s of the test model through the relay at ``speedup`` x real time (wall clock); run's loss window is
    50 s of that simulated time (5 s of wall clock at 10x). Returns (run output, sim-autopilot output, relay)."""
    (tmp_path / "model.yaml").write_text(MODEL)
    (tmp_path / "cfg.yaml").write_text(f"run:\n  loss_window_s: {50.0 / speedup:g}\n  baseline_s: 60\n")
    p_run = free_udp_port()
    relay = LossyRelay(p_run, seed=7, **relay_kw)
    relay.start()
    run_out = open(tmp_path / "run.out", "w")
    run = subprocess.Popen([sys.executable, "-m", "companion", "run", "--source", f"udpin:127.0.0.1:{p_run}",
                            "--no-state", "--config", str(tmp_path / "cfg.yaml"), "--duration", "900"],
                           cwd=tmp_path, env=env(), stdout=run_out, stderr=subprocess.STDOUT)
    sim = None
    try:
        wait_for_text(tmp_path / "run.out", READY, run)
        # paced by the wall clock, not flow-controlled: the loss warning looks at a window of wall-clock
        # seconds (run.loss_window_s), which a flow-controlled run at hundreds x real time would never fill
        sim = subprocess.Popen([sys.executable, "-m", "companion", "sim-autopilot", "--model", "model.yaml",
                                "--connect", f"udpout:127.0.0.1:{relay.port}", "--speedup", f"{speedup:g}", "--duration", "150",
                                "--wall-limit", "60", "--quiet"], cwd=tmp_path, env=env(),
                               stdout=open(tmp_path / "sim.out", "w"), stderr=subprocess.STDOUT)
        sim.wait(DEADLINE_S)  # bounded by its --wall-limit
        deadline = time.monotonic() + 4 * DEADLINE_S
        while not relay.drained():  # run has read everything the relay kept (a condition, not a fixed wait)
            assert time.monotonic() < deadline and run.poll() is None, "run did not read its input"
            time.sleep(0.02)
        run.send_signal(signal.SIGTERM)
        run.wait(DEADLINE_S)
    finally:
        kill_left(sim, run)
        relay.stop.set()
        relay.join(5)
        relay.sock.close()
        run_out.close()
    out = (tmp_path / "run.out").read_text()
    assert run.returncode == expected_run_status(out), out
    return out, (tmp_path / "sim.out").read_text(), relay
