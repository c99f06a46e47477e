"""`companion sim-autopilot --flow-control`: the receiver's UDP queue as the kernel shows it, and the options.
The flow-controlled link itself runs in every loopback test (tests/support/loopback.py)."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

from companion.cli.main import main
from companion.mavlink.autopilot_sim import flow_limit, udp_queue_bytes


@pytest.mark.skipif(not Path("/proc/net/udp").is_file(), reason="needs Linux /proc/net/udp")
def test_queue_of_a_real_socket_grows_with_unread_datagrams_and_empties_when_read():
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        rx.bind(("127.0.0.1", 0))
        port = rx.getsockname()[1]
        assert udp_queue_bytes([port]) == 0
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            closed = s.getsockname()[1]
        assert udp_queue_bytes([closed]) is None  # no socket on that port: not observable
        sizes = []
        for n in (5, 20):
            for _ in range(n):
                tx.sendto(b"x" * 40, ("127.0.0.1", port))
            deadline = time.monotonic() + 10.0
            while (q := udp_queue_bytes([port])) < (sizes[-1] if sizes else 0) + n * 40:
                assert time.monotonic() < deadline, q
                time.sleep(0.01)  # polling interval
            sizes.append(q)
        assert sizes[1] >= 5 * sizes[0]  # kernel accounting per datagram, 25 datagrams vs 5
        assert flow_limit() >= 16384 and flow_limit() > sizes[0]  # the threshold lets a few datagrams wait
        rx.setblocking(False)
        for _ in range(25):
            rx.recv(100)
        assert udp_queue_bytes([port]) == 0
    finally:
        rx.close()
        tx.close()


def test_flow_control_needs_a_udp_destination(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.yaml").write_text("rate_hz: 100\naxes:\n  gx: [{effect: white_noise, N: 3.0e-3}]\n")
    rc = main(["sim-autopilot", "--model", "m.yaml", "--connect", "tcp:127.0.0.1:5760", "--flow-control",
               "--duration", "1"])
    err = capsys.readouterr().err
    assert rc == 2 and "--flow-control needs" in err and len(err.strip().splitlines()) == 1
