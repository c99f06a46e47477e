"""Automatic fit against simulated data with known terms (N, B and K recovered within their intervals) and edge cases."""

import math

import numpy as np
import pytest

from companion.allan.adev import cluster_sizes, oavar
from companion.allan.confidence import edf_simple
from companion.allan.fit import fit_avar
from companion.sim.synth import synthesize_axis

RATE = 50.0
N2H = int(2 * 3600 * RATE)
# N, B, K a decade apart: white meets the flicker floor near 10 s, the floor meets the random walk near 100 s
TRUTH = {"N": 1e-3, "B": 5e-4, "K": 6e-5}
TERMS = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 5e-4},
         {"effect": "random_walk", "K": 6e-5}]


def fit_series(y, effects=None):
    m = cluster_sizes(len(y))
    tau, av, _, _ = oavar(y, RATE, m=m)
    return fit_avar(tau, av, edf_simple(len(y) + 1, m, 0), effects, n=len(y), rate_hz=RATE, m=m)


@pytest.mark.soak
def test_n_b_k_recovered_with_calibrated_intervals():
    errs = {p: [] for p in TRUTH}
    inside = 0
    seeds = range(12)
    for seed in seeds:
        r = fit_series(synthesize_axis(TERMS, RATE, N2H, np.random.default_rng(seed)))
        got = {t["effect"]: t for t in r.terms}
        assert set(got) <= {"white_noise", "bias_instability", "random_walk", "quantization", "ramp", "gauss_markov"}
        for effect, p in (("white_noise", "N"), ("bias_instability", "B"), ("random_walk", "K")):
            t = got.get(effect)
            assert t is not None, (seed, r.terms)
            errs[p].append(abs(t[p] / TRUTH[p] - 1))
            lo, hi = t["ci95"][p]
            assert lo <= t[p] <= hi
            inside += lo <= TRUTH[p] <= hi
    assert max(errs["N"]) < 0.02 and np.median(errs["N"]) < 0.002
    assert max(errs["B"]) < 0.20 and np.median(errs["B"]) < 0.05
    assert max(errs["K"]) < 0.50 and np.median(errs["K"]) < 0.20
    # 36 intervals at 95 %: P(<= 30 inside) ~ 0.4 %; all 36 inside would also be suspicious only over more seeds
    assert inside >= 31, inside


def test_missing_slope_regions_give_no_nan():
    y = synthesize_axis([{"effect": "white_noise", "N": 2e-3}], RATE, 20000, np.random.default_rng(1))
    r = fit_series(y)
    assert [t["effect"] for t in r.terms] == ["white_noise"]
    assert r.terms[0]["N"] == pytest.approx(2e-3, rel=0.03)
    assert np.all(np.isfinite(r.avar_fit)) and math.isfinite(r.chi2)


def test_constant_axis_returns_no_terms():
    r = fit_avar(np.array([0.1, 0.2, 0.4]), np.zeros(3), np.ones(3))
    assert r.terms == [] and r.notes


def test_gauss_markov_found_and_tau_c_interval_covers_truth():
    terms = [{"effect": "white_noise", "N": 5e-4}, {"effect": "gauss_markov", "sigma": 1e-3, "tau_c": 20.0}]
    r = fit_series(synthesize_axis(terms, RATE, N2H, np.random.default_rng(4)))
    gm = r.term("gauss_markov")
    assert gm is not None, r.terms
    assert gm["ci95"]["tau_c"][0] <= 20.0 <= gm["ci95"]["tau_c"][1]
    assert gm["sigma"] == pytest.approx(1e-3, rel=0.25)


def test_ramp_found():
    terms = [{"effect": "white_noise", "N": 1e-3}, {"effect": "ramp", "R": 3e-7}]
    r = fit_series(synthesize_axis(terms, RATE, N2H // 2, np.random.default_rng(2)))
    assert r.term("ramp")["R"] == pytest.approx(3e-7, rel=0.1)


def test_explicit_effects_and_diagonal_mode():
    y = synthesize_axis(TERMS[:2], RATE, N2H // 4, np.random.default_rng(3))
    m = cluster_sizes(len(y))
    tau, av, _, _ = oavar(y, RATE, m=m)
    r = fit_avar(tau, av, edf_simple(len(y) + 1, m, 0), ["white_noise", "bias_instability"])
    assert r.covariance_mode == "diagonal"
    assert r.term("white_noise")["N"] == pytest.approx(1e-3, rel=0.02)
    assert r.term("bias_instability")["B"] == pytest.approx(5e-4, rel=0.3)
    with pytest.raises(ValueError):
        fit_avar(tau, av, None, ["pink"])


def test_sinusoid_when_asked():
    terms = [{"effect": "white_noise", "N": 1e-3}, {"effect": "sinusoid", "amplitude": 2e-3, "freq_hz": 0.05}]
    y = synthesize_axis(terms, RATE, 90000, np.random.default_rng(0))
    m = cluster_sizes(len(y), "log:8")
    tau, av, _, _ = oavar(y, RATE, m=m)
    r = fit_avar(tau, av, None, ["white_noise", "sinusoid"], n=len(y), rate_hz=RATE, m=m)
    s = r.term("sinusoid")
    assert s["ci95"]["freq_hz"][0] <= 0.05 <= s["ci95"]["freq_hz"][1]
    assert s["ci95"]["amplitude"][0] <= 2e-3 <= s["ci95"]["amplitude"][1]
    assert s["freq_hz"] == pytest.approx(0.05, rel=0.05)


@pytest.mark.parametrize("seed", [0, 1])
def test_quantization_only_where_its_slope_is(seed):
    """White noise + a 19.7 Hz line at 100 Hz sampling (lifts the 0.02 s octave, as on the ADIS16405 z axes):
    no quantization term stands in for the line (AVAR does not fall like tau^-2 from the smallest cluster
    time; without that rule one did, with the roll-off search of `analyze`); with a real quantization term
    (3 Q^2 / tau^2 dominating the first octaves) it is found. Nor for a line near the Nyquist frequency."""
    rng = np.random.default_rng(seed)
    n, rate = 400_000, 100.0

    def fit(y):
        m = cluster_sizes(len(y))
        tau, av, _, _ = oavar(y, rate, m=m)
        return fit_avar(tau, av, edf_simple(len(y) + 1, m, 0), None, n=len(y), rate_hz=rate, m=m,
                        detect_filter="point")

    line = synthesize_axis([{"effect": "white_noise", "N": 7e-4},
                            {"effect": "sinusoid", "amplitude": 6e-3, "freq_hz": 19.7}], rate, n, rng)
    assert fit(line).term("quantization") is None
    # a line near the Nyquist frequency (an aliased vibration) lifts the smallest cluster time alone: AVAR falls
    # like tau^-1.6 over the first octave and like white noise after it (taken as quantization in 10 of 10
    # seeds before the second octave was asked to fall too)
    nyq = synthesize_axis([{"effect": "white_noise", "N": 7e-4},
                           {"effect": "sinusoid", "amplitude": 5e-3, "freq_hz": 49.0}], rate, 40_000, rng)
    assert fit(nyq).term("quantization") is None
    q = synthesize_axis([{"effect": "white_noise", "N": 7e-4}, {"effect": "quantization", "Q": 1e-3}], rate, n, rng)
    fq = fit(q)
    assert fq.term("quantization") is not None
    assert fq.term("quantization")["Q"] == pytest.approx(1e-3, rel=0.2)


def test_flicker_shape_widens_n_only_where_b_reaches_the_short_taus(monkeypatch):
    """Noise-free AVAR of N + B (1 h at 50 Hz): with white noise meeting the flicker floor at 0.6 s the flicker's
    uncertain shape at the first cluster times widens N's interval by more than half; at 20 s it leaves it
    within 3 %. The estimates do not move."""
    import companion.allan.fit.constants as fit_constants
    from companion.allan.terms import avar_model

    fs, n = 50.0, int(3600 * 50)
    m = cluster_sizes(n, "octave")
    tau = m / fs
    edf = edf_simple(n + 1, m, 0)
    widths = {}
    for t_nb in (0.6, 20.0):
        terms = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 1e-3 / math.sqrt(0.4413 * t_nb)}]
        av = avar_model(terms, tau)
        out = []
        for k in (0.0, 1.0):
            monkeypatch.setattr(fit_constants, "FLICKER_SHAPE_ERROR", k)
            r = fit_avar(tau, av, edf, ["white_noise", "bias_instability"], n=n, rate_hz=fs, m=m)
            lo, hi = r.term("white_noise")["ci95"]["N"]
            out.append((r.term("white_noise")["N"], hi - lo))
        assert out[0][0] == pytest.approx(out[1][0], rel=1e-9)
        widths[t_nb] = out[1][1] / out[0][1]
    assert widths[0.6] > 1.5
    assert 1.0 <= widths[20.0] < 1.03


def test_upper_bound_of_a_left_out_random_walk_holds():
    """A rate random walk that dominates only the last octaves of 2 h (B-K crossing at 430 s, expected evidence
    lambda 2.6): the selection leaves it out, and its 95 % upper bound, with the covariance evaluated at the
    bound, lies above the truth (evaluated at the fitted model, the online report's rule gives 0.56 x the truth on
    this record, benchmarks/bench_fit.py draws)."""
    from companion.allan.fit import upper_bounds

    fs, n = 50.0, int(2 * 3600 * 50)
    truth = {"N": 1.3480080139673396e-3, "B": 5.891713564593853e-4, "K": 3.270930663897592e-05}
    terms = [{"effect": "white_noise", "N": truth["N"]}, {"effect": "bias_instability", "B": truth["B"]},
             {"effect": "random_walk", "K": truth["K"]}]
    y = synthesize_axis(terms, fs, n, np.random.default_rng(10_011))
    m = cluster_sizes(n, "octave")
    tau, av = oavar(y, fs, m=m)[:2]
    r = fit_avar(tau, av, edf_simple(n + 1, m, 0), n=n, rate_hz=fs, m=m)
    assert r.term("random_walk") is None and r.term("bias_instability") is not None
    b = upper_bounds(r, tau, av, n=n, rate_hz=fs, m=m)
    assert [x["effect"] for x in b] == ["random_walk"] and b[0]["bound"]
    assert truth["K"] <= b[0]["K"] < 3.0 * truth["K"]
    assert b[0]["ci95"]["K"] == [0.0, b[0]["K"]]


@pytest.mark.parametrize("seed, truth", [
    # records of the random-draw benchmark (benchmarks/bench_fit.py draws, set 0: draws 63, 86) on which the
    # selection kept a weakly evidenced random walk (expected evidence lambda 2.4, 5.7; B-K crossing at 483,
    # 238 s) whose points lie high: K came out 1.5 and 1.3 x the truth
    (10_063, (8.474959781259103e-4, 4.189049550034397e-4, 2.19367424630356e-05)),
    (10_086, (3.678356398572779e-4, 7.781141175065369e-4, 5.800646312883119e-05)),
])
def test_interval_of_a_random_walk_kept_on_weak_evidence_covers(seed, truth):
    """The interval by test inversion (the points' covariance evaluated at each candidate K) covers the truth;
    the interval at the estimate (the pivot with nu from the estimate's variance there, too large where the
    estimate lies high) lay wholly above it on both records (lower ends 1.04, 1.01 x the truth).
    It stays an interval, not a bound: its lower end is above 0 and within a factor 10 of its upper end."""
    fs, n = 50.0, int(2 * 3600 * 50)
    terms = [{"effect": e, p: x} for (e, p), x in zip((("white_noise", "N"), ("bias_instability", "B"),
                                                        ("random_walk", "K")), truth)]
    y = synthesize_axis(terms, fs, n, np.random.default_rng(seed))
    m = cluster_sizes(n, "octave")
    tau, av = oavar(y, fs, m=m)[:2]
    r = fit_avar(tau, av, edf_simple(n + 1, m, 0), n=n, rate_hz=fs, m=m)
    k = r.term("random_walk")
    assert k is not None and k["K"] > 1.2 * truth[2]
    lo, hi = k["ci95"]["K"]
    assert lo <= truth[2] <= hi
    assert 0.0 < lo and hi < 10.0 * lo


def test_bias_instability_interval_allows_for_a_random_walk_left_out():
    """A random walk too weak to be selected (2 h at 50 Hz, B-K crossing near 320 s; benchmarks/bench_fit.py
    draws, set 0 draw 9) leaves its share in B: B comes out 1.06 x its truth and its interval in the selected
    model, [1.005, 1.131] x, misses it. The interval is the envelope over the model with N, B and K forced in
    (as the online report's): it covers, the estimate is unchanged, and K is still left out (no K invented)."""
    fs, n = 50.0, 2 * 3600 * 50
    truth = {"N": 0.0008277077055812292, "B": 0.0004048146603806761, "K": 2.600867176773318e-05}
    names = {"N": "white_noise", "B": "bias_instability", "K": "random_walk"}
    y = synthesize_axis([{"effect": names[p], p: v} for p, v in truth.items()], fs, n,
                        np.random.default_rng(10_009))
    m = cluster_sizes(n, "octave")
    tau, av = oavar(y, fs, m=m)[:2]
    fr = fit_avar(tau, av, edf_simple(n + 1, m, 0), n=n, rate_hz=fs, m=m)
    assert fr.term("random_walk") is None
    b = fr.term("bias_instability")
    assert b["B"] > truth["B"]
    lo, hi = b["ci95"]["B"]
    assert lo <= truth["B"] <= hi
    assert hi / lo < 1.3  # widened by the envelope, not made useless



_SHORT_NBK = [{"effect": "white_noise", "N": 1.16e-4}, {"effect": "bias_instability", "B": 1.0e-4},
              {"effect": "random_walk", "K": 6e-5}]


def _short_nbk_fit(seed):
    fs, n = 10.0, 600
    m = cluster_sizes(n, "octave")
    y = synthesize_axis(_SHORT_NBK, fs, n, np.random.default_rng(seed))
    tau, av = oavar(y, fs, m=m)[:2]
    return fit_avar(tau, av, edf_simple(n + 1, m, 0), n=n, rate_hz=fs, m=m)


def test_n_interval_allows_for_a_flicker_the_selection_left_out():
    """60 s at 10 Hz (a 10 Hz plane log's still) of white noise, flicker and a random walk that meet within the
    record: the selection keeps N and K in about a third of the records and leaves B out; the flicker's share
    at the short cluster times then goes into N (+3 % on average there). N's interval is the envelope over the
    model with N, B and K forced in, where B comes out at zero in many of them; B still shares the points with
    N, and could only pull it down, so N's lower end comes from the covariance with B's column in. Over 2000
    records (seeds 5000-6999) those selections' intervals covered N in 92.6 % without it, 95.9 % with it (all
    records 94.9 -> 96.4 %). This record (seed 5130): N 1.064 x the truth, [1.005, 1.131] x without,
    [0.990, 1.131] x with it (the upper end as before)."""
    fr = _short_nbk_fit(5130)
    assert [t["effect"] for t in fr.terms] == ["white_noise", "random_walk"]
    w = fr.term("white_noise")
    lo, hi = (x / 1.16e-4 for x in w["ci95"]["N"])
    assert w["N"] / 1.16e-4 > 1.05 and lo <= 1.0 <= hi and hi / lo < 1.2


@pytest.mark.soak
def test_n_interval_coverage_on_short_records_with_every_term():
    """The same records, 300 of them (seeds 5000-5299): N's interval covers the truth in 93-99 % of all (at 95 %
    the binomial sd of 300 records is 1.3 %; measured 97.0 %) and misses in at most 10 of the ~107 where the
    selection left B out (the binomial 97.5 % quantile of 107 at 95 %; measured 4), at a median relative width
    below 0.2 (measured 0.159: widened where needed, not made useless)."""
    truth = 1.16e-4
    nk = [0, 0]
    allc, width = 0, []
    for s in range(5000, 5300):
        fr = _short_nbk_fit(s)
        w = fr.term("white_noise")
        lo, hi = w["ci95"]["N"]
        ok = lo <= truth <= hi
        allc += ok
        width.append((hi - lo) / w["N"])
        if [t["effect"] for t in fr.terms] == ["white_noise", "random_walk"]:
            nk[0] += 1
            nk[1] += ok
    assert 80 <= nk[0] <= 140
    assert nk[0] - nk[1] <= 10, f"N covered in {nk[1]} of {nk[0]} selections without B"
    assert 0.93 <= allc / 300 <= 0.99
    assert np.median(width) < 0.2


def test_a_ramp_does_not_displace_white_noise_from_the_selection():
    """White noise and a warm-up ramp (a public 10 Hz plane log's gyro: N 1.05e-4 rad/s/sqrt(Hz), R 1.9e-5
    rad/s^2 over 103 s). The ramp, tried after the base terms, took the place of the random walk that had stood
    in for it and of white noise with it: the model was the ramp alone (chi^2 526 for 9 dof on the log), and the
    model error added for that misfit (70-75 % on all 20 seeds here) stayed when white noise came back. A base
    term now comes back where it lowers the BIC: no model error, N and R resolved, both intervals covering
    (R's covered 11 of these 20 while the covariance of the longest clusters was summed too coarsely: see
    tests/allan/test_confidence.py)."""
    from companion.allan.adev import oavar

    fs, n, N, R = 10.0, 1033, 1.05e-4, 1.9e-5
    cover = cover_r = 0
    for seed in range(20):
        rng = np.random.default_rng(seed)
        y = rng.normal(0.0, N * np.sqrt(fs), n) + R * np.arange(n) / fs
        tau, av, edf, _ = oavar(y, fs)
        fr = fit_avar(tau, av, edf, None, n=n, rate_hz=fs)
        assert fr.model_error == 0.0, (seed, fr.notes)
        w, r = fr.term("white_noise"), fr.term("ramp")
        assert w is not None and r is not None, (seed, [t["effect"] for t in fr.terms])
        assert abs(w["N"] / N - 1.0) < 0.15 and abs(r["R"] / R - 1.0) < 0.1
        cover += w["ci95"]["N"][0] <= N <= w["ci95"]["N"][1]
        cover_r += r["ci95"]["R"][0] <= R <= r["ci95"]["R"][1]
    assert cover >= 17, cover  # a 95 % interval: 17 of 20 at the binomial 2 % (measured 19)
    assert cover_r >= 17, cover_r  # measured 20 (11 before)
