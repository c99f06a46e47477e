"""Overlapping ADEV speed and equality: companion vs allantools.oadev(taus='octave') on 1,000,000 samples.

    python -m benchmarks.bench_oadev [n]
    python -m benchmarks.bench_oadev --quick     # 200,000 samples (the run recorded in RESULTS.md)

Target: equal to allantools to rounding (max relative difference ~1e-15) and faster (the ratio is the figure).
"""

import sys
import time

import numpy as np

from benchmarks import results
from companion.allan.adev import oadev


def best_of(fn, k=3):
    t = []
    for _ in range(k):
        t0 = time.perf_counter()
        out = fn()
        t.append(time.perf_counter() - t0)
    return min(t), out


def main():
    arg = sys.argv[1] if len(sys.argv) > 1 else ""
    if arg in ("-h", "--help"):
        print(__doc__)
        raise SystemExit(0)
    n = 200_000 if arg == "--quick" else int(arg) if arg else 1_000_000
    y = np.random.default_rng(0).normal(0.0, 1e-3, n) + 0.01
    t_ours, (tau, adev, _, _) = best_of(lambda: oadev(y, 100.0, spec="octave"))
    print(f"n = {n}, octave cluster times: {len(tau)}")
    print(f"companion oadev        {t_ours * 1e3:8.1f} ms")
    try:
        import allantools
    except ImportError:
        print("allantools not installed: no comparison")
        return
    t_at, (t2, a2, _, _) = best_of(lambda: allantools.oadev(y, rate=100.0, data_type="freq", taus="octave"))
    k = min(len(a2), len(adev))
    print(f"allantools oadev       {t_at * 1e3:8.1f} ms")
    print(f"ratio allantools/ours  {t_at / t_ours:8.2f}")
    print(f"max relative difference over {k} taus: {np.max(np.abs(adev[:k] / a2[:k] - 1)):.2e}")


if __name__ == "__main__":
    sys.exit(results.run(main))
