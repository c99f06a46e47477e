"""Benchmark of the gap workflow (companion.gap) on hidden cases with FRESH RANDOM parameters.

    python -m benchmarks.bench_gap --quick                # a few seeds per tier, ~2 min: for development
    python -m benchmarks.bench_gap --seeds 40             # the measurement quoted in docs/gap.md
    python -m benchmarks.bench_gap --legacy --seeds 6     # also the fixed-case tables of the earlier versions

Every draw is 2 h at 50 Hz. The model is white + flicker + rate random walk with random magnitudes (N
log-uniform 3e-4..3e-3 rad/s/sqrt(Hz); the white/flicker crossover 1-100 s; the flicker/random-walk
crossover T/10..3T). A hidden effect is drawn with random shape (Gauss-Markov tau_c 0.1 s..T/200, sinusoid
peak 0.371/f0 between 4 samples and T/20) and sized so that its ADEV is 3-6x (uniform) the model's at its
own tau (the largest ratio over tau0..T/10). Seven effects: quantization, ramp, gauss_markov, sinusoid
added to that model; white_noise, bias_instability, random_walk hidden from a model that lacks the term.

Tiers (seed ranges disjoint, printed):
* single effect, exact model: the rate the workflow names exactly the hidden effect ("named"), and with
  every parameter within 30 % ("30 %"), beside an ORACLE that knows the true form: the same Allan-curve
  likelihood, the hidden effect's form given, its corrected likelihood ratio against the model compared
  with the same level (what the data allow to detect), and its parameters within 30 %.
* null: model == truth (fresh random model): false-addition and false-recalibration rates (target <= 2 %).
* mis-sized model: each model term off by a factor drawn uniform 0.7-1.4, plus one hidden effect
  (quantization, ramp, gauss_markov, sinusoid): named exactly; model terms after within 30 % of the truth.
* two effects at once (two of quantization, ramp, gauss_markov, sinusoid): both named, nothing else.
* the ramp-under-random-walk family: ramp R around 4.9e-6 rad/s^2 under N 1.5e-3, B 7.3e-4, K 2e-5 (each x0.8-1.25):
  ramp named vs random walk K recalibrated.
* ramp or random walk (``--only ramp-rw``, ``--hard-draws`` each): a ramp or a random walk hidden from a mis-sized
  white + flicker model, both directions of the look-alike rule of companion.gap.trend.
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

from benchmarks import results
from benchmarks.results import SHARED_DATA
from companion.gap import run_gap  # noqa: E402
from companion.gap.workflow import NOISE_FLOOR_G  # noqa: E402
from companion.sim.synth import synthesize_axis  # noqa: E402
from companion.units import to_datasheet  # noqa: E402

RATE = 20.0
N = int(2 * 3600 * RATE)
WB = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 1e-4}]
WB_TXT = "white N 1e-3 + bias instability B 1e-4"
CASES = [
    ("quantization Q=6e-4", WB, {"effect": "quantization", "Q": 6e-4}),
    ("quantization Q=3e-3", WB, {"effect": "quantization", "Q": 3e-3}),
    ("white_noise N=1e-3", [{"effect": "quantization", "Q": 1e-4}, {"effect": "bias_instability", "B": 1e-4},
                            {"effect": "random_walk", "K": 5e-6}], {"effect": "white_noise", "N": 1e-3}),
    ("bias_instab B=2e-4", [{"effect": "white_noise", "N": 1e-3}, {"effect": "random_walk", "K": 1e-6}],
     {"effect": "bias_instability", "B": 2e-4}),
    ("random_walk K=3e-5", WB, {"effect": "random_walk", "K": 3e-5}),
    ("random_walk K=1e-4", WB, {"effect": "random_walk", "K": 1e-4}),
    ("random_walk K=1e-3", WB, {"effect": "random_walk", "K": 1e-3}),
    ("ramp R=4e-7", WB, {"effect": "ramp", "R": 4e-7}),
    ("ramp R=2e-6", WB, {"effect": "ramp", "R": 2e-6}),
    ("gauss_markov 8e-4,30s", WB, {"effect": "gauss_markov", "sigma": 8e-4, "tau_c": 30.0}),
    ("gauss_markov 2e-3,3s", WB, {"effect": "gauss_markov", "sigma": 2e-3, "tau_c": 3.0}),
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


def _psd_one_sided(f, N, B, sigma, tau_c):
    """One-sided PSD of white (2 N^2) + flicker (B^2 / (pi f)) + sampled Gauss-Markov (AR(1), variance
    sigma^2) rate noise at RATE, as the simulator makes them (IEEE 952 PSDs are two-sided)."""
    phi = math.exp(-1.0 / (RATE * tau_c))
    w = 2.0 * math.pi * f / RATE
    gm = (2.0 / RATE) * sigma**2 * (1.0 - phi**2) / np.abs(1.0 - phi * np.exp(-1j * w)) ** 2
    return 2.0 * N**2 + B**2 / (math.pi * f) + gm


def whittle_crlb(psd, params, k, n=N):
    """Cramer-Rao bound on the standard error of ln params[k] from n samples of noise with one-sided PSD
    ``psd(f, *params)``: Whittle Fisher information I = sum_j (d ln S(f_j) / d theta)(d ln S(f_j) / d theta)^T
    over the Fourier frequencies f_j = j RATE / n, theta = ln params (the periodogram ordinates are
    S chi^2_2 / 2, independent)."""
    f = np.arange(1, n // 2 + 1) * RATE / n
    p0 = np.log(params)
    grads = []
    for j in range(len(params)):
        h = np.zeros(len(params))
        h[j] = 1e-5
        grads.append((np.log(psd(f, *np.exp(p0 + h))) - np.log(psd(f, *np.exp(p0 - h)))) / 2e-5)
    G = np.array(grads)
    return float(math.sqrt(np.linalg.inv(G @ G.T)[k, k]))


def crlb_log_tau_c(N_, B, sigma, tau_c, n=N):
    """Cramer-Rao bound on the standard error of ln tau_c (white + flicker + Gauss-Markov, all free)."""
    return whittle_crlb(_psd_one_sided, [N_, B, sigma, tau_c], 3, n)


def whittle_tau_c(y, tau_c0, fmax=0.5):
    """Oracle: Whittle maximum-likelihood tau_c of y *knowing* the form white + flicker + Gauss-Markov."""
    from scipy.optimize import minimize

    n = y.shape[0]
    Y = np.fft.rfft(y - y.mean())
    f = np.fft.rfftfreq(n, 1.0 / RATE)
    per = 2.0 * np.abs(Y) ** 2 / (n * RATE)
    sel = (f > 0) & (f <= fmax)
    f, per = f[sel], per[sel]

    def nll(p):
        s = _psd_one_sided(f, *np.exp(p))
        return float(np.sum(np.log(s) + per / s))

    best = None
    for t in (tau_c0 / 3, tau_c0, 3 * tau_c0):
        r = minimize(nll, np.log([1e-3, 1e-4, 5e-4, t]), method="Nelder-Mead",
                     options={"xatol": 1e-5, "fatol": 1e-6, "maxiter": 4000, "maxfev": 8000})
        best = r if best is None or r.fun < best.fun else best
    return float(math.exp(best.x[3]))


def limit_table(seeds):
    """Gauss-Markov with tau_c a sizeable part of the record: what an ideal estimator could do, and what
    the workflow does."""
    from scipy.stats import norm

    T = N / RATE
    print(f"\n== information limit: Gauss-Markov sigma 5e-4 over {WB_TXT}, T = {T:.0f} s, {seeds} seeds ==")
    print("CRLB: Cramer-Rao se of ln tau_c (Whittle); 'ideal 30 %': P(|tau_c err| <= 30 %) for an efficient "
          "estimator; oracle: Whittle MLE knowing the true form; workflow: its Gauss-Markov candidate's tau_c, "
          "what it named, 'ok' as in the table above, and the corrected GM-vs-random-walk likelihood ratio "
          "(threshold 10.8)")
    print(f"{'tau_c':>6} {'T/tau_c':>7} {'CRLB':>5} {'ideal 30%':>9} {'oracle 30%':>10} {'GM fit 30%':>10} "
          f"{'ok':>5} {'named':36} {'LR med':>6}")
    for tau_c in (75.0, 150.0, 300.0, 600.0):
        hidden = {"effect": "gauss_markov", "sigma": 5e-4, "tau_c": tau_c}
        se = crlb_log_tau_c(1e-3, 1e-4, 5e-4, tau_c)
        ideal = norm.cdf(math.log(1.3) / se) - norm.cdf(math.log(0.7) / se)
        o30 = a30 = ok_n = 0
        named, lrs = {}, []
        for seed in range(seeds):
            y = synthesize_axis(WB + [hidden], RATE, N, np.random.default_rng(1000 + seed))
            o30 += abs(whittle_tau_c(y, tau_c) / tau_c - 1) <= 0.3
            r = run_gap(y, RATE, WB, seed=seed, simulate=False)
            it = r.iterations[0]
            gm = next(c for c in it["candidates"] if c["effect"] == "gauss_markov")
            a30 += abs(gm["params"]["tau_c"] / tau_c - 1) <= 0.3
            if "nested" in it:
                lrs.append(it["nested"]["lr"])
            ok_n += judge(r, hidden)[0]
            key = "+".join(a["effect"] for a in r.added) or "(nothing)"
            named[key] = named.get(key, 0) + 1
        named_s = ", ".join(f"{k} {v}" for k, v in sorted(named.items(), key=lambda kv: -kv[1]))
        print(f"{tau_c:6.0f} {T / tau_c:7.0f} {se:5.2f} {ideal:9.2f} {o30:>7}/{seeds:<2} {a30:>7}/{seeds:<2} "
              f"{ok_n:>2}/{seeds:<2} {named_s:36} {np.median(lrs) if lrs else float('nan'):6.1f}")


def nested_null_table(seeds):
    """Random-walk truth: the Gauss-Markov-over-random-walk likelihood ratio, raw and corrected (the null
    distribution of the nested test; a Gauss-Markov named here would be a false name)."""
    from companion.gap.candidates import fit_with_candidate, gm_rw_direction, lr_inflation
    from companion.gap.compare import measure

    print(f"\n== GM-vs-random-walk test under random-walk truth ({WB_TXT} + K), {seeds} seeds per K ==")
    worst_raw, worst = [], []
    for K in (3e-5, 1e-4, 3e-4, 1e-3):
        raw, corr = [], []
        for seed in range(seeds):
            y = synthesize_axis(WB + [{"effect": "random_walk", "K": K}], RATE, N,
                                np.random.default_rng(7000 + seed))
            m = measure(y, RATE)
            g = fit_with_candidate(m, WB, [], "gauss_markov")
            rw = fit_with_candidate(m, WB, [], "random_walk")
            phi = lr_inflation(m, rw, 2, direction=gm_rw_direction(m, rw.terms[2]["K"])) if rw.terms[2]["K"] > 0 else 1.0
            raw.append(rw.dev - g.dev)
            corr.append((rw.dev - g.dev) / phi)
        worst_raw.append(max(raw))
        worst.append(max(corr))
        print(f"  K {K:.0e}: raw LR max {max(raw):5.1f} (> 15.1: {sum(x > 15.1 for x in raw)}), corrected max "
              f"{max(corr):4.1f} (> 10.8: {sum(x > 10.8 for x in corr)})")
    print(f"  all {4 * seeds} draws: raw max {max(worst_raw):.1f}, corrected max {max(worst):.1f} (threshold 10.8)")


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
        verdicts = [f"{e['verdict'][:9]} (LR {e['lr']:.1f})" for e in r.recalibrated]
        ok_n += ok
        print(f"  factors {f[0]:.2f} {f[1]:.2f}: named {names}, verdicts {verdicts}, terms after within "
              f"{100 * max(errs):.0f} % of truth, G {r.gap_before:.3g} -> {r.gap_after:.3g}")
    print(f"ok {ok_n}/{seeds}")


def missized_power(seeds):
    """How often a model B off by a factor is called mis-sized (truth N 1e-3, B 2e-4, nothing hidden), beside
    the spread of the fitted B and its Cramer-Rao bound (Whittle, white + flicker)."""
    from companion.gap.candidates import fit_terms
    from companion.gap.compare import measure

    truth = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 2e-4}]
    factors = (0.6, 0.7, 1.4, 1.6)
    called = {f: 0 for f in factors}
    ln_fit = []
    for seed in range(seeds):
        y = synthesize_axis(truth, RATE, N, np.random.default_rng(3000 + seed))
        ln_fit.append(math.log(fit_terms(measure(y, RATE), truth).terms[1]["B"] / 2e-4))
        for f in factors:
            model = [dict(truth[0]), {"effect": "bias_instability", "B": 2e-4 * f}]
            e = run_gap(y, RATE, model, simulate=False).recalibrated[1]
            called[f] += e["verdict"] == ("too small" if f < 1 else "too large")
    crlb = whittle_crlb(lambda f, N_, B: _psd_one_sided(f, N_, B, 0.0, 1.0), [1e-3, 2e-4], 1)
    print(f"\n== model B off by a factor (truth N 1e-3, B 2e-4), {seeds} seeds: called mis-sized ==")
    print("  " + ", ".join(f"x{f}: {called[f]}/{seeds}" for f in factors)
          + f"; spread of the fitted ln B {np.std(ln_fit):.3f} (Cramer-Rao {crlb:.3f})")


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
    if "spectral" in a:
        sp = a["spectral"]
        ps += (f"; periodogram: line {sp['peak_ratio']:.3g}x level, {to_datasheet('amplitude', sp['amplitude_psd'], axis):.3g}"
               f" deg/h, {'confirmed' if sp['confirmed'] else 'NO LINE'}")
    if "alternative" in a:
        ps += f"; alternative gauss_markov tau_c {a['alternative']['tau_c']:.3g} s"
    return f"{a['effect']} ({ps})"


# --- fresh random draws (the measurement of docs/gap.md) ---------------------------------------------
F_RATE = 50.0
F_T = 7200.0
F_N = int(F_T * F_RATE)
MODEL_EFFECTS = ("white_noise", "bias_instability", "random_walk")
ADDED = ("quantization", "ramp", "gauss_markov", "sinusoid")
EFFECTS = ("quantization", "white_noise", "bias_instability", "random_walk", "ramp", "gauss_markov", "sinusoid")


def _loguniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_model(rng):
    """White + flicker + random walk with random magnitudes and crossovers (see the module docstring)."""
    N_ = _loguniform(rng, 3e-4, 3e-3)
    B = N_ / math.sqrt(_loguniform(rng, 1.0, 100.0)) / 0.664
    K = 0.664 * B * math.sqrt(3.0 / _loguniform(rng, F_T / 10, 3 * F_T))
    return [{"effect": "white_noise", "N": N_}, {"effect": "bias_instability", "B": B},
            {"effect": "random_walk", "K": K}]


def _size_taus():
    return np.logspace(math.log10(1.0 / F_RATE), math.log10(F_T / 10), 60)


def draw_effect(effect, base, rng, ratio=None):
    """A hidden term of ``effect`` with random shape, its ADEV ``ratio`` (default uniform 3-6) times the
    model's at its own tau (the largest ratio over tau0..T/10)."""
    from companion.gap.candidates import MAGNITUDE
    from companion.gap.compare import model_avar

    ratio = rng.uniform(3.0, 6.0) if ratio is None else ratio
    mag = MAGNITUDE[effect]
    term = {"effect": effect, mag: 1.0}
    if effect == "gauss_markov":
        term["tau_c"] = _loguniform(rng, 0.1, F_T / 200)
    elif effect == "sinusoid":
        term["freq_hz"] = 0.371 / _loguniform(rng, 4.0 / F_RATE, F_T / 20)
    tau = _size_taus()
    r = np.sqrt(model_avar([term], tau, F_RATE) / model_avar(base, tau, F_RATE))
    term[mag] = float(ratio / np.max(r))
    return term


def _scaled(terms, rng, lo=0.7, hi=1.4):
    from companion.gap.candidates import MAGNITUDE

    out, f = [], []
    for t in terms:
        p = MAGNITUDE[t["effect"]]
        f.append(rng.uniform(lo, hi))
        out.append({**t, p: t[p] * f[-1]})
    return out, f


def _params_ok(got, truth, tol=0.30):
    return all(abs(got[p] / v - 1) <= tol for p, v in truth.items() if p != "effect" and p in got)


def oracle(meas, model, hidden, free_model=False, others=()):
    """Knows the true form: fits ``model`` (held, or free with ``free_model``) + ``others`` + ``hidden``'s
    form; detected when the corrected likelihood ratio of the hidden term against the same fit without it
    passes the workflow's level (chi^2_k(1 - 1e-4)); returns (detected, params within 30 %)."""
    from companion.gap.candidates import N_PARAMS, fit_terms, fit_with_candidate, lr_inflation, unit_column
    from companion.gap.selection import add_penalty

    terms = [dict(t) for t in model] + [dict(t) for t in others]
    held = [] if free_model else list(range(len(model)))
    base = fit_terms(meas, terms, held, intervals=False)
    f = fit_with_candidate(meas, terms, held, hidden["effect"])
    phi = lr_inflation(meas, base, None, direction=[unit_column(f.terms[-1], meas.tau, meas.rate_hz)])
    detected = (base.dev - f.dev) / phi > add_penalty(N_PARAMS[hidden["effect"]])
    return bool(detected), bool(detected and _params_ok(f.terms[-1], hidden))


def _named(r):
    return [a["effect"] for a in r.added if a.get("form") != "rate_lsb"]


#: runs of the workflow, and Gauss-Markov terms in their final models (added or kept) with tau_c < 3 tau0
TAU_C_RULE = {"runs": 0, "gm_terms": 0, "below_3_tau0": 0}


def _run(truth, model, seed):
    y = synthesize_axis(truth, F_RATE, F_N, np.random.default_rng(seed))
    r = run_gap(y, F_RATE, model, seed=seed, simulate=False)
    TAU_C_RULE["runs"] += 1
    for t in r.terms_after:
        if t["effect"] == "gauss_markov":
            TAU_C_RULE["gm_terms"] += 1
            TAU_C_RULE["below_3_tau0"] += t["tau_c"] < 3.0 / F_RATE * (1 - 1e-9)
    return y, r, r.measured


_LAP = [time.perf_counter()]


def _lap() -> float:
    """Wall seconds since the previous row (or tier start): each row of a table says what it cost."""
    t = time.perf_counter()
    dt, _LAP[0] = t - _LAP[0], t
    return dt


def _pct(k, n):
    return f"{k:>3}/{n:<3} {100.0 * k / max(n, 1):5.1f} %"


def single_tier(seeds, seed0=100_000, only=None):
    print(f"\n== single hidden effect, exact model, fresh random draws: {seeds} per effect, 2 h at {F_RATE:g} Hz ==")
    print(f"{'effect':17} {'named':>15} {'30 %':>15} {'oracle named':>15} {'oracle 30 %':>15}  named instead (counts)")
    tot = [0, 0, 0, 0, 0]
    for e_i, effect in enumerate(EFFECTS):
        if only is not None and effect not in only:  # the same seeds as in a full run
            continue
        c = [0, 0, 0, 0]
        wrong: dict[str, int] = {}
        for s in range(seeds):
            seed = seed0 + 1000 * e_i + s
            rng = np.random.default_rng(seed)
            full = draw_model(rng)
            model = [t for t in full if t["effect"] != effect]
            hidden = draw_effect(effect, model, rng)
            _, r, meas = _run(model + [hidden], model, seed)
            names = _named(r)
            ok = names == [effect]
            c[0] += ok
            c[1] += ok and _params_ok(r.added[-1], hidden)
            od, o30 = oracle(meas, model, hidden)
            c[2] += od
            c[3] += o30
            if not ok:
                key = "+".join(names) or "(nothing)"
                recal = [e["param"] for e in r.recalibrated if e["verdict"] != "consistent"]
                key += (" & recal " + ",".join(recal)) if recal else ""
                wrong[key] = wrong.get(key, 0) + 1
        for j in range(4):
            tot[j] += c[j]
        tot[4] += seeds
        w = ", ".join(f"{k} {v}" for k, v in sorted(wrong.items(), key=lambda kv: -kv[1])) or "-"
        print(f"{effect:17} {_pct(c[0], seeds)} {_pct(c[1], seeds)} {_pct(c[2], seeds)} {_pct(c[3], seeds)}  {w}"
              f"  [{_lap():.0f} s]", flush=True)
    print(f"{'all':17} {_pct(tot[0], tot[4])} {_pct(tot[1], tot[4])} {_pct(tot[2], tot[4])} {_pct(tot[3], tot[4])}")


def null_fresh(seeds, seed0=200_000):
    print(f"\n== null case: model == truth, fresh random models, {seeds} draws ==")
    added = recal = 0
    g = []
    what: dict[str, int] = {}
    for s in range(seeds):
        rng = np.random.default_rng(seed0 + s)
        model = draw_model(rng)
        _, r, _ = _run(model, model, seed0 + s)
        a = bool(r.added)
        m = any(e["verdict"] != "consistent" for e in r.recalibrated)
        added += a
        recal += m
        g.append(r.gap_before)
        if a or m:
            key = "+".join(_named(r)) + "|" + ",".join(e["param"] for e in r.recalibrated if e["verdict"] != "consistent")
            what[key] = what.get(key, 0) + 1
    g = np.array(g)
    print(f"false additions {_pct(added, seeds)}; false recalibrations {_pct(recal, seeds)}; G median "
          f"{np.median(g):.2f}, 95th pct {np.percentile(g, 95):.2f}, max {g.max():.2f}; {what or ''}")


def missized_tier(seeds, seed0=300_000):
    print(f"\n== mis-sized model (each term x0.7-1.4) + one hidden effect, {seeds} draws per effect ==")
    print(f"{'effect':17} {'named':>15} {'terms<=30 %':>15} {'oracle named':>15}  named instead (counts)")
    tot = [0, 0, 0, 0]
    for e_i, effect in enumerate(ADDED):
        c = [0, 0, 0]
        wrong: dict[str, int] = {}
        for s in range(seeds):
            seed = seed0 + 1000 * e_i + s
            rng = np.random.default_rng(seed)
            truth = draw_model(rng)
            hidden = draw_effect(effect, truth, rng)
            model, _ = _scaled(truth, rng)
            _, r, meas = _run(truth + [hidden], model, seed)
            names = _named(r)
            c[0] += names == [effect]
            c[1] += all(abs(t[p] / tr[p] - 1) <= 0.30 for t, tr in zip(r.terms_after, truth)
                        for p in tr if p != "effect")
            c[2] += oracle(meas, truth, hidden, free_model=True)[0]
            if names != [effect]:
                key = "+".join(names) or "(nothing)"
                wrong[key] = wrong.get(key, 0) + 1
        for j in range(3):
            tot[j] += c[j]
        tot[3] += seeds
        w = ", ".join(f"{k} {v}" for k, v in sorted(wrong.items(), key=lambda kv: -kv[1])) or "-"
        print(f"{effect:17} {_pct(c[0], seeds)} {_pct(c[1], seeds)} {_pct(c[2], seeds)}  {w}  [{_lap():.0f} s]",
              flush=True)
    print(f"{'all':17} {_pct(tot[0], tot[3])} {_pct(tot[1], tot[3])} {_pct(tot[2], tot[3])}")


def two_effect_tier(seeds, seed0=400_000, only=None):
    pairs = [(a, b) for i, a in enumerate(ADDED) for b in ADDED[i + 1:]]
    print(f"\n== two hidden effects at once, exact model, {seeds} draws per pair ==")
    print(f"{'pair':30} {'both named':>15} {'oracle both':>15}  named instead (counts)")
    tot = [0, 0, 0]
    for p_i, (e1, e2) in enumerate(pairs):
        if only is not None and p_i not in only:
            continue
        c = [0, 0]
        wrong: dict[str, int] = {}
        for s in range(seeds):
            seed = seed0 + 1000 * p_i + s
            rng = np.random.default_rng(seed)
            model = draw_model(rng)
            h1 = draw_effect(e1, model, rng)
            h2 = draw_effect(e2, model, rng)
            _, r, meas = _run(model + [h1, h2], model, seed)
            names = _named(r)
            ok = sorted(names) == sorted([e1, e2])
            c[0] += ok
            c[1] += oracle(meas, model, h1, others=[h2])[0] and oracle(meas, model, h2, others=[h1])[0]
            if not ok:
                key = "+".join(names) or "(nothing)"
                wrong[key] = wrong.get(key, 0) + 1
        tot[0] += c[0]
        tot[1] += c[1]
        tot[2] += seeds
        w = ", ".join(f"{k} {v}" for k, v in sorted(wrong.items(), key=lambda kv: -kv[1])) or "-"
        print(f"{e1 + ' + ' + e2:30} {_pct(c[0], seeds)} {_pct(c[1], seeds)}  {w}  [{_lap():.0f} s]", flush=True)
    print(f"{'all':30} {_pct(tot[0], tot[2])} {_pct(tot[1], tot[2])}")


HARD_CASES = [("quantization",), ("ramp",), ("gauss_markov",), ("sinusoid",), ("random_walk",),
              ("gauss_markov", "sinusoid"), ("ramp", "gauss_markov")]


def hard_tier(draws, seed0=600_000, cases=None):
    """The hard tier: the model handed over is mis-sized (each term x0.7-1.4) and one or two effects hide
    in the data (a hidden random walk is taken out of the model). Right = exactly the hidden set named and
    the gap after within the noise floor (G <= 2). The oracle knows the truth: each hidden form added to
    the (free) model with the other hidden terms present, detected at the workflow's level."""
    print(f"\n== hard tier: mis-sized model (x0.7-1.4) + one or two hidden effects, {draws} draws per case, "
          f"seeds {seed0}+ ==")
    print(f"{'hidden':28} {'right set':>15} {'& G<=2':>15} {'oracle':>15}  G after median  named instead (counts)")
    tot = [0, 0, 0, 0]
    for c_i, case in enumerate(HARD_CASES):
        if cases is not None and c_i not in cases:
            continue
        c = [0, 0, 0]
        g_after = []
        wrong: dict[str, int] = {}
        for s in range(draws):
            seed = seed0 + 1000 * c_i + s
            rng = np.random.default_rng(seed)
            truth = draw_model(rng)
            base = [t for t in truth if t["effect"] not in case]
            hidden = [draw_effect(e, base, rng) for e in case]
            model, _ = _scaled(base, rng)
            _, r, meas = _run(base + hidden, model, seed)
            names = _named(r)
            ok = sorted(names) == sorted(case)
            c[0] += ok
            c[1] += ok and r.gap_after <= NOISE_FLOOR_G
            g_after.append(r.gap_after)
            c[2] += all(oracle(meas, base, h, free_model=True, others=[x for x in hidden if x is not h])[0]
                        for h in hidden)
            if not (ok and r.gap_after <= NOISE_FLOOR_G):
                key = ("+".join(names) or "(nothing)") + ("" if ok else "") + \
                    (f" G {r.gap_after:.2f}" if ok else "")
                wrong[key] = wrong.get(key, 0) + 1
        for j in range(3):
            tot[j] += c[j]
        tot[3] += draws
        w = ", ".join(f"{k} {v}" for k, v in sorted(wrong.items(), key=lambda kv: -kv[1])) or "-"
        print(f"{' + '.join(case):28} {_pct(c[0], draws)} {_pct(c[1], draws)} {_pct(c[2], draws)}  "
              f"{np.median(g_after):6.2f}          {w}  [{_lap():.0f} s]", flush=True)
    print(f"{'all':28} {_pct(tot[0], tot[3])} {_pct(tot[1], tot[3])} {_pct(tot[2], tot[3])}")


def ramp_rw_tier(draws, seed0=700_000):
    """Ramp or random walk, both directions: a ramp or a rate random walk hidden from a mis-sized (x0.7-1.4)
    white + flicker model (no random-walk term, so 'random_walk' is a candidate beside 'ramp'). Right = the
    hidden one named alone and G after <= 2. Also, wherever a ramp and a random walk both passed on the Allan
    curve, the ramp-or-random-walk rule's record (companion.gap.trend): the evidence for the random walk (its
    prediction of the detrended record against the ramp's, > 0: the random walk), the free random walk's
    corrected LR in the detrended record, and which of the two led the Allan ranking and which was named."""
    print(f"\n== ramp or random walk: hidden from a mis-sized white + flicker model, {draws} draws each, seeds {seed0}+ ==")
    print(f"{'hidden':14} {'right':>15}  where tested: evidence for the random walk / free detrended random-walk LR "
          f"(led -> named)  named instead (counts)")
    tot = [0, 0]
    for e_i, effect in enumerate(("ramp", "random_walk")):
        ok_n, lrs, wrong = 0, [], {}
        for s in range(draws):
            seed = seed0 + 1000 * e_i + s
            rng = np.random.default_rng(seed)
            base = draw_model(rng)[:2]
            hidden = draw_effect(effect, base, rng)
            model, _ = _scaled(base, rng)
            _, r, _ = _run(base + [hidden], model, seed)
            names = _named(r)
            ok = names == [effect] and r.gap_after <= NOISE_FLOOR_G
            ok_n += ok
            lrs += [f"{it['trend']['evidence']:+.0f}/{it['trend']['lr']:.1f} ({it['trend']['led'][:4]}->"
                    f"{it['trend']['named'][:4]})" for it in r.iterations if it.get("trend")]
            if not ok:
                key = "+".join(names) or "(nothing)"
                wrong[key] = wrong.get(key, 0) + 1
        tot[0] += ok_n
        tot[1] += draws
        w = ", ".join(f"{k} {v}" for k, v in sorted(wrong.items(), key=lambda kv: -kv[1])) or "-"
        print(f"{effect:14} {_pct(ok_n, draws)}  {', '.join(lrs) or '-'}  {w}  [{_lap():.0f} s]", flush=True)
    print(f"{'all':14} {_pct(tot[0], tot[1])}")


def issue_ramp_family(seeds, seed0=500_000):
    """The ramp-under-random-walk case and draws around it: ramp named, and how the random-walk recalibration fared."""
    print(f"\n== ramp-under-random-walk family: ramp ~4.9e-6 rad/s^2 under N 1.5e-3, B 7.3e-4, K 2e-5 (each x0.8-1.25), "
          f"{seeds} draws ==")
    named = k_recal = 0
    margins = []
    for s in range(seeds):
        rng = np.random.default_rng(seed0 + s)
        f = rng.uniform(0.8, 1.25, 4) if s else np.ones(4)
        model = [{"effect": "white_noise", "N": 1.5e-3 * f[0]}, {"effect": "bias_instability", "B": 7.3e-4 * f[1]},
                 {"effect": "random_walk", "K": 2e-5 * f[2]}]
        _, r, _ = _run(model + [{"effect": "ramp", "R": 4.9e-6 * f[3]}], model, seed0 + s)
        named += _named(r) == ["ramp"]
        k_recal += r.recalibrated[2]["verdict"] != "consistent"
        first = r.iterations[0]
        ex = {x["explanation"]: x for x in first.get("explanations", [])}
        kx = ex.get("recalibrated random_walk K")
        if first.get("chosen") == "ramp" and kx is not None:
            margins.append(first["test"]["score"] - kx["score"])
    m = f"; score margin of ramp over 'random walk K recalibrated' at step 1: min {min(margins):.0f}, median " \
        f"{np.median(margins):.0f}" if margins else ""
    print(f"ramp named {_pct(named, seeds)}; K called mis-sized {_pct(k_recal, seeds)}{m}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=40, help="draws per effect (single tier); the mis-sized tier "
                    "uses the same, the two-effect tier half per pair (default 40)")
    ap.add_argument("--null-seeds", type=int, default=None, help="null draws (default 2.5 x --seeds)")
    ap.add_argument("--quick", action="store_true", help="4 draws per effect, 10 null: a smoke run")
    ap.add_argument("--only", choices=("single", "null", "missized", "two", "issue", "hard", "ramp-rw"), help="run one tier")
    ap.add_argument("--fresh", action="store_true", help="fresh random draws: the seed ranges start at a number "
                    "drawn from the OS entropy (printed, so a run can be repeated), not at the fixed defaults")
    ap.add_argument("--offset", type=int, help="the seed offset / 10^6 of an earlier --fresh run, to repeat it")
    ap.add_argument("--hard-draws", type=int, default=10, help="draws per case of the hard tier (default 10)")
    ap.add_argument("--two-pairs", help="comma-separated indices of the two-effect tier's pairs to run (0 "
                    "quantization + ramp, ... 2 quantization + sinusoid, ... 5 gauss_markov + sinusoid; default all)")
    ap.add_argument("--hard-cases", help="comma-separated indices of HARD_CASES to run (default all; to run "
                    "the cases in parallel processes)")
    ap.add_argument("--legacy", action="store_true", help="also the fixed-case tables of the earlier versions "
                    "(20 Hz; information limit, nested null, B power, ArduPilot rounding, real ADIS16405)")
    ap.add_argument("--effects", help="comma-separated effects of the single tier to run (default all; each "
                    "keeps its seeds)")
    ap.add_argument("--skip-real", action="store_true")
    ap.add_argument("--shared", default=str(SHARED_DATA))
    a = ap.parse_args()
    if a.quick:
        a.seeds = 4
    null_seeds = a.null_seeds if a.null_seeds is not None else (10 if a.quick else int(2.5 * a.seeds))
    t0 = time.perf_counter()
    off = 0
    if a.offset is not None:
        off = a.offset * 10**6
        print(f"every tier's seeds offset by {off}")
    elif a.fresh:
        off = int(np.random.SeedSequence().entropy % 10**9) * 10**6
        print(f"fresh draws: every tier's seeds offset by {off} (repeat with the same offset to reproduce)")
    only = set(a.effects.split(",")) if a.effects else None
    tiers = {"single": lambda: single_tier(a.seeds, 100_000 + off, only), "null": lambda: null_fresh(null_seeds, 200_000 + off),
             "missized": lambda: missized_tier(a.seeds, 300_000 + off),
             "two": lambda: two_effect_tier(max(2, a.seeds // 2), 400_000 + off,
                                            None if not a.two_pairs else {int(x) for x in a.two_pairs.split(",")}),
             "issue": lambda: issue_ramp_family(a.seeds, 500_000 + off),
             "hard": lambda: hard_tier(a.hard_draws, 600_000 + off,
                                       None if not a.hard_cases else {int(x) for x in a.hard_cases.split(",")}),
             "ramp-rw": lambda: ramp_rw_tier(a.hard_draws, 700_000 + off)}
    for name, fn in tiers.items():
        if a.only in (None, name):
            t = time.perf_counter()
            _LAP[0] = t
            fn()
            print(f"[{name}: {time.perf_counter() - t:.0f} s]", flush=True)
    if a.legacy:
        hidden_table(a.seeds)
        limit_table(2 * a.seeds)
        nested_null_table(max(4, 8 * a.seeds // 3))
        null_table(null_seeds)
        missized_table(a.seeds)
        missized_power(2 * a.seeds)
        ardupilot(max(2, a.seeds // 3))
        if not a.skip_real:
            real(Path(a.shared))
    print(f"tau_c >= 3 tau0 rule: {TAU_C_RULE['gm_terms']} Gauss-Markov terms in the final models of "
          f"{TAU_C_RULE['runs']} fresh-draw runs, {TAU_C_RULE['below_3_tau0']} with tau_c < 3 tau0")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    sys.exit(results.run(main))
