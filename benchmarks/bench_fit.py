"""Accuracy and interval coverage of the automatic fit on simulated records with known terms, side by side with a plain
weighted NNLS (weights from the measured points, N/B/K columns given, no selection, no intervals).

2 h at 50 Hz of white noise N = 1e-3 rad/s/sqrt(Hz), flicker B = 5e-4 rad/s and rate random walk
K = 6e-5 rad/s^1.5 (white meets the flicker floor near 10 s, the floor meets the random walk near 100 s).

    python -m benchmarks.bench_fit [seeds=40]

Further modes (docs/analysis.md quotes them):

    python -m benchmarks.bench_fit real [--no-shared] [LOG|FOLDER ...]
                                               real still stretches: offline N against the white-noise plateau of
                                               ADEV sqrt(tau) (computed here, no fit), online against offline; the
                                               ../shared/data recordings, then the logs named (e.g. public logs
                                               fetched for local use; a folder: every .bin/.ulg/.tlog/.csv in it)
    python -m benchmarks.bench_fit filtered [seeds=100]
                                               coverage of N's 95 % interval on white noise through a 2-pole
                                               low-pass, point-sampled (50 Hz, f_c 20 Hz) or averaged (250 Hz,
                                               f_c 30 Hz): cut-off from the log, or found in the data
    python -m benchmarks.bench_fit plain [seeds=200] [seconds=20,60,600]
                                               unfiltered white noise (+ B) analysed as a source without a
                                               cut-off is (the roll-off looked for in the data): roll-offs
                                               claimed where there is none, N's error and coverage
    python -m benchmarks.bench_fit draws [draws=100] [set=0]
                                               random N/B/K (2 h at 50 Hz): every term found, coverage;
                                               a term left out: whether its 95 % upper bound holds; each
                                               split by whether the term is detectable at all (bands with
                                               and without it apart at some tau <= T/10, no fit involved)
    python -m benchmarks.bench_fit short [seeds=200] [seconds=33]
                                               the fit and the plateau reference of `real` on the same short
                                               filtered white-noise records (the copter's 20 Hz at 50 Hz):
                                               how far apart two sound estimates of N are on such a record
    python -m benchmarks.bench_fit preset [name=copter] [seeds=20] [seconds=60]
                                               the realistic simulator's stills (sensor rate, the autopilot's
                                               filter and decimation, LSB, temperature, bias wander): N and its
                                               95 % interval, offline and online, against the logged white level
    python -m benchmarks.bench_fit gm [seeds=200]
                                               white noise + a Gauss-Markov term (three cases, 30 min-2 h at
                                               50 Hz): coverage of sigma's, tau_c's and N's 95 % intervals
    python -m benchmarks.bench_fit shape [seeds=40] [seconds=20,60,120] [log=5|none]
                                               a roll-off of first-order shape (a Gauss-Markov process of
                                               tau_c 73 ms) where the log says a 2-pole 5 Hz: N and its 95 %
                                               interval against the long-tau white level, the shape used
    python -m benchmarks.bench_fit draws null [draws=100] [set=0]
                                               the same N/B draws with K = 0: how often a K is invented
    python -m benchmarks.bench_fit --quick     the default mode on 10 seeds (the run recorded in RESULTS.md)

Each mode records its own section of benchmarks/RESULTS.md ("bench_fit draws", ...).

Target: 95 % intervals that cover the truth in about 95 % of records (a binomial count: 95 of 100 has a 90 %
range of about 91-98); N within a few % of the truth; no term invented where the data hold none.
"""

import sys
import time

import numpy as np
from scipy.optimize import nnls

from benchmarks import results
from companion.allan.adev import cluster_sizes, oavar
from companion.allan.confidence import edf_simple
from companion.allan.fit import fit_avar
from companion.allan.terms import linear_basis
from companion.sim.synth import synthesize_axis

RATE, N = 50.0, int(2 * 3600 * 50)
TRUTH = {"N": 1e-3, "B": 5e-4, "K": 6e-5}
TERMS = [{"effect": "white_noise", "N": TRUTH["N"]}, {"effect": "bias_instability", "B": TRUTH["B"]},
         {"effect": "random_walk", "K": TRUTH["K"]}]
EFFECTS = {"N": "white_noise", "B": "bias_instability", "K": "random_walk"}


def plain_nnls(tau, av, edf):
    A = linear_basis(tau, ["white_noise", "bias_instability", "random_walk"])
    w = np.sqrt(edf / 2.0) / av  # 1 / sd of each point, from the measured AVAR
    th, _ = nnls(A * w[:, None], av * w)
    return dict(zip("NBK", np.sqrt(th)))


def main(seeds: int = 40):
    m = cluster_sizes(N)
    edf = edf_simple(N + 1, m, 0)
    err = {p: [] for p in TRUTH}
    err_plain = {p: [] for p in TRUTH}
    inside = {p: 0 for p in TRUTH}
    width = {p: [] for p in TRUTH}
    missing = {p: 0 for p in TRUTH}
    extra = 0
    t_fit = []
    for seed in range(seeds):
        y = synthesize_axis(TERMS, RATE, N, np.random.default_rng(1000 + seed))
        tau, av, _, _ = oavar(y, RATE, m=m)
        t0 = time.perf_counter()
        r = fit_avar(tau, av, edf, n=N, rate_hz=RATE, m=m)
        t_fit.append(time.perf_counter() - t0)
        extra += any(t["effect"] not in EFFECTS.values() for t in r.terms)
        pl = plain_nnls(tau, av, edf)
        for p, true in TRUTH.items():
            err_plain[p].append(abs(pl[p] / true - 1))
            t = r.term(EFFECTS[p])
            if t is None:
                missing[p] += 1
                err[p].append(1.0)
                continue
            lo, hi = t["ci95"][p]
            err[p].append(abs(t[p] / true - 1))
            inside[p] += lo <= true <= hi
            width[p].append((hi - lo) / true)
    print(f"{seeds} seeds, 2 h at 50 Hz, truth N={TRUTH['N']:g} B={TRUTH['B']:g} K={TRUTH['K']:g} (SI)")
    print(f"fit time per axis: median {np.median(t_fit):.2f} s")
    print(f"{'':3}{'auto fit median/max err':>26}{'plain NNLS median/max err':>28}{'95% CI coverage':>18}"
          f"{'median CI width':>17}{'term missed':>13}")
    for p in TRUTH:
        e, q = np.array(err[p]) * 100, np.array(err_plain[p]) * 100
        print(f"{p:3}{np.median(e):>15.2f} % / {e.max():5.1f} %{np.median(q):>17.2f} % / {q.max():5.1f} %"
              f"{inside[p] / seeds * 100:>15.0f} %{np.median(width[p]) * 100:>15.1f} %{missing[p]:>13d}")
    print(f"seeds with an extra (spurious) term: {extra}")


MODES = ("real", "filtered", "draws", "short", "plain", "preset", "gm", "shape")


def cli() -> int:
    """Dispatch ``sys.argv``: --help, --quick, a mode of fit_modes, or the default mode's seed count."""
    argv = sys.argv[1:]
    if argv and argv[0] in ("-h", "--help"):
        print(__doc__)
        raise SystemExit(0)
    if argv and argv[0] in MODES:
        from benchmarks.fit_modes import main_mode

        main_mode(argv[0], argv[1:])
        return 0
    main(10 if argv[:1] == ["--quick"] else int(argv[0]) if argv else 40)
    return 0


if __name__ == "__main__":
    mode = sys.argv[1] if len(sys.argv) > 1 and sys.argv[1] in MODES else ""
    sys.exit(results.run(cli, f"bench_fit {mode}".strip()))
