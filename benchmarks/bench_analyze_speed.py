"""Speed and memory of `companion analyze` on a 2.8 h, 100 Hz recording (1 M samples x 6 axes).

    python -m benchmarks.bench_analyze_speed            # 3 runs per record (the minimum is the figure)
    python -m benchmarks.bench_analyze_speed --runs 5
    python -m benchmarks.bench_analyze_speed --quick    # 2 runs per record
    python -m benchmarks.bench_analyze_speed --baseline ../main   # also another checkout (its .venv), interleaved

Two records: the ADIS16405 recording 1 of ../shared/data (a gzip CSV, skipped with a message where the data are
absent) and a synthetic 1 M x 6 record of the simulator (white noise, bias instability and a rate random walk on
every axis, written as a gzip CSV of the same format). Each run is a fresh `python -m companion analyze ... --json`
process: its wall time, CPU time (user + system) and peak resident memory (the child's own rusage; the synthetic
record is written by another process, as a child's peak counts from its parent's size at the fork).

Target: within 3 s and 150 MB on this machine; printed as ratios (figure / target, <= 1 meets it). The machine is
shared: the CPU time varies less with the other processes than the wall time, but still by a third with their
load; ``--baseline`` runs another checkout's ``analyze`` in turn with this one's (the same load for both), prints
its figures and the ratio of the two, and whether their JSON reports are identical.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

from benchmarks import results

TARGET_S = 3.0  #: the issue's target for the whole command (load, still selection, six fits, JSON)
TARGET_MB = 150.0  #: the issue's target of peak resident memory
RATE_HZ = 100.0  #: the recording's rate
SAMPLES = 1_000_000  #: 2.8 h at 100 Hz
SHARED_CSV = "adis16405/adis16405_imu1.csv.gz"  #: the recording of the issue, under the shared data
#: the synthetic record's terms per sensor (SI), of the ADIS16405's order
GYRO_TERMS = [{"effect": "white_noise", "N": 7e-4}, {"effect": "bias_instability", "B": 1.5e-4},
              {"effect": "random_walk", "K": 5e-6}]
ACCEL_TERMS = [{"effect": "white_noise", "N": 1e-2}, {"effect": "bias_instability", "B": 1e-3},
               {"effect": "random_walk", "K": 5e-5}]


class Run(NamedTuple):
    """One analyze process."""

    wall_s: float
    cpu_s: float
    peak_mb: float


def analyze_once(path: Path, out_json: Path, checkout: Path | None = None) -> Run:
    """One `companion analyze` process on ``path`` (of ``checkout``, run with its .venv's python; None: this one);
    its rusage is the child's own (os.wait4)."""
    python = str(checkout / ".venv" / "bin" / "python") if checkout else sys.executable
    t0 = time.perf_counter()
    proc = subprocess.Popen([python, "-m", "companion", "analyze", str(path), "--quiet", "--json",
                             str(out_json)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=checkout)
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"analyze {path} failed: {proc.stderr.read().decode(errors='replace')}")
    return Run(wall, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0)


def synthetic_record(path: Path, seed: int = 49) -> None:
    """A 1 M x 6 record of the simulator's terms, written as ``time_s,gx,...,az`` gzip CSV."""
    import numpy as np

    from companion.sim.synth import synthesize_axis
    from companion.sources.csvfile import write_csv

    rng = np.random.default_rng(seed)
    gyro = np.column_stack([synthesize_axis(GYRO_TERMS, RATE_HZ, SAMPLES, rng) for _ in range(3)])
    accel = np.column_stack([synthesize_axis(ACCEL_TERMS, RATE_HZ, SAMPLES, rng) for _ in range(3)])
    accel[:, 2] -= 9.80665
    write_csv(str(path), np.arange(SAMPLES) / RATE_HZ, gyro, accel)


def _line(name: str, out: list) -> str:
    wall = min(r.wall_s for r in out)
    cpu = min(r.cpu_s for r in out)
    peak = min(r.peak_mb for r in out)
    return (f"{name}: {len(out)} runs, min wall {wall:.2f} s ({wall / TARGET_S:.2f} x {TARGET_S:g} s), "
            f"min CPU {cpu:.2f} s ({cpu / TARGET_S:.2f} x), peak {peak:.0f} MB ({peak / TARGET_MB:.2f} x "
            f"{TARGET_MB:g} MB)\n   each run (wall s, CPU s, MB): "
            + "; ".join(f"{r.wall_s:.2f}, {r.cpu_s:.2f}, {r.peak_mb:.0f}" for r in out))


def report(name: str, path: Path, runs: int, tmp: Path, baseline: Path | None = None) -> None:
    out, base = [], []
    for _ in range(runs):
        if baseline is not None:
            base.append(analyze_once(path, tmp / "base.json", baseline))
        out.append(analyze_once(path, tmp / "out.json"))
    print(_line(name, out))
    if baseline is not None:
        print(_line(f"   baseline {baseline}", base))
        same = (tmp / "base.json").read_bytes() == (tmp / "out.json").read_bytes()
        print(f"   CPU / baseline's (min): {min(r.cpu_s for r in out) / min(r.cpu_s for r in base):.2f}; "
              f"JSON report identical to the baseline's: {'yes' if same else 'NO'}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3, help="analyze processes per record (the minimum is printed)")
    ap.add_argument("--baseline", type=Path, default=None,
                    help="another checkout (with its .venv) whose analyze runs in turn with this one's")
    args = results.parse_args(ap, {"runs": 2})
    try:
        load = os.getloadavg()
        print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    except OSError:
        pass
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        shared = results.SHARED_DATA / SHARED_CSV
        if shared.exists():
            report(f"ADIS16405 {SHARED_CSV}", shared, args.runs, tmp, args.baseline)
        else:
            print(f"skipped the ADIS16405 recording: {shared} is absent (set COMPANION_SHARED_DATA)")
        synth = tmp / "synthetic_1M_x6.csv.gz"
        subprocess.run([sys.executable, "-c", "import sys; from pathlib import Path; "
                        "from benchmarks.bench_analyze_speed import synthetic_record; "
                        "synthetic_record(Path(sys.argv[1]))", str(synth)], check=True)
        report(f"synthetic {SAMPLES:,} x 6 at {RATE_HZ:g} Hz", synth, args.runs, tmp, args.baseline)
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
