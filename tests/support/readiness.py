"""Waiting for another process without a fixed sleep: poll its output file for a readiness line.

Tests never wait a fixed time for a process: ``wait_for_text`` returns as soon as the line is there, fails
at once (with the output) when the process died, and only gives up after a generous deadline, so a busy
machine makes a test slower, never red.
"""

from __future__ import annotations

import time
from pathlib import Path

READY = "companion run: listening on"  # printed by `companion run` once its link is open (also with --quiet)
DEADLINE_S = 120.0


def wait_for_text(path, needle: str, proc=None, timeout: float = DEADLINE_S) -> str:
    """Poll ``path`` until it contains ``needle``; returns the file's text. Fails if ``proc`` exits first."""
    path = Path(path)
    deadline = time.monotonic() + timeout
    text = ""
    while True:
        try:
            text = path.read_text(errors="replace")
        except FileNotFoundError:
            text = ""
        if needle in text:
            return text
        if proc is not None and proc.poll() is not None:
            text = path.read_text(errors="replace") if path.exists() else ""
            if needle in text:
                return text
            raise AssertionError(f"process exited ({proc.returncode}) before printing {needle!r}:\n{text}")
        if time.monotonic() > deadline:
            raise AssertionError(f"no {needle!r} within {timeout:.0f} s:\n{text}")
        time.sleep(0.02)  # polling interval, not a wait for the other process


def udp_rx_queue(port: int) -> int | None:
    """Bytes waiting in the receive queue of the UDP socket bound to ``port`` (Linux /proc/net/udp), or
    None where that cannot be read. Lets a test wait until `companion run` has read everything sent to it."""
    total, found = 0, False
    for name in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            lines = Path(name).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            f = line.split()
            if len(f) > 4 and int(f[1].rsplit(":", 1)[1], 16) == port:
                total += int(f[4].split(":")[1], 16)
                found = True
    return total if found else None


def wait_until_read(port: int, proc=None, timeout: float = DEADLINE_S) -> None:
    """Wait until nothing is queued for ``port`` any more (the receiver caught up), with a deadline; returns
    at once where the queue cannot be observed."""
    deadline = time.monotonic() + timeout
    while True:
        q = udp_rx_queue(port)
        if q is None or q == 0:
            return
        if proc is not None and proc.poll() is not None:
            return
        if time.monotonic() > deadline:
            raise AssertionError(f"port {port}: {q} bytes still unread after {timeout:.0f} s")
        time.sleep(0.02)  # polling interval


def kill_left(*procs) -> None:
    """Kill the processes of a test that are still running (None: never started), after a failure."""
    for p in procs:
        if p is not None and p.poll() is None:
            p.kill()
            p.wait(10)
