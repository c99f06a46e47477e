"""Low-pass filtered (and decimated) white noise: its Allan variance, its model covariance, and the fit that
models the filter instead of leaving cluster times out."""

import math

import numpy as np
import pytest
from scipy import integrate

from companion.allan.adev import cluster_sizes, oadev
from companion.allan.confidence import _gcov, edf_simple, oavar_covariance
from companion.allan.fit import fit_avar
from companion.allan.terms import avar_term, avar_white_noise, validate_term
from companion.sim.filtered_noise import filtered_white_noise, logged_white_level


def _avar_by_quadrature(tau, N, fc):
    """2 int_0^inf 2 S(f) |H|^2 sin^4(pi f tau) / (pi f tau)^2 df, S = N^2 two-sided: the textbook transfer
    function form (NIST SP 1065 eq. (65)), independent of the closed form."""
    def f(x):
        return 2.0 * 2.0 * N**2 / (1.0 + (x / fc) ** 4) * math.sin(math.pi * x * tau) ** 4 / (math.pi * x * tau) ** 2

    edges = np.concatenate([[0.0], np.arange(1, 400) / (2.0 * tau)])
    return sum(integrate.quad(f, a, b, limit=200)[0] for a, b in zip(edges[:-1], edges[1:]))


def test_averaged_form_equals_transfer_function_integral():
    for tau in (0.004, 0.012, 0.05, 0.4):
        ref = _avar_by_quadrature(tau, 1.0, 30.0)
        assert avar_white_noise(tau, 1.0, 30.0) == pytest.approx(ref, rel=2e-3)
    # far above the cut-off: plain white noise
    assert avar_white_noise(10.0, 2.0, 30.0) == pytest.approx(4.0 / 10.0, rel=1e-3)


def test_point_sampled_form_against_aliased_sum():
    """Point samples: AVAR(m) = r(0) - ... from the autocovariance r(l tau0) = int S |H|^2 cos(2 pi f l tau0) df
    evaluated numerically; N is the white level of the logged samples (aliasing included)."""
    fs, fc = 50.0, 20.0
    tau0 = 1.0 / fs
    lags = np.arange(0, 200)
    r = np.array([2.0 * integrate.quad(lambda f: 1.0 / (1.0 + (f / fc) ** 4), 0, np.inf, weight="cos",
                                       wvar=2 * math.pi * lag * tau0)[0] if lag else
                  2.0 * integrate.quad(lambda f: 1.0 / (1.0 + (f / fc) ** 4), 0, np.inf)[0] for lag in lags])
    level = tau0 * (r[0] + 2.0 * r[1:].sum())
    assert level == pytest.approx(logged_white_level(1.0, fs, fc) ** 2, rel=1e-4)
    for m in (1, 2, 3, 8):
        # Var(mean of m) - Cov(adjacent means) of a stationary sequence
        k = np.arange(-(m - 1), m)
        w = m - np.abs(k)
        var = np.sum(w * r[np.abs(k)]) / m**2
        cov = np.sum(w * r[np.abs(k + m)]) / m**2
        assert avar_white_noise(m * tau0, 1.0, fc, fs) * level == pytest.approx(var - cov, rel=1e-6)


@pytest.mark.parametrize("sample_hz", [None, 50.0])
def test_generalised_covariance_reproduces_avar(sample_hz):
    term = {"effect": "white_noise", "N": 3e-3, "filter_hz": 20.0, "sample_hz": sample_hz}
    validate_term({k: v for k, v in term.items() if v is not None})
    tau0 = 0.02
    for m in (1, 2, 5, 40):
        g = _gcov(term, np.array([0, m, 2 * m]), tau0)
        lhs = 6 * g[0] - 8 * g[1] + 2 * g[2]
        assert lhs == pytest.approx(2 * (m * tau0) ** 2 * avar_term(term, m * tau0), rel=1e-9)


@pytest.mark.parametrize("fs, fc, sampling", [(50.0, 20.0, "point"), (250.0, 30.0, "average")])
def test_synthesis_matches_the_model(fs, fc, sampling):
    """Mean of the overlapping AVAR over 16 seeds within 4 standard errors of the model at every octave."""
    n = int(fs * 200)
    m = np.array([1, 2, 4, 8, 16])
    est = np.array([oadev(filtered_white_noise(n, 1.0, fs, fc, sampling, s), fs, m=m)[1] ** 2 for s in range(16)])
    level = logged_white_level(1.0, fs, fc, sampling)
    model = avar_white_noise(m / fs, level, fc, fs if sampling == "point" else None)
    sd = np.sqrt(np.diag(oavar_covariance([{"effect": "white_noise", "N": level, "filter_hz": fc,
                                            "sample_hz": fs if sampling == "point" else None}], m, n, fs)))
    assert np.all(np.abs(est.mean(0) - model) < 4 * sd / 4.0)
    # and the model's standard deviation is the spread over seeds (within 40 % at 16 seeds)
    assert np.all(np.abs(est.std(0, ddof=1) / sd - 1) < 0.4)


def _fit(y, fs, **kw):
    n = y.shape[0]
    m = cluster_sizes(n, "octave")
    tau, ad = oadev(y, fs, m=m)[:2]
    return fit_avar(tau, ad**2, edf_simple(n + 1, m, 0), n=n, rate_hz=fs, m=m, **kw)


@pytest.mark.parametrize("fs, fc, sampling", [(50.0, 20.0, "point"), (250.0, 30.0, "average")])
def test_fit_models_the_filter(fs, fc, sampling):
    """N (the logged white level) from the filtered shape: within its 95 % interval in >= 9 of 10 seeds
    (P(< 9 | 95 %) = 8.6 %), the roll-off found in the data (cut-off inside its interval), no other term;
    the log's cut-off gives the same N. Without the filter the plain fit reads N low."""
    level = logged_white_level(1e-3, fs, fc, sampling)
    hits = hits_log = 0
    plain_err = []
    for s in range(10):
        y = filtered_white_noise(int(fs * 300), 1e-3, fs, fc, sampling, 100 + s)
        fr = _fit(y, fs, detect_filter=sampling)
        assert fr.filter is not None and fr.filter["source"] == "data"
        assert [t["effect"] for t in fr.terms] == ["white_noise"]
        lo, hi = fr.term("white_noise")["ci95"]["N"]
        hits += lo <= level <= hi
        fr_log = _fit(y, fs, white_filter={"filter_hz": fc, "sample_hz": fs if sampling == "point" else None},
                      detect_filter=sampling)
        assert fr_log.filter["source"] == "log"
        lo, hi = fr_log.term("white_noise")["ci95"]["N"]
        hits_log += lo <= level <= hi
        plain = _fit(y, fs).term("white_noise")
        plain_err.append(plain["N"] / level - 1)
    assert hits >= 9 and hits_log >= 9
    assert np.median(plain_err) < -0.01  # what the filter model corrects


def test_flat_curve_gives_no_rolloff():
    """White noise (no filter): no roll-off claimed in 10 of 10 seeds, N within its interval."""
    hits = 0
    for s in range(10):
        y = np.random.default_rng(200 + s).standard_normal(15000) * 1e-3 * math.sqrt(50.0)
        fr = _fit(y, 50.0, detect_filter="point")
        assert fr.filter is None
        lo, hi = fr.term("white_noise")["ci95"]["N"]
        hits += lo <= 1e-3 <= hi
    assert hits >= 9


def test_no_white_region_gives_a_bound_that_holds():
    """A heavy filter (1 Hz at 50 Hz) and then a rate random walk that dominates wherever the filter passes the
    white level: N is not resolved; its filter-aware bound is above the truth in >= 9 of 10 seeds and not far
    above it (< 3x)."""
    from companion.allan.white import apply_white_rules
    from companion.sim.synth import synthesize_axis

    fs, fc, n = 50.0, 1.0, 30000
    level = logged_white_level(1e-3, fs, fc)
    m = cluster_sizes(n, "octave")
    edf = edf_simple(n + 1, m, 0)
    held = 0
    for s in range(10):
        y = filtered_white_noise(n, 1e-3, fs, fc, "point", 300 + s)
        y = y + synthesize_axis([{"effect": "random_walk", "K": 2e-3}], fs, n, np.random.default_rng(400 + s))
        tau, av = oadev(y, fs, m=m)[:2]
        av = av**2
        wf = {"filter_hz": fc, "sample_hz": fs}
        fr = fit_avar(tau, av, edf, n=n, rate_hz=fs, m=m, white_filter=wf, detect_filter="point")
        terms, notes = apply_white_rules(fr.terms, tau, av, edf, 1 / fs, fr.model_error, wf)
        wn = next(t for t in terms if t["effect"] == "white_noise")
        assert wn["bound"] and any(x.startswith("N not resolved") for x in notes)
        held += wn["N"] >= level
        assert wn["N"] < 3 * level
    assert held >= 9


def test_white_bound_holds_at_its_level_over_all_points():
    """The bound is the least of the points' one-sided upper bounds: on pure white noise (every point carries N)
    it must still fall below N in at most 5 % of records. Each point at 95 % alone gave 30 % (120 of 400
    records of 3000 samples, 11 octave points, seed 0); Bonferroni over the points 3 %. 200 records: at most
    16 below (binomial 5 %: mean 10, sd 3.1)."""
    from companion.allan.adev import oavar
    from companion.allan.white import white_bound

    fs, n, N = 50.0, 3000, 1e-3
    m = cluster_sizes(n, "octave")
    edf = edf_simple(n + 1, m, 0)
    rng = np.random.default_rng(7)
    below = 0
    for _ in range(200):
        tau, av = oavar(rng.standard_normal(n) * N * math.sqrt(fs), fs, m=m)[:2]
        ub, _ = white_bound(tau, av, edf)
        below += ub < N
        assert ub < 1.5 * N
    assert below <= 16


def test_online_report_models_the_filter_not_a_gauss_markov_term():
    """The octave bank's report on filtered, decimated white noise (the log's cut-off given, and not given):
    N resolved within its interval of the truth in >= 5 of 6 runs, no Gauss-Markov term, online N within 1 %
    of the offline fit of the same samples; with the cut-off found in the data, N's interval is the offline
    one (profiled over the cut-off; ends within 0.1 %, measured 0.01 %: the conditional interval at the fitted
    cut-off alone, as before, was about 0.3 % narrower at each end)."""
    from companion.estimators import online_terms

    fs, fc, n = 50.0, 20.0, 30000
    level = logged_white_level(1e-3, fs, fc)
    hits = 0
    for s in range(3):
        y = filtered_white_noise(n, 1e-3, fs, fc, "point", 500 + s)
        off = _fit(y, fs, white_filter={"filter_hz": fc, "sample_hz": fs}, detect_filter="point").term("white_noise")
        found = _fit(y, fs, detect_filter="point")
        assert found.filter["source"] == "data"
        for given in (fc, None):
            terms = online_terms(y, fs, filter_hz=given, sampling="point")
            assert not any(t["effect"] == "gauss_markov" for t in terms)
            wn = next(t for t in terms if t["effect"] == "white_noise")
            assert not wn["bound"]
            lo, hi = wn["ci95"]["N"]
            hits += lo <= level <= hi
            if given:
                assert wn["N"] == pytest.approx(off["N"], rel=0.01)
            else:
                assert wn["ci95"]["N"] == pytest.approx(found.term("white_noise")["ci95"]["N"], rel=1e-3)
    assert hits >= 5


def test_local_white_refit_is_unbiased():
    """The local white-noise refit (used under model misfit, offline and online) on 300 records of pure white
    noise (66 s at 100 Hz): its mean N is the truth within 0.6 % (3 standard errors). Weights from the
    measured points (1 / AVAR^2) gave -1.4 % (the points that lie low get the most weight), and 5 % low on one
    axis of a lossy-link run with a chance bump at 1-3 s."""
    from companion.allan.adev import oavar
    from companion.allan.white import local_white_noise

    fs, n, N = 100.0, 6600, 3e-3
    m = cluster_sizes(n, "octave")
    edf = edf_simple(n + 1, m, 0)
    r = []
    for s in range(300):
        y = np.random.default_rng(s).normal(0.0, N * math.sqrt(fs), n)
        tau, av = oavar(y, fs, m=m)[:2]
        wn = {"effect": "white_noise", "N": N, "ci95": {"N": [0.9 * N, 1.1 * N]}}
        terms, note = local_white_noise([wn], tau, av, edf, 1.0 / fs)
        r.append(terms[0]["N"] / N - 1.0)
    assert abs(np.mean(r)) < 0.006, np.mean(r)


def test_local_white_refit_interval_is_its_own_where_its_region_is_short():
    """Under misfit N comes from a few long cluster times; its interval must be theirs, not the global fit's
    (which the short-tau points made narrow). 200 records of pure white noise, 60 s at 10 Hz, the global
    interval +-1 %: the local refit's 95 % interval covers the truth in 93-99 % (measured 95.5 %; the refit's
    spread 10 %, its predicted 1-sigma 10 %); the global interval scaled by the ratio covered 8 %."""
    from companion.allan.adev import oavar
    from companion.allan.white import local_white_noise

    fs, n, N = 10.0, 600, 1e-3
    m = cluster_sizes(n, "octave")
    edf = edf_simple(n + 1, m, 0)
    covered = refits = 0
    for s in range(200):
        y = np.random.default_rng(500 + s).normal(0.0, N * math.sqrt(fs), n)
        tau, av = oavar(y, fs, m=m)[:2]
        wn = {"effect": "white_noise", "N": 1.01 * N, "ci95": {"N": [N, 1.02 * N]}}
        terms, note = local_white_noise([wn], tau, av, edf, 1.0 / fs)
        if note is None:
            continue
        refits += 1
        lo, hi = terms[0]["ci95"]["N"]
        covered += lo <= N <= hi
    assert refits >= 190
    assert 0.93 <= covered / refits <= 0.99, (covered, refits)


def test_local_white_refit_stops_at_a_persistent_rise():
    """Under misfit the local white-noise refit holds the other fitted terms fixed; a rise the model does not
    hold (a term the record is too short to resolve, drift) must end its region, not be read as white noise.
    40 records of 60 s at 100 Hz, white noise plus a rate random walk that crosses it at 3 s, the model white
    noise alone: mean N within 2.5 % of the truth (its spread is 3.4 %, so 2.5 % is over 4 standard errors).
    Refitted through the rise (to 20 s) N came out +14 % (the PX4 bench log's gz: +6.9 % against its
    plateau)."""
    from companion.allan.adev import oavar
    from companion.allan.white import local_white_noise
    from companion.sim.synth import synthesize_axis

    fs, n, N = 100.0, 6000, 3e-3
    K = math.sqrt(3.0) * N / 3.0  # K^2 tau / 3 = N^2 / tau at tau = 3 s
    m = cluster_sizes(n, "octave")
    edf = edf_simple(n + 1, m, 0)
    r = []
    for s in range(40):
        y = synthesize_axis([{"effect": "white_noise", "N": N}, {"effect": "random_walk", "K": K}], fs, n,
                            np.random.default_rng(s))
        tau, av = oavar(y, fs, m=m)[:2]
        wn = {"effect": "white_noise", "N": 0.8 * N, "ci95": {"N": [0.7 * N, 0.9 * N]}}
        terms, note = local_white_noise([wn], tau, av, edf, 1.0 / fs)
        assert note is not None
        r.append(terms[0]["N"] / N - 1.0)
    assert abs(np.mean(r)) < 0.025, np.mean(r)


def test_a_log_cut_off_the_data_contradict_is_set_aside():
    """The log says 5 Hz, the filter is a 2-pole 6.5 Hz (a nominal DLPF setting need not be its 2-pole
    equivalent); 20 s at 50 Hz. Where the data put the log's value outside their 99 % profile interval the fit
    models the cut-off it finds (and says so); N's 95 % interval covers the logged white level in >= 13 of 20
    seeds (measured 15, N -0.6 % in the median; with the log's value kept unless chi^2 drops by ln(points) + 10:
    8 of 20, N +13 %). A right log value stands: set aside in 0 of 20 seeds (1 % expected per seed)."""
    fs, n = 50.0, 1000
    level = logged_white_level(1e-3, fs, 6.5)
    covered = aside = 0
    for s in range(20):
        y = filtered_white_noise(n, 1e-3, fs, 6.5, "point", 700 + s)
        fr = _fit(y, fs, white_filter={"filter_hz": 5.0, "sample_hz": fs}, detect_filter="point")
        wn = fr.term("white_noise")
        covered += wn["ci95"]["N"][0] <= level <= wn["ci95"]["N"][1]
        if fr.filter["source"] == "data":
            assert any("the log's 5 Hz set aside" in x for x in fr.notes)
        right = _fit(filtered_white_noise(n, 1e-3, fs, 5.0, "point", 800 + s), fs,
                     white_filter={"filter_hz": 5.0, "sample_hz": fs}, detect_filter="point")
        aside += right.filter["source"] == "data"
    assert covered >= 13
    assert aside <= 1


def test_a_first_order_roll_off_the_log_s_2_pole_cannot_fit():
    """What a 20-s still of a 2014 MPU-6000 rover log showed on one axis: a roll-off near 2 Hz of first-order
    shape (white noise through a 2-pole 8.4 Hz filter plus a Gauss-Markov process of tau_c 73 ms, 50 Hz), the
    log saying 5 Hz. With the log's 2-pole shape an unresolved bias instability took up the difference and N
    came out at half the long-tau white level, its interval covering it in 0 of 20 seeds; judged under the
    covariance of its own model the first-order shape sets the log's aside, and N's 95 % interval covers the
    long-tau white level (the plateau of ADEV sqrt(tau) above the roll-off) in 18 of 20; the note says a
    Gauss-Markov process has that shape. In the other 2 the log's 2-pole stays (the 1-pole fits better, not by
    the 99 % margin): N's interval spans the first-order reading too, and says so: 20 of 20 (asserted >= 9 of
    10; 8 of 10 without that). A first-order shape is also exactly that process: its AVAR is the Gauss-Markov
    term's."""
    from companion.sim.synth import synthesize_axis

    fs, n, sigma, tau_c = 50.0, 1000, 7.4e-3, 0.073
    phi = math.exp(-1.0 / (fs * tau_c))
    level = math.sqrt(logged_white_level(4e-4, fs, 8.4) ** 2 + sigma**2 / fs * (1 + phi) / (1 - phi))
    covered = 0
    for s in range(10):
        y = filtered_white_noise(n, 4e-4, fs, 8.4, "point", 500 + s) + synthesize_axis(
            [{"effect": "gauss_markov", "sigma": sigma, "tau_c": tau_c}], fs, n, np.random.default_rng(900 + s))
        fr = _fit(y, fs, white_filter={"filter_hz": 5.0, "sample_hz": fs}, detect_filter="point")
        wn = fr.term("white_noise")
        covered += wn["ci95"]["N"][0] <= level <= wn["ci95"]["N"][1]
        if fr.filter.get("filter_order") == 1:
            assert any("Gauss-Markov process of tau_c" in x for x in fr.notes)
        elif wn["ci95"]["N"][0] <= level <= wn["ci95"]["N"][1]:
            assert any(x.startswith("N's interval spans a first-order") for x in fr.notes)
    assert covered >= 9
    tau = np.array([0.02, 0.1, 0.5, 2.0])
    gm = avar_term({"effect": "gauss_markov", "sigma": 1.0, "tau_c": tau_c}, tau)
    one = avar_term({"effect": "white_noise", "N": 1.0, "filter_hz": 1.0 / (2 * math.pi * tau_c), "filter_order": 1},
                    tau)
    np.testing.assert_allclose(one / one[-1], gm / gm[-1], rtol=1e-9)


@pytest.mark.soak
def test_a_first_order_roll_off_without_a_log_is_not_left_to_a_2_pole_and_a_drift_term():
    """The same process with no cut-off from a log (a tlog, a CSV): the data set "no filter" aside for a 2-pole
    of their own, whose model keeps an unresolved bias instability for the difference, and the first-order
    shape, judged against that model with the drift term in both, was left out: the first-order shape found in
    6 of 20 records of 20 s, N about half the long-tau level in the other 12 with a roll-off, and N's interval
    covered that level in 6 of the 18 (`bench_fit.py shape 40 20 none`: 12 of 40). Judged again under its own
    model (its own selection and covariance), as where it beats no filter, the first-order shape is taken in 13
    of these 20 (asserted >= 9; 21 of 40 in the benchmark); and where a 2-pole stays, the two orders are within
    the 99 % margin of each other, so N's interval is its profile interval over the roll-off's order as well as
    its cut-off and spans both readings: it covers the level in 18 of the 18 with a roll-off (asserted all but
    three; the other 2 read the curve as white noise + a Gauss-Markov term, N the white part)."""
    from companion.sim.synth import synthesize_axis

    fs, n, sigma, tau_c = 50.0, 1000, 7.4e-3, 0.073
    phi = math.exp(-1.0 / (fs * tau_c))
    level = math.sqrt(logged_white_level(4e-4, fs, 8.4) ** 2 + sigma**2 / fs * (1 + phi) / (1 - phi))
    first = rolled = covered = spans = 0
    for s in range(20):
        y = filtered_white_noise(n, 4e-4, fs, 8.4, "point", 500 + s) + synthesize_axis(
            [{"effect": "gauss_markov", "sigma": sigma, "tau_c": tau_c}], fs, n, np.random.default_rng(900 + s))
        fr = _fit(y, fs, detect_filter="point")
        if (fr.filter or {}).get("source") != "data":
            continue
        rolled += 1
        first += fr.filter.get("filter_order") == 1
        lo, hi = fr.term("white_noise")["ci95"]["N"]
        covered += lo <= level <= hi
        spans += any(x.startswith("N's interval spans a first-order") for x in fr.notes)
    assert first >= 9
    assert rolled >= 15 and covered >= rolled - 3
    assert 1 <= spans <= rolled - first  # said where a 2-pole stays and the interval spans the 1-pole's reading


@pytest.mark.soak
def test_n_whose_interval_reaches_zero_is_a_bound_that_holds():
    """Quantization above white noise up to 5 s and a random walk above it from 1.7 s (90 s at 10 Hz, as the
    public plane still whose gx read N 1.43 [0, 2.61] deg/sqrt(h)): white noise dominates nowhere, and a fitted N
    whose interval reaches 0 is no resolved value. It is reported as its bound with the reason; a resolved N
    keeps a lower end above 0. 40 records: the bound above the truth in all but at most 3 (one-sided 95 %:
    at most 3 misses of ~25 bounds with probability 0.96); 100 records measured: 62 bounds, 61 above the truth,
    where before 35 of 94 resolved values reached 0."""
    from companion.analysis.axis import analyze_axis
    from companion.sim.synth import synthesize_axis

    fs, n, truth = 10.0, 900, 3e-4
    terms = [{"effect": "quantization", "Q": 4e-4}, {"effect": "white_noise", "N": truth},
             {"effect": "random_walk", "K": 3e-4}]
    bounds = held = zero = 0
    for s in range(40):
        a = analyze_axis(synthesize_axis(terms, fs, n, np.random.default_rng(700 + s)), fs)
        wn = next((t for t in a["terms"] if t["effect"] == "white_noise"), None)
        if wn is not None:
            assert wn["ci95"]["N"][0] > 0
            continue
        b = next(t for t in a["bounds"] if t["effect"] == "white_noise")
        bounds += 1
        held += b["N"] >= truth
        zero += any(x.startswith("N not resolved: its 95 % interval reaches 0") for x in a["fit"]["notes"])
    assert bounds >= 15 and bounds - held <= 3, (bounds, held)
    assert zero >= 5, zero  # the new reason, not only the older ones
