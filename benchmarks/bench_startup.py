"""Start-up of the `companion` command, side by side with `python -c "import numpy"` in the same run.

Each command is started ``--repeat`` times in turn (interleaved, so a busy machine affects all alike);
the median wall time and child CPU time are printed with the ratio to the numpy import:

- ``companion --version`` and ``companion --help``: target within 1.5x of importing numpy;
- ``companion run --source udpin:127.0.0.1:PORT``: time until its readiness line on stderr
  ("companion run: listening on ..."), i.e. signal handlers installed and the socket open, target within 3x;
  its resident memory (VmRSS) at that moment is printed too.

    python -m benchmarks.bench_startup              # 7 repeats
    python -m benchmarks.bench_startup --repeat 3
"""

from __future__ import annotations

import argparse
import os
import resource
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import results

ROOT = Path(__file__).resolve().parent.parent
READY = "companion run: listening on"


def env():
    e = dict(os.environ)
    e["PYTHONPATH"] = str(ROOT) + os.pathsep + e.get("PYTHONPATH", "")
    return e


def child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(cmd) -> tuple[float, float]:
    c0, t0 = child_cpu(), time.perf_counter()
    subprocess.run(cmd, env=env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - t0, child_cpu() - c0


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return -1


def run_ready() -> tuple[float, float, int]:
    """Wall time until the readiness line, CPU of the whole process (ready + SIGTERM), RSS at readiness."""
    port = free_port()
    with tempfile.TemporaryDirectory() as d:
        errf = Path(d) / "err"
        c0, t0 = child_cpu(), time.perf_counter()
        with open(errf, "w") as fh:
            p = subprocess.Popen([sys.executable, "-m", "companion", "run", "--source", f"udpin:127.0.0.1:{port}",
                                  "--no-state", "--quiet", "--duration", "300"], env=env(),
                                 stdout=subprocess.DEVNULL, stderr=fh)
        try:
            while READY not in errf.read_text():
                if p.poll() is not None:
                    raise SystemExit(f"companion run exited: {errf.read_text()}")
                if time.perf_counter() - t0 > 120:
                    raise SystemExit("no readiness line within 120 s")
                time.sleep(0.002)
            wall = time.perf_counter() - t0
            rss = rss_kib(p.pid)
            p.send_signal(signal.SIGTERM)
            p.wait(60)
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
        return wall, child_cpu() - c0, rss


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=7)
    args = results.parse_args(ap, {"repeat": 3})
    py = sys.executable
    cases = {
        'python -c "import numpy"': lambda: timed([py, "-c", "import numpy"]),
        "companion --version": lambda: timed([py, "-m", "companion", "--version"]),
        "companion --help": lambda: timed([py, "-m", "companion", "--help"]),
        "companion run (until ready)": run_ready,
    }
    res = {k: [] for k in cases}
    rss = []
    for _ in range(args.repeat):
        for k, f in cases.items():
            r = f()
            res[k].append(r[:2])
            if len(r) > 2:
                rss.append(r[2])
    base_w = statistics.median(w for w, _ in res['python -c "import numpy"'])
    base_c = statistics.median(c for _, c in res['python -c "import numpy"'])
    target = {"companion --version": 1.5, "companion --help": 1.5, "companion run (until ready)": 3.0}
    print(f"{'command':<30}{'wall s':>8}{'ratio':>7}{'CPU s':>8}{'ratio':>7}  target")
    for k, v in res.items():
        w = statistics.median(x for x, _ in v)
        c = statistics.median(x for _, x in v)
        t = target.get(k)
        verdict = "" if t is None else f"<= {t}x: {'ok' if w / base_w <= t else 'MISSED'}"
        print(f"{k:<30}{w:>8.3f}{w / base_w:>7.2f}{c:>8.3f}{c / base_c:>7.2f}  {verdict}")
    print(f"median of {args.repeat} interleaved runs; `companion run` resident memory at readiness: "
          f"{statistics.median(rss) / 1024:.1f} MiB")


if __name__ == "__main__":
    sys.exit(results.run(main))
