"""Every synthesiser against its analytic Allan variance (IEEE 952), over many seeds; tolerance from the
model covariance of the OAVAR estimates (companion.allan.confidence), i.e. from the EDF."""

import numpy as np
import pytest

from companion.allan import terms as T
from companion.allan.adev import oavar
from companion.allan.confidence import oavar_covariance
from companion.sim.synth import simulate_model, synthesize_axis

RATE = 10.0
N_SAMPLES = 20000
SEEDS = 24
M = np.array([4, 8, 16, 32, 64, 128, 256])

CASES = [
    ({"effect": "white_noise", "N": 2e-3}, {"effect": "white_noise", "N": 2e-3}),
    ({"effect": "quantization", "Q": 1e-4}, {"effect": "quantization", "Q": 1e-4}),
    # flicker with its high cut-off at Nyquist: the cosine-integral form with f0 = fs/2 (thesis eq. 3.16)
    ({"effect": "bias_instability", "B": 1e-3}, {"effect": "bias_instability", "B": 1e-3, "f0": RATE / 2}),
    # the README's optional cut-off f0 below Nyquist: the same cosine-integral form with that f0
    ({"effect": "bias_instability", "B": 1e-3, "f0": RATE / 8}, {"effect": "bias_instability", "B": 1e-3, "f0": RATE / 8}),
    ({"effect": "random_walk", "K": 1e-4}, {"effect": "random_walk", "K": 1e-4}),
    ({"effect": "gauss_markov", "sigma": 1e-3, "tau_c": 3.0}, {"effect": "gauss_markov", "sigma": 1e-3, "tau_c": 3.0}),
    ({"effect": "sinusoid", "amplitude": 1e-3, "freq_hz": 0.07}, {"effect": "sinusoid", "amplitude": 1e-3, "freq_hz": 0.07}),
]


@pytest.mark.parametrize("term,analytic", CASES, ids=[c[0]["effect"] + ("_f0" if "f0" in c[0] else "") for c in CASES])
def test_synth_matches_analytic_avar(term, analytic):
    rng = np.random.default_rng(12345)
    # continuous-time formulas; the sampled process departs from them at a few tau0 (e.g. the discrete
    # random walk has AVAR K^2 tau/3 (1 + 1/(2 m^2))), so long-memory effects are compared from m = 16
    m = M if term["effect"] in ("white_noise", "quantization", "random_walk", "sinusoid") else M[M >= 16]
    est = np.array([oavar(synthesize_axis([term], RATE, N_SAMPLES, rng), RATE, m=m)[1] for _ in range(SEEDS)])
    mean = est.mean(axis=0)
    truth = T.avar_term(analytic, m / RATE)
    if term["effect"] == "random_walk":
        truth = truth * (1.0 + 1.0 / (2.0 * m**2))
    if term["effect"] == "sinusoid":  # random phase only: the AVAR hardly varies between seeds
        assert mean == pytest.approx(truth, rel=0.02)
        return
    sd = np.sqrt(np.diag(oavar_covariance([term], m, N_SAMPLES, RATE)) / SEEDS)
    z = (mean - truth) / sd
    # 4.5 sigma per point (7 points, 6 effects: a false alarm is far below 1e-3); and not biased overall
    assert np.all(np.abs(z) < 4.5), z
    assert abs(z.mean()) < 3.0, z


def test_ramp_is_exact():
    y = synthesize_axis([{"effect": "ramp", "R": 2e-4}], RATE, 5000, np.random.default_rng(0))
    tau, av, _, _ = oavar(y, RATE, m=M)
    assert av == pytest.approx(T.avar_ramp(tau, 2e-4), rel=1e-9)


def test_white_noise_sample_std_is_two_sided_density():
    y = synthesize_axis([{"effect": "white_noise", "N": 1e-3}], 400.0, 200000, np.random.default_rng(1))
    # two-sided PSD N^2 -> per-sample std N sqrt(fs) = 0.02; standard error of the std ~ 0.02 / sqrt(2 n)
    assert np.std(y) == pytest.approx(1e-3 * np.sqrt(400.0), rel=5 * 1 / np.sqrt(2 * 200000))


def test_gauss_markov_is_stationary_with_exact_correlation():
    rng = np.random.default_rng(2)
    Tc, s, fs = 0.5, 2.0, 20.0
    ys = np.array([synthesize_axis([{"effect": "gauss_markov", "sigma": s, "tau_c": Tc}], fs, 400, rng) for _ in range(400)])
    assert np.std(ys[:, 0]) == pytest.approx(s, rel=0.15)  # stationary from the first sample
    phi = np.mean(ys[:, 1:] * ys[:, :-1]) / np.mean(ys**2)
    assert phi == pytest.approx(np.exp(-1 / (fs * Tc)), abs=0.01)


def test_simulate_model_axes_independent_of_order():
    a = simulate_model({"rate_hz": 10.0, "axes": {"gx": [{"effect": "white_noise", "N": 1.0}],
                                                  "gy": [{"effect": "white_noise", "N": 1.0}]}}, 100, seed=3)
    b = simulate_model({"rate_hz": 10.0, "axes": {"gy": [{"effect": "white_noise", "N": 1.0}]}}, 100, seed=3)
    assert np.array_equal(a["gy"], b["gy"]) and not np.array_equal(a["gx"], a["gy"])
    assert a["gx"].shape == (1000,)


@pytest.mark.parametrize("term, msg", [
    ({"effect": "sinusoid", "amplitude": 1e-3, "freq_hz": 6.0}, "Nyquist"),
    ({"effect": "sinusoid", "amplitude": 1e-3, "freq_hz": 5.0}, "Nyquist"),
    ({"effect": "bias_instability", "B": 1e-3, "f0": 7.0}, "f0"),
])
def test_terms_the_rate_cannot_carry_are_refused(term, msg):
    with pytest.raises(ValueError, match=msg):
        synthesize_axis([term], RATE, 100, np.random.default_rng(0))
