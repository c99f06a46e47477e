"""The test suite's long soaks and scans (tests marked ``soak``): the same assertions as when they ran with
the README's test command, kept out of it for its time (docs/testing.md). Exits with pytest's code: 0 when
every check passed, 1 when one failed.

    python -m benchmarks.soak_checks            # all, on every core
    python -m benchmarks.soak_checks -n 0 -k gap # pytest's options pass through
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str]) -> int:
    cmd = [sys.executable, "-m", "pytest", "-q", "-m", "soak", *argv]
    print("soak checks:", " ".join(cmd[2:]), flush=True)
    return subprocess.call(cmd, cwd=ROOT)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
