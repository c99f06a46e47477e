"""Benchmark of the gap workflow (companion.gap): success table on simulated data with hidden effects,
false alarms on the null case, the ArduPilot-style rate-rounding case, and the real ADIS16405 recordings
against their datasheet model.

    python benchmarks/bench_gap.py                 # everything (~3-4 min on 2 cores)
    python benchmarks/bench_gap.py --seeds 4 --skip-real

Truth is the simulator's parameters; "ok" means: exactly the hidden effect named, each of its parameters
within 30 %, gap after <= the noise floor, no model term wrongly called mis-sized.
"""

from __future__ import annotations

import argparse
import gzip
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from companion.gap import run_gap  # noqa: E402
from companion.gap.workflow import NOISE_FLOOR_G  # noqa: E402
from companion.sim.synth import synthesize_axis  # noqa: E402
from companion.units import to_datasheet  # noqa: E402

RATE = 20.0
N = int(2 * 3600 * RATE)
WB = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 1e-4}]
CASES = [
    ("quantization Q=6e-4", WB, {"effect": "quantization", "Q": 6e-4}),
    ("quantization Q=3e-3", WB, {"effect": "quantization", "Q": 3e-3}),
    ("white_noise N=1e-3", [{"effect": "quantization", "Q": 1e-4}, {"effect": "bias_instability", "B": 1e-4},
                            {"effect": "random_walk", "K": 5e-6}], {"effect": "white_noise", "N": 1e-3}),
    ("bias_instab B=2e-4", [{"effect": "white_noise", "N": 1e-3}, {"effect": "random_walk", "K": 1e-6}],
     {"effect": "bias_instability", "B": 2e-4}),
    ("random_walk K=3e-5", WB, {"effect": "random_walk", "K": 3e-5}),
    ("random_walk K=1e-4", WB, {"effect": "random_walk", "K": 1e-4}),
    ("ramp R=4e-7", WB, {"effect": "ramp", "R": 4e-7}),
    ("ramp R=2e-6", WB, {"effect": "ramp", "R": 2e-6}),
    ("gauss_markov 8e-4,30s", WB, {"effect": "gauss_markov", "sigma": 8e-4, "tau_c": 30.0}),
    ("gauss_markov 2e-3,3s", WB, {"effect": "gauss_markov", "sigma": 2e-3, "tau_c": 3.0}),
    ("gauss_markov 5e-4,300s", WB, {"effect": "gauss_markov", "sigma": 5e-4, "tau_c": 300.0}),
    ("sinusoid 2e-3,0.05Hz", WB, {"effect": "sinusoid", "amplitude": 2e-3, "freq_hz": 0.05}),
    ("sinusoid 1e-3,0.005Hz", WB, {"effect": "sinusoid", "amplitude": 1e-3, "freq_hz": 0.005}),
    ("sinusoid 3e-3,0.5Hz", WB, {"effect": "sinusoid", "amplitude": 3e-3, "freq_hz": 0.5}),
]


def judge(r, hidden, exact_base=True):
    names = [a["effect"] for a in r.added if a.get("form") != "rate_lsb"]
    if names != [hidden["effect"]]:
        return False, names
    errs = [abs(r.added[0][p] / v - 1) for p, v in hidden.items() if p != "effect"]
    ok = max(errs) <= 0.30 and r.gap_after <= NOISE_FLOOR_G
    if exact_base:
        ok = ok and all(e["verdict"] == "consistent" for e in r.recalibrated)
    return ok, names


def hidden_table(seeds):
    print(f"\n== hidden effect, 2 h at {RATE:g} Hz, {seeds} seeds each ==")
    print(f"{'case':24} {'ok':>5} {'named as (counts)':40} {'max param err':>13} {'G before':>9} {'G after':>8} {'s/run':>6}")
    total_ok = total = 0
    for label, base, hidden in CASES:
        ok_n, named, perr, gb, ga, dt = 0, {}, [], [], [], 0.0
        for seed in range(seeds):
            y = synthesize_axis(base + [hidden], RATE, N, np.random.default_rng(1000 + seed))
            t = time.perf_counter()
            r = run_gap(y, RATE, base, seed=seed)
            dt += time.perf_counter() - t
            ok, names = judge(r, hidden)
            ok_n += ok
            key = "+".join(names) or "(nothing)"
            named[key] = named.get(key, 0) + 1
            if names == [hidden["effect"]]:
                perr.append(max(abs(r.added[0][p] / v - 1) for p, v in hidden.items() if p != "effect"))
            gb.append(r.gap_before)
            ga.append(r.gap_after)
        total_ok += ok_n
        total += seeds
        named_s = ", ".join(f"{k} {v}" for k, v in sorted(named.items(), key=lambda kv: -kv[1]))
        print(f"{label:24} {ok_n:>2}/{seeds:<2} {named_s:40} {max(perr) if perr else float('nan'):13.2f} "
              f"{np.median(gb):9.3g} {np.median(ga):8.3g} {dt / seeds:6.2f}")
    print(f"overall: {total_ok}/{total} = {100 * total_ok / total:.0f} % ok")


def null_table(seeds):
    print(f"\n== null case (model == truth: N, B, K), {seeds} seeds ==")
    base = WB + [{"effect": "random_walk", "K": 5e-6}]
    g, added, recal = [], 0, 0
    for seed in range(seeds):
        y = synthesize_axis(base, RATE, N, np.random.default_rng(2000 + seed))
        r = run_gap(y, RATE, base, seed=seed, simulate=False)
        g.append(r.gap_before)
        added += bool(r.added)
        recal += any(e["verdict"] != "consistent" for e in r.recalibrated)
    g = np.array(g)
    print(f"G: median {np.median(g):.2f}, 95th pct {np.percentile(g, 95):.2f}, max {g.max():.2f} "
          f"(floor {NOISE_FLOOR_G}); false 'added' {added}/{seeds}; false 'mis-sized' {recal}/{seeds}")


def missized_table(seeds):
    print(f"\n== model terms off by 0.7-1.4 + hidden sinusoid, {seeds} seeds ==")
    truth = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 2e-4}]
    hidden = {"effect": "sinusoid", "amplitude": 2e-3, "freq_hz": 0.05}
    ok_n, recal_err = 0, []
    rng = np.random.default_rng(5)
    for seed in range(seeds):
        f = rng.uniform(0.7, 1.4, 2)
        model = [{"effect": "white_noise", "N": 1e-3 * f[0]}, {"effect": "bias_instability", "B": 2e-4 * f[1]}]
        y = synthesize_axis(truth + [hidden], RATE, N, np.random.default_rng(3000 + seed))
        r = run_gap(y, RATE, model, seed=seed, simulate=False)
        ok, names = judge(r, hidden, exact_base=False)
        errs = [abs(t[p] / tr[p] - 1) for t, tr, p in zip(r.terms_after, truth, ("N", "B"))]
        recal_err.append(max(errs))
        verdicts = [e["verdict"][:9] for e in r.recalibrated]
        ok_n += ok
        print(f"  factors {f[0]:.2f} {f[1]:.2f}: named {names}, verdicts {verdicts}, terms after within "
              f"{100 * max(errs):.0f} % of truth, G {r.gap_before:.3g} -> {r.gap_after:.3g}")
    print(f"ok {ok_n}/{seeds}")


def ardupilot(seeds):
    print("\n== ArduPilot-style RAW_IMU: rate rounded to 1 mrad/s, 50 Hz, 1 h, model without quantisation ==")
    lsb, rate = 1e-3, 50.0
    for Nw in (2e-5, 6e-5, 9e-5, 2e-4, 5e-4):
        terms = [{"effect": "white_noise", "N": Nw}, {"effect": "bias_instability", "B": 5e-5}]
        res = []
        for seed in range(seeds):
            y = synthesize_axis(terms, rate, int(3600 * rate), np.random.default_rng(4000 + seed))
            y = np.round(y / lsb) * lsb
            r = run_gap(y, rate, terms, lsb=lsb, seed=seed, simulate=False)
            q = r.quantization
            named = any(a.get("form") == "rate_lsb" for a in r.added)
            res.append((q["sigma_sample_lsb"], q["dithered"], named,
                        [e["verdict"] for e in r.recalibrated], r.gap_before, r.gap_after))
        share = (lsb**2 / (12 * rate)) / Nw**2
        print(f"  N={Nw:.0e} ({to_datasheet('N', Nw):.3g} deg/sqrt(h)): noise/LSB {res[0][0]:.2f}, "
              f"N_q^2/N^2 {share:.2f}, dithered {res[0][1]}, rate quantisation named {sum(x[2] for x in res)}/{seeds}, "
              f"verdicts {res[0][3]}, G {np.median([x[4] for x in res]):.3g} -> {np.median([x[5] for x in res]):.3g}")


def real(shared: Path):
    print("\n== ADIS16405 recordings (../shared/data/adis16405) vs datasheet model: ARW 2 deg/sqrt(h), "
          "bias stability 0.007 deg/s ==")
    model = [{"effect": "white_noise", "N": 5.82e-4}, {"effect": "bias_instability", "B": 1.22e-4}]
    for i in (1, 2, 3):
        path = shared / "adis16405" / f"adis16405_imu{i}.csv.gz"
        if not path.exists():
            print(f"  {path} missing, skipped")
            continue
        with gzip.open(path, "rt") as fh:
            data = np.loadtxt(fh, delimiter=",", skiprows=1)
        for j, axis in enumerate(("gx", "gy", "gz")):
            y = data[:, 1 + j]
            t = time.perf_counter()
            r = run_gap(y, 100.0, model, axis=axis, seed=0)
            dt = time.perf_counter() - t
            added = "; ".join(_short(a, axis) for a in r.added) or "nothing"
            recal = ", ".join(f"{e['param']} x{e['ratio']:.2f}" for e in r.recalibrated if e["verdict"] != "consistent")
            print(f"  imu{i} {axis}: G {r.gap_before:.3g} -> {r.gap_after:.3g} (sim {r.gap_sim_before:.3g} -> "
                  f"{r.gap_sim_after:.3g}); added {added}; recalibrated {recal or 'none'} [{dt:.1f} s]")


def _short(a, axis):
    if a.get("form") == "rate_lsb":
        return f"rate quantisation N_q {a['N']:.2g}"
    ps = ", ".join(f"{k} {to_datasheet(k, v, axis):.3g}" for k, v in a.items()
                   if k not in ("effect", "ci95", "explanation") and isinstance(v, float))
    return f"{a['effect']} ({ps})"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--null-seeds", type=int, default=30)
    ap.add_argument("--skip-real", action="store_true")
    ap.add_argument("--shared", default=str(ROOT.parent / "shared" / "data"))
    a = ap.parse_args()
    t0 = time.perf_counter()
    hidden_table(a.seeds)
    null_table(a.null_seeds)
    missized_table(a.seeds)
    ardupilot(max(2, a.seeds // 3))
    if not a.skip_real:
        real(Path(a.shared))
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
