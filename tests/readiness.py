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
