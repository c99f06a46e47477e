"""Benchmark of the three compensation methods (Shi et al.): ADEV reduction, accuracy, speed, factor validity.

    python -m benchmarks.bench_compensation                      # 10^6 simulated + ADIS16405 gy 10^6 + gx/gz 10^5
    python -m benchmarks.bench_compensation --samples 100000     # quicker
    python -m benchmarks.bench_compensation --data ../shared/data --json /tmp/bench_comp.json
    python -m benchmarks.bench_compensation --gauss-markov 20   # seeds 1-20 of Gauss-Markov + white noise only

Simulated: ARIMA(1,1,1) (phi 0.8, delta1 2e-3, delta2 6e-4 rad/s) plus white noise 5e-3 rad/s at 100 Hz, so
the truth x is known: the table gives the RMS error of each estimate against it and against the optimal
(exact ARIMA, DARE) Kalman filter. A second, "weak" case has delta1, delta2 ten times smaller (the ARIMA part
is 0.1 % of the variance of the differenced data): there the free fit hides the white noise in x and the auto
split's white-share rule refits canonically (docs/compensation.md).
Real: ../shared/data/adis16405 (100 Hz, at rest; not in the repository).
Gauss-Markov mode (--gauss-markov K): for seeds 1..K, a first-order Gauss-Markov process (tau_c log-uniform in
0.2-20 s, sigma log-uniform in 1-10 times the white noise) plus white noise 5e-3 rad/s at 100 Hz: not an
ARIMA(1,1,1) of the paper's kind (its difference is ARMA(1,1) with theta = 1) but what real gyros show. The
reference is the optimal filter for that exact model (scalar steady-state Kalman filter with the true
parameters): per seed and method, ADEV(method)/ADEV(optimal) at tau0 and rmse/rmse(optimal) against the truth.
For every series: ADEV(compensated) / ADEV(raw) at short and long tau, samples/s, and whether the
covariance factor stayed valid (no NaN, positive diagonal) at every step (smallest diagonal element shown).

Target: every method lowers ADEV at the shortest tau below the raw data's, its RMS error close to the optimal filter's, and its covariance factor valid at every step.
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


from benchmarks import results
from benchmarks.results import SHARED_DATA
from companion.compensation.arima import optimal_error_std
from companion.compensation.compare_methods import compensate

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


def gauss_markov_case(seed: int, n: int):
    """(x, z, opt_x, info): GM truth, measurement, optimal (steady-state Kalman) estimate, parameters."""
    rng = np.random.default_rng(seed)
    sr = 5e-3
    tau_c = float(np.exp(rng.uniform(np.log(0.2), np.log(20.0))))
    sigma = float(sr * np.exp(rng.uniform(0.0, np.log(10.0))))
    a = np.exp(-1.0 / (RATE * tau_c))
    q = sigma**2 * (1.0 - a * a)
    x = lfilter([np.sqrt(q)], [1.0, -a], rng.standard_normal(n), zi=[a * sigma * rng.standard_normal()])[0]
    z = x + sr * rng.standard_normal(n)
    # steady-state scalar Kalman filter: prior variance p solves p = a^2 p R / (p + R) + q
    R = sr * sr
    b = R * (1.0 - a * a) - q
    p = (-b + np.sqrt(b * b + 4.0 * q * R)) / 2.0
    K = p / (p + R)
    opt = lfilter([K], [1.0, -(1.0 - K) * a], z)  # xhat_k = (1-K) a xhat_{k-1} + K z_k
    return x, z, opt, {"tau_c": tau_c, "sigma": sigma, "white": sr}


def gauss_markov(seeds, n):
    from companion.allan.adev import oadev

    print(f"\n## Gauss-Markov + white noise, seeds {seeds[0]}-{seeds[-1]}, {n} samples at {RATE:g} Hz")
    print(f"{'seed':>4}{'tau_c s':>9}{'sigma/w':>9}  {'split':<10}{'theta':>8}"
          + "".join(f"{'adev/opt ' + m:>17}" for m in ("stf", "srukf", "srrsukf"))
          + "".join(f"{'rmse/opt ' + m:>17}" for m in ("stf", "srukf", "srrsukf")))
    rows = {}
    for seed in seeds:
        x, z, opt, info = gauss_markov_case(seed, n)
        res = compensate(z, RATE)
        _, opt_adev, _, _ = oadev(opt, RATE, m=np.array([1]))
        opt_rmse = float(np.sqrt(np.mean((opt[1000:] - x[1000:]) ** 2)))
        row = {**info, "split": res.params.split, "theta": res.params.theta, "adev_over_opt": {}, "rmse_over_opt": {}}
        for m in res.methods.values():
            row["adev_over_opt"][m.name] = float(m.adev[0] / opt_adev[0])
            row["rmse_over_opt"][m.name] = float(np.sqrt(np.mean((m.x[1000:] - x[1000:]) ** 2)) / opt_rmse)
        print(f"{seed:>4}{info['tau_c']:>9.2f}{info['sigma'] / info['white']:>9.2f}  {res.params.split:<10}"
              f"{res.params.theta:>8.3f}" + "".join(f"{row['adev_over_opt'][k]:>17.3f}" for k in row["adev_over_opt"])
              + "".join(f"{row['rmse_over_opt'][k]:>17.3f}" for k in row["rmse_over_opt"]), flush=True)
        rows[seed] = row
    for key in ("adev_over_opt", "rmse_over_opt"):
        for m in ("stf", "srukf", "srrsukf"):
            v = np.array([r[key][m] for r in rows.values()])
            print(f"{key} {m:<8} median {np.median(v):.3f}  max {v.max():.3f}")
    return rows


def load_adis(data: Path, imu: int, n: int):
    path = data / "adis16405" / f"adis16405_imu{imu}.csv.gz"
    with gzip.open(path, "rt") as fh:
        return np.loadtxt(fh, delimiter=",", skiprows=1, max_rows=n, usecols=(1, 2, 3))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=1_000_000, help="samples of the long runs (default 10^6)")
    ap.add_argument("--short", type=int, default=100_000, help="samples of the other ADIS axes (default 10^5)")
    ap.add_argument("--data", default=str(SHARED_DATA))
    ap.add_argument("--json", help="write all figures as JSON")
    ap.add_argument("--skip-sim", action="store_true")
    ap.add_argument("--gauss-markov", type=int, default=0, metavar="K",
                    help="only the Gauss-Markov + white noise cases, seeds 1..K")
    ap.add_argument("--gm-samples", type=int, default=50_000, help="samples per Gauss-Markov case (default 5x10^4)")
    args = results.parse_args(ap, {"samples": 100_000, "short": 20_000}, argv)
    out = {}
    t0 = time.time()
    if args.gauss_markov > 0:
        out["gauss_markov"] = gauss_markov(list(range(1, args.gauss_markov + 1)), args.gm_samples)
        print(f"\ntotal {time.time() - t0:.0f} s")
        if args.json:
            Path(args.json).write_text(json.dumps(out, indent=1))
        return 0
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
    sys.exit(results.run(main))
