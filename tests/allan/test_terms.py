"""The analytic noise-term library against IEEE 952 / REFERENCE.md facts (independent numbers)."""

import math

import numpy as np
import pytest

from companion.allan import terms as T


def test_slopes_and_constants():
    tau = np.array([1.0, 10.0])
    assert T.avar_quantization(tau, 2.0) == pytest.approx([12.0, 0.12])
    assert T.avar_white_noise(tau, 2.0) == pytest.approx([4.0, 0.4])
    assert T.avar_random_walk(tau, 3.0) == pytest.approx([3.0, 30.0])
    assert T.avar_ramp(tau, 2.0) == pytest.approx([2.0, 200.0])
    assert T.avar_bias_instability(tau, 1.0) == pytest.approx([0.4412712] * 2, rel=1e-6)


def test_gauss_markov_peak_and_limits():
    tau = np.logspace(-3, 4, 20001)
    adev = np.sqrt(T.avar_gauss_markov(tau, 2.0, 10.0))
    i = int(np.argmax(adev))
    assert tau[i] / 10.0 == pytest.approx(1.89, abs=0.01)
    assert adev[i] == pytest.approx(0.617 * 2.0, rel=2e-3)
    qc2 = 2 * 2.0**2 / 10.0
    # short tau: rate random walk with K^2 = qc^2; long tau: white noise with N^2 = (qc Tc)^2
    assert T.avar_gauss_markov(1e-4, 2.0, 10.0) == pytest.approx(qc2 * 1e-4 / 3, rel=1e-4)
    assert T.avar_gauss_markov(1e6, 2.0, 10.0) == pytest.approx(qc2 * 100 / 1e6, rel=1e-4)


def test_sinusoid_peak():
    tau = np.logspace(-2, 2, 20001)
    adev = np.sqrt(T.avar_sinusoid(tau, 1.0, 0.1))
    i = int(np.argmax(adev))
    assert tau[i] * 0.1 == pytest.approx(0.371, abs=0.001)
    assert adev[i] == pytest.approx(0.725, abs=0.001)


def test_bias_instability_full_form_tends_to_plateau():
    B = 3.0
    assert T.avar_bias_instability(1e4, B, f0=50.0) == pytest.approx(T.BIAS_PLATEAU * B**2, rel=1e-4)
    assert T.avar_bias_instability(0.001, B, f0=50.0) < T.BIAS_PLATEAU * B**2


def test_validate_term_messages():
    with pytest.raises(ValueError, match="unknown effect"):
        T.validate_term({"effect": "pink"})
    with pytest.raises(ValueError, match="needs parameter 'tau_c'"):
        T.validate_term({"effect": "gauss_markov", "sigma": 1.0})
    with pytest.raises(ValueError, match="no parameter 'X'"):
        T.validate_term({"effect": "white_noise", "N": 1.0, "X": 2})
    T.validate_term({"effect": "bias_instability", "B": 1.0, "f0": 50.0})
    T.validate_term({"effect": "white_noise", "N": 1.0, "filter_hz": 5.0, "filter_order": 1})
    with pytest.raises(ValueError, match="'filter_order' must be 1, 2, 3 or 4"):
        T.validate_term({"effect": "white_noise", "N": 1.0, "filter_hz": 5.0, "filter_order": 0})


def test_linear_basis_matches_terms():
    tau = np.array([0.5, 2.0, 40.0])
    basis = T.linear_basis(tau)
    coef = np.array([1e-3, 2e-3, 3e-4, 4e-5, 5e-7]) ** 2
    terms = [{"effect": e, T.LINEAR_PARAM[e]: math.sqrt(c)} for e, c in zip(T.LINEAR_EFFECTS, coef)]
    assert basis @ coef == pytest.approx(T.avar_model(terms, tau), rel=1e-12)
