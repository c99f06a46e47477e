"""The online report (companion.estimators.online_report): the model chosen from the data, resolved values and
95 % upper bounds, against simulated truth over several seeds (calibration over 100 seeds is measured by
benchmarks/bench_online.py coverage)."""

from __future__ import annotations

import numpy as np
import pytest

from companion.estimators import from_state_dict, make_estimator, online_terms
from companion.mavlink.reporter import NAME_RE, Reporter
from companion.sim.synth import synthesize_axis
from tests.support.stats import coverage_floor

FS = 50.0


def by_effect(terms):
    return {t["effect"]: t for t in terms}


def covers(t, p, truth):
    lo, hi = t["ci95"][p]
    return lo <= truth <= hi


SEEDS = range(20)  #: realisations per coverage count (0.3 s of CPU each); the floor from tests.support.stats


def test_absent_terms_are_bounds_present_terms_resolved():
    """Per seed: N and B resolved, the absent effects 95 % upper bounds. Over the seeds: the N and B intervals
    hold the truth as often as 95 % intervals do (a binomial count, false failure <= 1e-3 each)."""
    truth = [{"effect": "white_noise", "N": 3.0e-4}, {"effect": "bias_instability", "B": 1.5e-4}]
    held = {"N": 0, "B": 0}
    for seed in SEEDS:
        y = synthesize_axis(truth, FS, int(3600 * FS), np.random.default_rng(seed))
        on = by_effect(online_terms(y, FS))
        assert not on["white_noise"]["bound"] and not on["bias_instability"]["bound"], seed
        held["N"] += covers(on["white_noise"], "N", 3.0e-4)
        held["B"] += covers(on["bias_instability"], "B", 1.5e-4)
        for e, p in (("random_walk", "K"), ("quantization", "Q"), ("ramp", "R")):
            assert on[e]["bound"] and on[e]["ci95"][p] == [0.0, on[e][p]] and on[e][p] > 0, (seed, e)
        assert "gauss_markov" not in on and "sinusoid" not in on, seed
    assert min(held.values()) >= coverage_floor(len(SEEDS)), held


def test_gauss_markov_is_in_the_model_and_n_is_not_inflated():
    """Per seed: the Gauss-Markov term in the model, N within 2 % of the truth, no random walk. Over the
    seeds: the N, sigma and tau_c intervals hold the truth as 95 % intervals do (binomial counts)."""
    truth = [{"effect": "white_noise", "N": 3.0e-4}, {"effect": "gauss_markov", "sigma": 6.0e-4, "tau_c": 20.0}]
    held = {"N": 0, "sigma": 0, "tau_c": 0}
    for seed in SEEDS:
        y = synthesize_axis(truth, FS, int(3600 * FS), np.random.default_rng(10 + seed))
        on = by_effect(online_terms(y, FS))
        assert abs(on["white_noise"]["N"] / 3.0e-4 - 1) < 0.02, seed
        gm = on["gauss_markov"]
        held["N"] += covers(on["white_noise"], "N", 3.0e-4)
        held["sigma"] += covers(gm, "sigma", 6.0e-4)
        held["tau_c"] += covers(gm, "tau_c", 20.0)
        assert on["random_walk"]["bound"], seed
    assert min(held.values()) >= coverage_floor(len(SEEDS)), held


def test_quick_refit_between_selections_and_state_round_trip():
    truth = [{"effect": "white_noise", "N": 3.0e-4}, {"effect": "random_walk", "K": 6.0e-5}]
    y = synthesize_axis(truth, FS, int(3600 * FS), np.random.default_rng(5))
    est = make_estimator("octave", rate_hz=FS)
    est.update(y[: y.size // 2])
    est.terms()  # selects the model
    est.update(y[y.size // 2: y.size // 2 + y.size // 10])  # +20 %: no re-selection (x1.5 due), quick refit
    quick = by_effect(est.terms())
    full = by_effect(from_state_dict(est.state_dict()).terms())  # a restored estimator selects afresh
    for p, e in (("N", "white_noise"), ("K", "random_walk")):
        assert quick[e]["bound"] is full[e]["bound"] is False
        assert abs(quick[e][p] / full[e][p] - 1) < 0.05
        assert 0.5 < quick[e]["std"][p] / full[e]["std"][p] < 2.0


def test_a_report_asked_again_before_new_samples_is_the_same_and_new_samples_renew_it():
    truth = [{"effect": "white_noise", "N": 3.0e-4}, {"effect": "bias_instability", "B": 2.0e-5}]
    y = synthesize_axis(truth, FS, int(900 * FS), np.random.default_rng(8))
    est = make_estimator("octave", rate_hz=FS)
    est.update(y[: y.size // 2])
    first = est.terms()
    by_effect(first)["white_noise"]["N"] = -1.0  # what a caller does with its copy does not reach the next report
    again = est.terms()
    fresh = from_state_dict(est.state_dict())  # the same samples, no cached report
    assert again == fresh.terms() and by_effect(again)["white_noise"]["N"] > 0
    est.update(y[y.size // 2: y.size // 2 + y.size // 10])
    fresh.update(y[y.size // 2: y.size // 2 + y.size // 10])
    later = est.terms()
    assert later != again  # the new samples are in it, exactly as in an estimator that made no report twice
    assert later == fresh.terms()
    est.new_segment()  # a junction with no new sample changes nothing; the next samples then count as a piece
    assert est.terms() == later

class Sink:
    def __init__(self):
        self.sent = {}

    def send_named_value_float(self, ms, name, value):
        self.sent[name] = value

    def send_statustext(self, sev, text, time_boot_ms=None):
        pass


def test_named_value_float_sigmas_and_bounds():
    rep = Reporter(Sink(), 1.0)
    terms = [{"effect": "white_noise", "N": 2.909e-4, "std": {"N": 2.909e-6}, "ci95": {"N": [2.85e-4, 2.97e-4]},
              "bound": False},
             {"effect": "random_walk", "K": 8.08e-6, "std": {"K": 1e-6}, "ci95": {"K": [0.0, 8.08e-6]}, "bound": True},
             {"effect": "gauss_markov", "sigma": 4.848e-4, "tau_c": 20.0, "std": {"sigma": 4.848e-5},
              "ci95": {"sigma": [4e-4, 6e-4], "tau_c": [15.0, 26.0]}, "bound": False}]
    rep.set_online_terms(0, "gx", terms)
    v = rep.values
    assert all(NAME_RE.match(n) for n in v)
    assert v["IMU0GX_N"] == pytest.approx(1.0, rel=1e-3) and v["IMU0GX_NS"] == pytest.approx(0.01, rel=1e-3)
    assert v["IMU0GX_K"] == pytest.approx(100.0, rel=1e-3) and v["IMU0GX_KS"] == -1.0  # a bound
    assert v["IMU0GX_GM"] == pytest.approx(100.0, rel=1e-3) and v["IMU0GX_GMS"] == pytest.approx(10.0, rel=1e-3)
    assert v["IMU0GX_GMT"] == 20.0
    rep.set_online_terms(0, "gx", terms[:2])  # the Gauss-Markov term is no longer resolved: its names stop
    assert not any(n.startswith("IMU0GX_GM") for n in rep.values)
    assert rep.tick(0.0) == 1 and rep.tick(1.0) >= 1


def test_a_term_too_short_to_resolve_stays_in_the_model_and_n_keeps_the_truth():
    """The fast estimator of a copter at 50 Hz (600 s forgetting: about 20 min of record) sees white noise
    through the 20 Hz low-pass, a bias instability making 20-45 % of the AVAR from 1 s to 330 s, and a
    Gauss-Markov bias (tau_c ~20 s). The record rule makes B a bound (it would need hours); refitted without
    B, its share went into N (N 1.087x the truth on these levels, model error 33 %; in the simulated copter
    hours N 1.4x and 1.6x the baseline with +-0.5 % between selections, and false `degrading: N` alarms).
    The levels here are the expected Allan variances of that stream (the truth's model at the octave
    cluster times), the EDF of its 1200 s effective record; then the curve's long-tau part changes (the
    Gauss-Markov hump moves) while N does not, and the report between selections must keep N too."""
    from companion.allan.confidence import edf_simple
    from companion.allan.terms import avar_model
    from companion.estimators.online_report import report, rescaled_cov, select

    n_true, b_true = 7.6e-5, 1.0e-4
    white = {"effect": "white_noise", "N": n_true, "filter_hz": 21.6, "sample_hz": FS}
    truth = [white, {"effect": "bias_instability", "B": b_true},
             {"effect": "gauss_markov", "sigma": 2.1e-4, "tau_c": 19.0}]
    tau = 0.02 * 2.0 ** np.arange(15)
    m = np.round(tau * FS).astype(int)
    n = 60000
    avar = avar_model(truth, tau)
    _, st = select(tau, avar, edf_simple(n + 1, m, 0), n, FS, n_raw=n, detect_filter="point")
    keep = np.isin(m, st.m)
    on = by_effect(report(tau[keep], avar[keep], st))
    assert not on["white_noise"]["bound"] and covers(on["white_noise"], "N", n_true)
    assert abs(on["white_noise"]["N"] / n_true - 1) < 0.03
    assert on["bias_instability"]["bound"] and on["bias_instability"]["B"] >= b_true
    later = avar_model([white, truth[1], {"effect": "gauss_markov", "sigma": 3.0e-4, "tau_c": 40.0}], tau)[keep]
    on2 = by_effect(report(tau[keep], later, st, cov=rescaled_cov(st, tau[keep], later, n)))
    assert not on2["white_noise"]["bound"] and covers(on2["white_noise"], "N", n_true)
    assert abs(on2["white_noise"]["N"] / n_true - 1) < 0.03



@pytest.mark.soak  # kept out of the README's command for its time (python -m benchmarks.soak_checks)
def test_online_bound_of_a_left_out_random_walk_holds():
    """A rate random walk too weak for the selection in 2 h at 50 Hz (the truth of
    tests/cli/test_analyze.py::test_bound_of_a_left_out_random_walk_holds): where the selection leaves K out,
    the online report's K bound is at least the offline analysis' bound by test inversion and lies above the
    truth. Seeds 0-11, every draw that leaves K out (8 of the 12); the report's own rule (the covariance at
    the fitted model, where K is 0) bounded it below the truth in two of them (0.72 x and 0.90 x), the
    inverted bound in none (1.03-1.64 x)."""
    n = int(2 * 3600 * FS)
    truth = {"N": 1.3480080139673396e-3, "B": 5.891713564593853e-4, "K": 3.270930663897592e-05}
    terms = [{"effect": "white_noise", "N": truth["N"]}, {"effect": "bias_instability", "B": truth["B"]},
             {"effect": "random_walk", "K": truth["K"]}]
    left_out = []
    for seed in range(12):
        on = by_effect(online_terms(synthesize_axis(terms, FS, n, np.random.default_rng(seed)), FS))
        assert not on["white_noise"]["bound"] and not on["bias_instability"]["bound"], seed
        k = on["random_walk"]
        if not k["bound"]:
            continue
        left_out.append(seed)
        assert k["ci95"]["K"] == [0.0, k["K"]]
        assert truth["K"] <= k["K"] < 3.0 * truth["K"], (seed, k["K"] / truth["K"])
    assert len(left_out) >= 4, left_out  # the case arises: K weak enough to be left out


def test_a_selected_term_whose_interval_reaches_zero_is_a_bound_online_and_offline():
    # weak bias instability (crossing N at 2-60 s) on 26-60 min at 10 Hz: in some records the selection keeps
    # B while its interval with N, B and K in the model reaches 0. Such a B was reported resolved ("B 40 +- 18
    # deg/h" on the shared ArduSub tlog) where the data do not tell it from 0: now its bound, as the offline
    # table gives it, and the bound holds the truth
    from companion.analysis.axis import analyze_axis
    from companion.estimators.online_report import estimator_report
    from companion.sim.synth import flicker, random_walk, white_noise

    rate, flagged = 10.0, 0
    for seed in (1, 19, 39, 48):
        rng = np.random.default_rng(seed)
        n = int(rng.uniform(300, 3600) * rate)
        b_true = 3e-4 / np.sqrt(rng.uniform(2, 60))
        k_true = b_true / rng.uniform(50, 400) if rng.random() < 0.5 else 0.0
        y = white_noise(3e-4, rate, n, rng) + flicker(b_true, rate, n, rng)
        if k_true:
            y = y + random_walk(k_true, rate, n, rng)
        est = make_estimator(rate_hz=rate, forgetting_s=None)
        est.update(y)
        off = analyze_axis(y, rate)
        for terms in (estimator_report(est, full=True), off["terms"] + off["bounds"]):
            for t in terms:
                p = {"bias_instability": "B", "random_walk": "K", "white_noise": "N"}.get(t["effect"])
                if p and not t.get("bound"):
                    assert t["ci95"][p][0] > 0, t
            b = by_effect(terms)["bias_instability"]
            if b.get("selected"):
                flagged += 1
                assert b["bound"] and b["B"] >= b_true, b
    assert flagged >= 3
