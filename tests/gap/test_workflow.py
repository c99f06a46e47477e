"""Gap workflow on simulated measurements with a hidden effect the input model lacks (independent truth:
the simulator's parameters). Each hidden effect is sized so that its ADEV is at least ~3x the rest of the
model somewhere in the measured tau range; the workflow must name it, recover its parameters within 30 %,
and end at the noise floor. Seeds fixed; ~1 s per case."""

import math

import numpy as np
import pytest

# Each case runs one seed in the README's command; its further seeds are soak checks (python -m
# benchmarks.soak_checks), which run them all.

from companion.allan.terms import adev_model
from companion.gap import run_gap
from companion.gap.workflow import NOISE_FLOOR_G
from companion.sim.synth import synthesize_axis
from tests.support.stats import coverage_floor

RATE = 20.0
N_2H = int(2 * 3600 * RATE)
WB = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 1e-4}]

HIDDEN = [
    # (base model, hidden term)
    (WB, {"effect": "quantization", "Q": 6e-4}),
    ([{"effect": "quantization", "Q": 1e-4}, {"effect": "bias_instability", "B": 1e-4},
      {"effect": "random_walk", "K": 5e-6}], {"effect": "white_noise", "N": 1e-3}),
    ([{"effect": "white_noise", "N": 1e-3}, {"effect": "random_walk", "K": 1e-6}],
     {"effect": "bias_instability", "B": 2e-4}),
    (WB, {"effect": "random_walk", "K": 3e-5}),
    (WB, {"effect": "ramp", "R": 4e-7}),
    (WB, {"effect": "gauss_markov", "sigma": 8e-4, "tau_c": 30.0}),
    (WB, {"effect": "sinusoid", "amplitude": 2e-3, "freq_hz": 0.05}),
]


def _measure(terms, seed, n=N_2H):
    return synthesize_axis(terms, RATE, n, np.random.default_rng(seed))


def _visible(base, hidden):
    tau = np.logspace(math.log10(1 / RATE), math.log10(N_2H / RATE / 2), 200)
    return float(np.max(adev_model([hidden], tau) / adev_model(base, tau)))


@pytest.mark.parametrize("base,hidden", HIDDEN, ids=[h["effect"] for _, h in HIDDEN])
@pytest.mark.parametrize("seed", [11, pytest.param(12, marks=pytest.mark.soak)])
def test_names_the_hidden_effect(base, hidden, seed):
    assert _visible(base, hidden) >= 3.0  # the case is one where the effect is visible
    y = _measure(base + [hidden], seed)
    r = run_gap(y, RATE, base, seed=seed)
    names = [a["effect"] for a in r.added]
    assert names == [hidden["effect"]], (names, r.iterations[0]["candidates"][:3])
    got = r.added[0]
    for p, v in hidden.items():
        if p != "effect":
            assert got[p] == pytest.approx(v, rel=0.30), (p, got[p], v)
    assert r.gap_before > NOISE_FLOOR_G
    assert r.gap_after <= NOISE_FLOOR_G
    assert r.gap_sim_after is not None and r.gap_sim_after < r.gap_sim_before
    assert not [e for e in r.recalibrated if e["verdict"] != "consistent"]  # base model was exact
    assert "commonly" in got["explanation"].lower()
    if hidden["effect"] == "sinusoid":  # a real line: the periodogram check confirms it
        assert got["spectral"]["confirmed"] and "confirmed" in got["explanation"]


@pytest.mark.parametrize("seed", [21, pytest.param(22, marks=pytest.mark.soak), pytest.param(23, marks=pytest.mark.soak)])
def test_null_case_adds_nothing(seed):
    base = WB + [{"effect": "random_walk", "K": 5e-6}]
    r = run_gap(_measure(base, seed), RATE, base, seed=seed)
    assert r.added == []
    assert r.fits_within_noise
    assert r.terms_after == base
    assert r.gap_before <= NOISE_FLOOR_G
    assert r.sim_check_before is not None and r.sim_check_before <= NOISE_FLOOR_G  # simulator == analytic


@pytest.mark.parametrize("seed", [31, pytest.param(32, marks=pytest.mark.soak)])
def test_two_hidden_effects(seed):
    hidden = [{"effect": "gauss_markov", "sigma": 8e-4, "tau_c": 30.0}, {"effect": "quantization", "Q": 6e-4}]
    y = _measure(WB + hidden, seed)
    r = run_gap(y, RATE, WB, seed=seed)
    got = {a["effect"]: a for a in r.added}
    assert set(got) == {"gauss_markov", "quantization"}
    assert got["quantization"]["Q"] == pytest.approx(6e-4, rel=0.3)
    assert got["gauss_markov"]["sigma"] == pytest.approx(8e-4, rel=0.3)
    assert got["gauss_markov"]["tau_c"] == pytest.approx(30.0, rel=0.3)
    assert len(r.iterations) >= 2
    assert r.gap_after <= NOISE_FLOOR_G


@pytest.mark.parametrize("seed,factors", [(41, (0.7, 1.4)), (42, (1.4, 0.7)), (43, (0.75, 1.0))])
def test_missized_terms_are_recalibrated_not_added(seed, factors):
    truth = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 2e-4}]
    hidden = {"effect": "sinusoid", "amplitude": 2e-3, "freq_hz": 0.05}
    model = [{"effect": "white_noise", "N": 1e-3 * factors[0]}, {"effect": "bias_instability", "B": 2e-4 * factors[1]}]
    r = run_gap(_measure(truth + [hidden], seed), RATE, model, seed=seed)
    assert [a["effect"] for a in r.added] == ["sinusoid"]
    assert r.added[0]["amplitude"] == pytest.approx(2e-3, rel=0.3)
    assert r.added[0]["freq_hz"] == pytest.approx(0.05, rel=0.3)
    for entry, f, t in zip(r.recalibrated, factors, truth):
        p = entry["param"]
        if f == 1.0:
            assert entry["verdict"] == "consistent"
            continue
        assert entry["verdict"] == ("too small" if f < 1 else "too large")
        assert entry["ratio"] == pytest.approx(1.0 / f, rel=0.2)
        assert r.terms_after[r.recalibrated.index(entry)][p] == pytest.approx(t[p], rel=0.2)
        assert ("too small" if f < 1 else "too large") in entry["text"]
    assert r.gap_after <= NOISE_FLOOR_G


def test_missized_only_no_effect_missing():
    truth = WB
    model = [{"effect": "white_noise", "N": 0.55e-3}, {"effect": "bias_instability", "B": 1e-4}]
    r = run_gap(_measure(truth, 51), RATE, model, seed=51)
    assert r.added == []
    assert not r.fits_within_noise
    assert r.recalibrated[0]["verdict"] == "too small"
    assert "1.8" in r.recalibrated[0]["text"]
    assert r.gap_after <= NOISE_FLOOR_G < r.gap_before



def test_low_flicker_draw_keeps_b():
    """Seed 1000 draws a flicker floor 0.48x the simulated B (raw LR 15.8 > 10.8): the long-tau estimates are
    few and correlated, and the sandwich-corrected LR must keep B (bench_gap: this draw failed 5 cases)."""
    r = run_gap(_measure(WB, 1000), RATE, WB, seed=0, simulate=False)
    assert r.added == []
    b = r.recalibrated[1]
    assert b["lr_raw"] > 10.8 and b["inflation"] > 1.5
    assert [e["verdict"] for e in r.recalibrated] == ["consistent", "consistent"]


@pytest.mark.soak  # kept out of the README's command for its time (python -m benchmarks.soak_checks)
def test_b_far_off_still_called_missized():
    """The correction must not blind the test: a model B 5x too small is still named (truth: simulator), with
    the fitted B within 0.7-1.4x the truth, in most draws: 12 consecutive seeds, the detection's power at
    least 0.75 (a binomial count, false failure <= 1e-3; measured 13-14 of 16 over seeds 50-65: a draw
    whose flicker floor reads 0.69x the truth, seed 52, is called consistent; see docs/gap.md)."""
    model = [{"effect": "white_noise", "N": 1e-3}, {"effect": "bias_instability", "B": 1e-4 / 5}]
    named = []
    for seed in range(50, 62):
        r = run_gap(_measure(WB, seed), RATE, model, seed=seed, simulate=False)
        b = r.recalibrated[1]
        named.append(r.added == [] and b["verdict"] == "too small" and 0.7e-4 <= b["fitted"] <= 1.4e-4)
    assert sum(named) >= coverage_floor(len(named), 0.75), named

# --- ArduPilot-style rate rounding (RAW_IMU int16 mrad/s) -------------------------------------------
LSB = 1e-3
AP_RATE = 50.0


def _rounded(N, seed, n=int(3600 * AP_RATE)):
    terms = [{"effect": "white_noise", "N": N}, {"effect": "bias_instability", "B": 5e-5}]
    y = synthesize_axis(terms, AP_RATE, n, np.random.default_rng(seed))
    return terms, np.round(y / LSB) * LSB


@pytest.mark.parametrize("seed", [61, pytest.param(62, marks=pytest.mark.soak)])
def test_rate_quantization_named_when_lsb_known(seed):
    # per-sample noise N sqrt(fs) = 0.64 LSB: dithered, N_q^2 / N^2 = 1/12 / 0.41 = 20 %
    terms, y = _rounded(9e-5, seed)
    r = run_gap(y, AP_RATE, terms, lsb=LSB, seed=seed)
    assert r.quantization["dithered"]
    assert [a["effect"] for a in r.added] == ["quantization"]
    assert r.added[0]["form"] == "rate_lsb"
    assert r.added[0]["N"] == pytest.approx(LSB * math.sqrt(1 / (12 * AP_RATE)), rel=1e-9)
    assert [e["verdict"] for e in r.recalibrated] == ["consistent", "consistent"]  # sensor N not blamed
    assert r.gap_after <= NOISE_FLOOR_G < r.gap_before


def test_rate_quantization_without_lsb_is_a_missized_white_noise():
    # same data, LSB neither given nor detectable (values offset by a random bias): honest answer is N
    terms, y = _rounded(9e-5, 61)
    r = run_gap(y, AP_RATE, terms, lsb=None, seed=61)  # values on a grid: the LSB is detected
    assert r.quantization is not None and r.quantization["lsb"] == pytest.approx(LSB, rel=1e-6)
    r2 = run_gap(y + 1e-7 * np.random.default_rng(1).standard_normal(y.shape), AP_RATE, terms, lsb=None, seed=61)
    assert r2.quantization is None
    assert r2.added == []
    assert r2.recalibrated[0]["verdict"] == "too small"
    expected = math.sqrt(9e-5**2 + LSB**2 / (12 * AP_RATE)) / 9e-5
    assert r2.recalibrated[0]["ratio"] == pytest.approx(expected, rel=0.05)


def test_undithered_rounding_is_flagged():
    terms, y = _rounded(2e-5, 63, n=int(600 * AP_RATE))  # 0.14 LSB per sample
    r = run_gap(y, AP_RATE, terms, lsb=LSB, seed=63)
    assert not r.quantization["dithered"]
    assert any("not dithered" in n for n in r.notes)
    assert not any(a["effect"] == "quantization" for a in r.added)


@pytest.mark.shared
def test_adis16405_against_datasheet(shared_data):
    """Real recording vs datasheet model: the gap shrinks to the noise floor, the datasheet ARW is found
    optimistic, and the rising long-tau end is named a rate random walk (see docs/gap.md). The white level
    is judged as the data see it at tau >> 0.03 s: N^2 plus the white-equivalent 2 sigma^2 tau_c of a
    filter-like Gauss-Markov term (tau_c < 1 s) when one is named; how the Allan curve splits the two at
    the shortest cluster times is not identifiable (both fits are within the noise)."""
    import gzip

    with gzip.open(shared_data / "adis16405" / "adis16405_imu1.csv.gz", "rt") as fh:
        y = np.loadtxt(fh, delimiter=",", skiprows=1, usecols=2)  # gy
    model = [{"effect": "white_noise", "N": 5.82e-4}, {"effect": "bias_instability", "B": 1.22e-4}]
    r = run_gap(y, 100.0, model, axis="gy", simulate=False)
    assert r.gap_before > 10 * NOISE_FLOOR_G and r.gap_after <= NOISE_FLOOR_G
    assert "random_walk" in [a["effect"] for a in r.added]
    n_eff2 = sum(t["N"] ** 2 for t in r.terms_after if t["effect"] == "white_noise")
    n_eff2 += sum(2 * t["sigma"] ** 2 * t["tau_c"] for t in r.terms_after
                  if t["effect"] == "gauss_markov" and t["tau_c"] < 1.0)
    assert 1.03 < math.sqrt(n_eff2) / 5.82e-4 < 1.35


@pytest.mark.parametrize("seed", [7000, pytest.param(7009, marks=pytest.mark.soak)])
def test_strong_random_walk_is_not_named_gauss_markov(seed):
    """K = 1e-3 over white + flicker: the raw likelihood ratio of a Gauss-Markov fit over the random walk is
    17-20 for these two draws (above the old uncorrected threshold 15.1; 48 random-walk draws give up to
    20); corrected for the correlated long-tau estimates it is below 10.8, so the random walk is named."""
    hidden = {"effect": "random_walk", "K": 1e-3}
    r = run_gap(_measure(WB + [hidden], seed), RATE, WB, seed=seed, simulate=False)
    assert [a["effect"] for a in r.added] == ["random_walk"]
    assert r.added[0]["K"] == pytest.approx(1e-3, rel=0.30)
    nested = r.iterations[0]["nested"]
    assert nested["lr_raw"] > 15.1 and nested["inflation"] > 1.5 and nested["lr"] < nested["threshold"]


@pytest.mark.parametrize("seed", [1000, pytest.param(1001, marks=pytest.mark.soak)])
def test_gauss_markov_at_a_hundredth_of_the_record(seed):
    """tau_c = 75 s in 7200 s: named Gauss-Markov, not its random-walk limit. The Cramer-Rao bound on
    ln tau_c for this record is 0.23 (benchmarks/bench_gap.py, limit table), so the tolerance is its 99 %
    range, exp(2.58 * 0.23) = 1.81x; the 30 % rate over many seeds is measured by the benchmark."""
    hidden = {"effect": "gauss_markov", "sigma": 5e-4, "tau_c": 75.0}
    r = run_gap(_measure(WB + [hidden], seed), RATE, WB, seed=seed, simulate=False)
    assert [a["effect"] for a in r.added] == ["gauss_markov"]
    assert 75.0 / 1.81 < r.added[0]["tau_c"] < 75.0 * 1.81
    assert r.added[0]["sigma"] == pytest.approx(5e-4, rel=0.30)
    assert r.gap_after <= NOISE_FLOOR_G


def test_too_long_gauss_markov_is_named_random_walk_with_the_alternative():
    """tau_c = 300 s in 7200 s (T/24): no estimator can pin tau_c within 30 % reliably (Cramer-Rao 0.42 in
    ln tau_c). Seed 1000: the random walk is named, the gap closes, and the report gives the Gauss-Markov
    fit as the alternative the record cannot rule out."""
    hidden = {"effect": "gauss_markov", "sigma": 5e-4, "tau_c": 300.0}
    r = run_gap(_measure(WB + [hidden], 1000), RATE, WB, seed=0, simulate=False)
    assert [a["effect"] for a in r.added] == ["random_walk"]
    alt = r.added[0]["alternative"]
    assert alt["effect"] == "gauss_markov" and alt["instead_of"] == "random_walk" and 150.0 < alt["tau_c"] < 600.0
    assert "too short to tell" in r.added[0]["explanation"]
    assert r.gap_after <= NOISE_FLOOR_G


def test_hidden_flicker_is_not_named_a_gauss_markov_term():
    """A flicker floor B 4.5e-4 hidden from white + random walk (2 h at 50 Hz; a fresh bench_gap draw): one
    Gauss-Markov term of tau_c ~17 s fits this record 5.3 deviance units better, which the ranking's 3.3
    for its shape parameter let through. The one-parameter flicker is named, B within 30 % of the truth,
    and the Gauss-Markov fit is given as the alternative."""
    model = [{"effect": "white_noise", "N": 1.2233769e-3}, {"effect": "random_walk", "K": 4.3008905e-6}]
    hidden = {"effect": "bias_instability", "B": 4.4951199e-4}
    y = synthesize_axis(model + [hidden], RATE_50, N_50, np.random.default_rng(718693275102007))
    r = run_gap(y, RATE_50, model, seed=0, simulate=False)
    assert [a["effect"] for a in r.added] == ["bias_instability"]
    assert abs(r.added[0]["B"] / hidden["B"] - 1) < 0.3
    alt = r.added[0]["alternative"]
    assert alt["effect"] == "gauss_markov" and alt["instead_of"] == "bias_instability" and alt["lr"] < 10.8
    assert r.gap_after <= NOISE_FLOOR_G


def test_flicker_rule_charges_the_shape_parameter_its_level():
    """The rule alone: a Gauss-Markov winner gives way to an added flicker that passes its own level unless
    it fits better by more than chi^2_1(0.999) = 10.8; a flicker that fails its level, or comes with other
    recalibrations, does not replace it."""
    from companion.gap.candidates import Fit
    from companion.gap.selection import Explanation, flicker_rule

    def x(effect, dev, score_pen=15.1, recal=()):
        return Explanation(effect, recal, Fit([], [], dev, 1.0, np.zeros(1)), 1000.0 - dev, 1.0, score_pen)

    gm = x("gauss_markov", 100.0, 18.4)
    assert flicker_rule(gm, [gm, x("bias_instability", 105.0)]).effect == "bias_instability"
    assert flicker_rule(gm, [gm, x("bias_instability", 115.0)]) is gm
    assert flicker_rule(gm, [gm, x("bias_instability", 990.0)]) is gm  # fails its level (score < 0)
    assert flicker_rule(gm, [gm, x("bias_instability", 105.0, recal=(1,))]) is gm
    sine = x("sinusoid", 100.0, 18.4)
    assert flicker_rule(sine, [sine, x("bias_instability", 101.0)]) is sine


def test_alternative_explanations_name_the_right_limit():
    from companion.gap.explain import explain_alternative

    alt = {"effect": "gauss_markov", "sigma": 5e-4, "tau_c": 300.0, "lr": 4.2}
    rw = explain_alternative({**alt, "instead_of": "random_walk"}, 7200.0, 20.0)
    assert "rate random walk" in rw and "24 times that tau_c" in rw
    wn = explain_alternative({**alt, "tau_c": 0.1, "instead_of": "white_noise"}, 7200.0, 20.0)
    assert "white noise" in wn and "2 samples" in wn and "random walk" not in wn
    fl = explain_alternative({**alt, "tau_c": 17.0, "instead_of": "bias_instability"}, 7200.0, 20.0)
    assert "flicker" in fl and "random walk" not in fl


# --- a ramp under a mis-sized random walk: explanations weighed head to head on the same data ----------------------------------------
RATE_50 = 50.0
N_50 = int(2 * 3600 * RATE_50)
ISSUE_MODEL = [{"effect": "white_noise", "N": 1.5e-3}, {"effect": "bias_instability", "B": 7.3e-4},
               {"effect": "random_walk", "K": 2.0e-5}]


def _ranked(r, it=0):
    return {x["explanation"]: x for x in r.iterations[it]["explanations"]}


def test_issue_ramp_is_named_not_a_larger_random_walk():
    """A ramp that hides under the random walk: R = 4.9e-6 rad/s^2 under N 1.5e-3, B 7.3e-4, K 2e-5 (2 h at 50 Hz). Before, a
    ramp test against a model whose K was already free gave LR 14.4 < 15.1 and 'K 5x too small' won; now
    the ramp and the recalibrated K are fitted from the same state and the ramp scores higher."""
    y = synthesize_axis(ISSUE_MODEL + [{"effect": "ramp", "R": 4.9e-6}], RATE_50, N_50, np.random.default_rng(0))
    r = run_gap(y, RATE_50, ISSUE_MODEL, simulate=False)
    assert [a["effect"] for a in r.added] == ["ramp"]
    assert r.added[0]["R"] == pytest.approx(4.9e-6, rel=0.30)
    assert [e["verdict"] for e in r.recalibrated] == ["consistent"] * 3
    assert r.gap_after <= NOISE_FLOOR_G < r.gap_before
    ranked = _ranked(r)
    k = ranked.get("recalibrated random_walk K")
    if k is None:  # not among the eight best shown: then it scored below all of them
        k = min(ranked.values(), key=lambda x: x["score"])
    assert r.iterations[0]["chosen"] == "ramp" and r.iterations[0]["test"]["score"] > k["score"]
    doc = r.to_dict()
    alt = doc["alternatives"][0]
    assert alt["chosen"]["explanation"] == "ramp" and alt["runner_up"] is not None and alt["margin"] > 0
    assert alt["runner_up"]["score"] < alt["chosen"]["score"] and "weighed against" in alt["text"]


@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.soak), pytest.param(3, marks=pytest.mark.soak)])
def test_issue_ramp_family_names_the_ramp(seed):
    """Fresh draws like the issue's case: N, B, K and R each scaled by a factor in 0.8-1.25."""
    rng = np.random.default_rng(1600 + seed)
    f = rng.uniform(0.8, 1.25, 4)
    model = [{"effect": "white_noise", "N": 1.5e-3 * f[0]}, {"effect": "bias_instability", "B": 7.3e-4 * f[1]},
             {"effect": "random_walk", "K": 2.0e-5 * f[2]}]
    y = synthesize_axis(model + [{"effect": "ramp", "R": 4.9e-6 * f[3]}], RATE_50, N_50, rng)
    r = run_gap(y, RATE_50, model, simulate=False)
    assert [a["effect"] for a in r.added] == ["ramp"]
    assert r.recalibrated[2]["verdict"] == "consistent"
    assert r.gap_after <= NOISE_FLOOR_G


def test_missized_k_is_chosen_when_it_fits_better():
    """No ramp, the model's K 3x too small: the recalibrated K is chosen over the ramp (both one parameter:
    the larger likelihood), and the ramp is in the ranking with a lower one."""
    truth = [dict(t) for t in ISSUE_MODEL[:2]] + [{"effect": "random_walk", "K": 6.0e-5}]
    y = synthesize_axis(truth, RATE_50, N_50, np.random.default_rng(5))
    r = run_gap(y, RATE_50, ISSUE_MODEL, simulate=False)
    assert r.added == []
    k = r.recalibrated[2]
    assert k["verdict"] == "too small" and k["ratio"] == pytest.approx(3.0, rel=0.35)
    ranked = _ranked(r)
    assert r.iterations[0]["chosen"] == "recalibrated random_walk K"
    assert ranked["ramp"]["score"] < ranked["recalibrated random_walk K"]["score"]
    assert ranked["ramp"]["delta_dev"] < ranked["recalibrated random_walk K"]["delta_dev"]


@pytest.mark.soak
def test_ramp_beside_gauss_markov_is_not_absorbed_by_a_recalibrated_k():
    """A hard-tier draw (mis-sized model, a ramp and a Gauss-Markov term hidden): after the Gauss-Markov
    term, "random walk K recalibrated" (16x) and the ramp both pass and the ramp fits better; the level of a
    recalibration (10.8 < 15.1) made K win and the ramp was never named (fails with that rule). Both one
    parameter: the larger likelihood wins (selection.equal_size_rule, and the swap step)."""
    truth = [{"effect": "white_noise", "N": 9.8716e-4}, {"effect": "bias_instability", "B": 2.8537e-4},
             {"effect": "random_walk", "K": 4.8452e-6}, {"effect": "ramp", "R": 1.7908e-6},
             {"effect": "gauss_markov", "sigma": 2.0629e-3, "tau_c": 28.468}]
    model = [{"effect": "white_noise", "N": 1.2588e-3}, {"effect": "bias_instability", "B": 2.5630e-4},
             {"effect": "random_walk", "K": 3.7695e-6}]
    y = synthesize_axis(truth, RATE_50, N_50, np.random.default_rng(365166856005))
    r = run_gap(y, RATE_50, model, simulate=False)
    assert sorted(a["effect"] for a in r.added) == ["gauss_markov", "ramp"]
    assert r.recalibrated[2]["verdict"] == "consistent"
    assert r.gap_after <= NOISE_FLOOR_G


def test_gauss_markov_preferred_by_likelihood_still_meets_its_limit():
    """A hard-tier draw (a random walk hidden from a mis-sized white + flicker model): a sinusoid leads the
    first ranking, the equal-size rule prefers the Gauss-Markov term that fits better (tau_c ~ 260 s), and
    that term must still beat its random-walk limit (it was named without the nested test before)."""
    truth = [{"effect": "white_noise", "N": 2.2121e-3}, {"effect": "bias_instability", "B": 6.0009e-4},
             {"effect": "random_walk", "K": 1.19674e-4}]
    model = [{"effect": "white_noise", "N": 2.91258e-3}, {"effect": "bias_instability", "B": 6.86633e-4}]
    y = synthesize_axis(truth, RATE_50, N_50, np.random.default_rng(489328211604001))
    r = run_gap(y, RATE_50, model, simulate=False)
    assert [a["effect"] for a in r.added] == ["random_walk"]
    assert r.added[0]["K"] == pytest.approx(1.19674e-4, rel=0.3)
    assert r.iterations[0].get("nested", {}).get("limit") == "random_walk"
    assert r.gap_after <= NOISE_FLOOR_G


@pytest.mark.parametrize("seed", [71, pytest.param(72, marks=pytest.mark.soak)])
def test_null_fresh_random_model_adds_nothing(seed):
    """Model == truth with random magnitudes (white/flicker crossover 1-100 s, flicker/random-walk
    crossover T/10-3T, as in benchmarks/bench_gap.py): nothing added."""
    rng = np.random.default_rng(seed)
    N_ = math.exp(rng.uniform(math.log(3e-4), math.log(3e-3)))
    B = N_ / math.sqrt(math.exp(rng.uniform(0.0, math.log(100.0)))) / 0.664
    K = 0.664 * B * math.sqrt(3.0 / math.exp(rng.uniform(math.log(720.0), math.log(21600.0))))
    model = [{"effect": "white_noise", "N": N_}, {"effect": "bias_instability", "B": B},
             {"effect": "random_walk", "K": K}]
    r = run_gap(synthesize_axis(model, RATE_50, N_50, rng), RATE_50, model, simulate=False)
    assert r.added == []
