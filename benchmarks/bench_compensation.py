"""Benchmark of the three compensation methods (Shi et al.): ADEV reduction, accuracy, speed, factor validity.

    python benchmarks/bench_compensation.py                      # 10^6 simulated + ADIS16405 gy 10^6 + gx/gz 10^5
    python benchmarks/bench_compensation.py --samples 100000     # quicker
    python benchmarks/bench_compensation.py --data ../shared/data --json /tmp/bench_comp.json

Simulated: ARIMA(1,1,1) (phi 0.8, delta1 2e-3, delta2 6e-4 rad/s) plus white noise 5e-3 rad/s at 100 Hz, so
the truth x is known: the table gives the RMS error of each estimate against it and against the optimal
(exact ARIMA, DARE) Kalman filter. A second, "weak" case has delta1, delta2 ten times smaller (the ARIMA part
is 0.1 % of the variance of the differenced data): there the least-squares start cannot identify the model. Real: ../shared/data/adis16405 (100 Hz, at rest; not in the repository).
For every series: ADEV(compensated) / ADEV(raw) at short and long tau, samples/s, and whether the
covariance factor stayed valid (no NaN, positive diagonal) at every step (smallest diagonal element shown).
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from companion.compensation.arima import optimal_error_std  # noqa: E402
from companion.compensation.pipeline import compensate  # noqa: E402

RATE = 100.0
TAUS = (0.01, 0.16, 1.28, 81.92)


def progress(name, done, total):
    sys.stderr.write(f"\r  {name:<8} {100.0 * done / total:5.1f} %   ")
    sys.stderr.flush()


def report(title, z, truth=None, opt=None):
    print(f"\n## {title}: {len(z)} samples at {RATE:g} Hz", flush=True)
    res = compensate(z, RATE, progress=progress)
    sys.stderr.write("\r" + " " * 40 + "\r")
    p = res.params
    print(f"ARIMA fit ({p.split}): phi={p.phi:.4f} theta={p.theta:.4f} delta1={p.delta1 * p.scale:.3g} "
          f"delta2={p.delta2 * p.scale:.3g} sqrt(R)={np.sqrt(p.R) * p.scale:.3g} rad/s")
    idx = [int(np.argmin(np.abs(res.raw_tau - t))) for t in TAUS]
    cols = "".join(f"{'ratio@' + format(res.raw_tau[i], 'g') + 's':>14}" for i in idx)
    extra = f"{'rmse/raw':>10}{'rmse/opt':>10}" if truth is not None else ""
    print(f"{'method':<20}{cols}{extra}{'samples/s':>11}{'valid':>7}{'min diag':>11}")
    print(f"{'raw ADEV (rad/s)':<20}" + "".join(f"{res.raw_adev[i]:>14.4g}" for i in idx))
    rows = {}
    for m in res.methods.values():
        ratio = m.adev / res.raw_adev
        line = f"{m.label:<20}" + "".join(f"{ratio[i]:>14.3f}" for i in idx)
        row = {"ratio": {f"{res.raw_tau[i]:g}": float(ratio[i]) for i in idx}, "samples_per_s": m.samples_per_s,
               "factor_valid": m.factor_valid, "min_diag": m.min_diag, **m.extra}
        if truth is not None:
            rmse = float(np.sqrt(np.mean((m.x[1000:] - truth[1000:]) ** 2)))
            raw = float(np.sqrt(np.mean((z[1000:] - truth[1000:]) ** 2)))
            line += f"{rmse / raw:>10.3f}{rmse / opt:>10.3f}"
            row.update(rmse=rmse, rmse_raw=raw, rmse_opt=opt)
        line += f"{m.samples_per_s:>11.0f}{'yes' if m.factor_valid else 'NO':>7}{m.min_diag:>11.3g}"
        print(line, flush=True)
        rows[m.name] = row
    return {"samples": len(z), "arima": p.as_dict(), "methods": rows}


def load_adis(data: Path, imu: int, n: int):
    path = data / "adis16405" / f"adis16405_imu{imu}.csv.gz"
    with gzip.open(path, "rt") as fh:
        return np.loadtxt(fh, delimiter=",", skiprows=1, max_rows=n, usecols=(1, 2, 3))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=1_000_000, help="samples of the long runs (default 10^6)")
    ap.add_argument("--short", type=int, default=100_000, help="samples of the other ADIS axes (default 10^5)")
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--json", help="write all figures as JSON")
    ap.add_argument("--skip-sim", action="store_true")
    args = ap.parse_args(argv)
    out = {}
    t0 = time.time()
    if not args.skip_sim:
        for name, d1, n in (("simulated", 2e-3, args.samples), ("simulated_weak", 2e-4, args.short)):
            phi, d2, sr = 0.8, 0.3 * d1, 5e-3
            rng = np.random.default_rng(2024)
            x = np.cumsum(lfilter([d1, -d2], [1.0, -phi], rng.standard_normal(n))) + 0.01
            z = x + sr * rng.standard_normal(n)
            out[name] = report(f"{name}: ARIMA(1,1,1) phi {phi} delta1 {d1:g} delta2 {d2:g} + white {sr:g} rad/s",
                               z, truth=x, opt=optimal_error_std(phi, d1, d2, sr**2))
    data = Path(args.data)
    if (data / "adis16405").is_dir():
        g = load_adis(data, 1, args.samples)
        out["adis16405_imu1_gy"] = report("ADIS16405 imu1 gy", g[:, 1])
        for k, ax in ((0, "gx"), (2, "gz")):
            out[f"adis16405_imu1_{ax}"] = report(f"ADIS16405 imu1 {ax}", g[: args.short, k])
    else:
        print(f"\n({data / 'adis16405'} not found: real-data part skipped)")
    print(f"\ntotal {time.time() - t0:.0f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
