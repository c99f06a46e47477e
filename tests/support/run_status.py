"""The exit status a ``companion run`` must end with, read from its printed summary (README "Exit status"):
4 when the summary lists an active fault or a degrading IMU, 5 when no IMU data came, else 0."""

from __future__ import annotations

import re


def expected_run_status(summary: str) -> int:
    if re.search(r"^\s+FAULT: ", summary, re.M) or re.search(r"^IMU\d+ \([^)]*\): degrading;", summary, re.M):
        return 4
    if "no IMU data from the vehicle" in summary:
        return 5
    return 0
