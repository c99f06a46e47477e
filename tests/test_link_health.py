"""Link health: lost, out-of-order, duplicate and late frames per source from MAVLink sequence numbers, the
loss STATUSTEXT, and the estimator through a lossy relay over loopback (20 % random loss, bursts of loss)."""

from __future__ import annotations

import math
import os
import random
import re
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from readiness import DEADLINE_S, READY, wait_for_text

from companion.mavlink.link import LinkStats, SourceStats

ROOT = Path(__file__).resolve().parent.parent


class Msg:
    def __init__(self, seq, sysid=1, compid=1, mtype="RAW_IMU", t=None):
        self.seq, self.sysid, self.compid, self.mtype = seq & 0xFF, sysid, compid, mtype
        self.time_usec = t
        self.id = 0

    def get_type(self):
        return self.mtype

    def get_seq(self):
        return self.seq

    def get_srcSystem(self):
        return self.sysid

    def get_srcComponent(self):
        return self.compid


def test_sequence_accounting_with_wrap_loss_reorder_and_duplicates():
    rng = random.Random(4)
    st = SourceStats()
    sent = list(range(5000))  # wraps the 8-bit counter many times
    kept = [s for s in sent if rng.random() > 0.2]
    dropped = len(sent) - len(kept)
    # swap a few neighbours (reordering) and repeat a few frames (duplicates)
    for i in range(100, 4000, 400):
        kept[i], kept[i + 1] = kept[i + 1], kept[i]
    out = []
    dups = 0
    for i, s in enumerate(kept):
        out.append(s)
        if i % 500 == 250:  # (never next to a swapped pair)
            out.append(s)
            dups += 1
    for s in out:
        st.on_seq(s & 0xFF)
    assert st.received == len(out)
    assert dups >= 7 and st.duplicates == dups
    assert st.out_of_order == 10
    assert st.lost == dropped
    assert st.loss_fraction() == pytest.approx(dropped / len(sent), abs=1e-3)


def test_late_imu_samples_and_sources_are_separate():
    ls = LinkStats()
    for k, t in enumerate([1_000, 2_000, 3_000, 2_500, 4_000, 4_000]):
        ls.on_message(Msg(k, t=t))
    for k in range(10):
        ls.on_message(Msg(k * 2, sysid=255, compid=190, mtype="HEARTBEAT"))
    a, g = ls.sources[(1, 1)], ls.sources[(255, 190)]
    assert a.late == 1 and a.lost == 0
    assert g.lost == 9 and g.received == 10
    lines = ls.summary_lines()
    assert any(line.startswith("link from 1/1: 6 frames received, 0 lost") for line in lines)


# ---------------------------------------------------------------- over loopback, through a lossy relay
N_SI = 3e-3
RATE = 100.0
N_TRUE = math.sqrt(N_SI**2 + 1e-6 / (12 * RATE)) * 180 / math.pi * 60  # deg/sqrt(h), with the LSB rounding
MODEL = f"rate_hz: {RATE}\naxes:\n" + "".join(f"  {a}: [{{effect: white_noise, N: {N_SI}}}]\n" for a in ("gx", "gy", "gz"))


def env():
    e = dict(os.environ)
    e["PYTHONPATH"] = str(ROOT) + os.pathsep + e.get("PYTHONPATH", "")
    return e


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LossyRelay(threading.Thread):
    """Forwards datagrams between the vehicle (sim-autopilot) and `companion run`, dropping vehicle->run
    datagrams: independently with ``p`` (random) or in bursts (Gilbert model: good->bad ``p_gb``,
    bad->good ``p_bg``, everything lost while bad). Counts what it dropped."""

    def __init__(self, run_port: int, seed: int, p: float = 0.0, burst: tuple[float, float] | None = None):
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.run_addr = ("127.0.0.1", run_port)
        self.rng = random.Random(seed)
        self.p, self.burst = p, burst
        self.bad = False
        self.vehicle = None
        self.forwarded = self.dropped = 0
        self.stop = threading.Event()

    def lose(self) -> bool:
        if self.burst is None:
            return self.rng.random() < self.p
        p_gb, p_bg = self.burst
        self.bad = (self.rng.random() >= p_bg) if self.bad else (self.rng.random() < p_gb)
        return self.bad

    def run(self):
        while not self.stop.is_set():
            try:
                data, addr = self.sock.recvfrom(65536)
            except socket.timeout:
                continue
            except OSError:
                return
            if addr == self.run_addr:
                if self.vehicle is not None:
                    self.sock.sendto(data, self.vehicle)
                continue
            self.vehicle = addr
            if self.lose():
                self.dropped += 1
            else:
                self.forwarded += 1
                self.sock.sendto(data, self.run_addr)


def loop_through_relay(tmp_path, **relay_kw):
    (tmp_path / "model.yaml").write_text(MODEL)
    (tmp_path / "cfg.yaml").write_text("run:\n  loss_window_s: 5.0\n  baseline_s: 60\n")
    p_run = free_udp_port()
    relay = LossyRelay(p_run, seed=7, **relay_kw)
    relay.start()
    run_out = open(tmp_path / "run.out", "w")
    run = subprocess.Popen([sys.executable, "-m", "companion", "run", "--source", f"udpin:127.0.0.1:{p_run}",
                            "--no-state", "--config", str(tmp_path / "cfg.yaml"), "--duration", "600"],
                           cwd=tmp_path, env=env(), stdout=run_out, stderr=subprocess.STDOUT)
    sim = None
    try:
        wait_for_text(tmp_path / "run.out", READY, run)
        sim = subprocess.Popen([sys.executable, "-m", "companion", "sim-autopilot", "--model", "model.yaml",
                                "--connect", f"udpout:127.0.0.1:{relay.port}", "--speedup", "10", "--duration", "150",
                                "--wall-limit", "60", "--quiet"], cwd=tmp_path, env=env(),
                               stdout=open(tmp_path / "sim.out", "w"), stderr=subprocess.STDOUT)
        sim.wait(DEADLINE_S)  # bounded by its --wall-limit
        run.send_signal(signal.SIGTERM)
        run.wait(DEADLINE_S)
    finally:
        for p in (sim, run):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait(10)
        relay.stop.set()
        relay.join(5)
        relay.sock.close()
        run_out.close()
    out = (tmp_path / "run.out").read_text()
    assert run.returncode == 0, out
    return out, (tmp_path / "sim.out").read_text(), relay


def check_loss_run(out, sim_out, relay, lo, hi):
    m = re.search(r"link from 1/1: (\d+) frames received, (\d+) lost \(([\d.]+) %\)", out)
    assert m, out
    received, lost, pct = int(m.group(1)), int(m.group(2)), float(m.group(3))
    assert received <= relay.forwarded
    # every datagram the relay dropped is counted (plus any the kernel dropped), except that 8-bit sequence
    # numbers cannot see a run of 128 or more lost at once (a pause of the receiver longer than its buffer)
    assert lost >= 0.9 * relay.dropped
    assert lo <= relay.dropped / (relay.dropped + relay.forwarded) <= hi
    assert pct >= 100 * lo
    assert "STATUSTEXT" in sim_out and "companion: link loss" in sim_out  # the warning reached the vehicle
    for ax in "xyz":
        n = re.search(rf"  g{ax}: N ([\d.]+) ", out)
        assert n, out
        assert float(n.group(1)) == pytest.approx(N_TRUE, rel=0.05)


@pytest.mark.network
def test_twenty_percent_random_loss(tmp_path):
    out, sim_out, relay = loop_through_relay(tmp_path, p=0.2)
    check_loss_run(out, sim_out, relay, 0.17, 0.23)


@pytest.mark.network
def test_bursts_of_loss(tmp_path):
    # Gilbert model: bursts of 1/0.08 = 12.5 datagrams on average (125 ms at 100 Hz), 20 % lost overall
    out, sim_out, relay = loop_through_relay(tmp_path, burst=(0.02, 0.08))
    check_loss_run(out, sim_out, relay, 0.12, 0.28)
