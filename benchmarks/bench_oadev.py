"""Overlapping ADEV speed and equality: companion vs allantools.oadev(taus='octave') on 1,000,000 samples.

    python benchmarks/bench_oadev.py [n]
"""

import sys
import time

import numpy as np

sys.path.insert(0, str(__import__('pathlib').Path(__file__).resolve().parent.parent))
from companion.allan.adev import oadev


def best_of(fn, k=3):
    t = []
    for _ in range(k):
        t0 = time.perf_counter()
        out = fn()
        t.append(time.perf_counter() - t0)
    return min(t), out


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
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
    main()
