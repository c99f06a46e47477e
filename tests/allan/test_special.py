"""The scipy-free root finder, bounded minimiser and chi-square functions of companion.allan.special,
checked against scipy (the reference) over grids, and against independent truth where scipy itself is
inexact (lower tail of the chi-square at very large nu)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.allan.special import (brentq, chi2_cdf, chi2_ppf, chi2_sf, gammainc_p, gammainc_q,
                                     minimize_scalar_bounded)

scipy_optimize = pytest.importorskip("scipy.optimize")
scipy_special = pytest.importorskip("scipy.special")
scipy_stats = pytest.importorskip("scipy.stats")

NU = [0.1, 0.3, 1.0, 2.0, 3.7, 10.0, 33.0, 100.0, 1e3, 1e4, 1e5, 1e6]
P = [1e-10, 1e-6, 1e-3, 0.025, 0.1, 0.5, 0.68, 0.95, 0.975, 0.999, 1 - 1e-6, 1 - 1e-10]


def _roots_cases():
    rng = np.random.default_rng(7)
    cases = [(lambda x: x**3 - 2.0 * x - 5.0, 2.0, 3.0),
             (lambda x: math.cos(x) - x, 0.0, 1.0),
             (lambda x: math.exp(x) - 1e3, 0.0, 20.0),
             (lambda x: (x - 0.3) ** 5, -1.0, 2.0),  # flat root
             (lambda x: math.atan(50.0 * (x - 0.123)), -3.0, 4.0)]
    for _ in range(20):
        c, s = rng.uniform(-2, 2), rng.uniform(0.1, 10)
        cases.append((lambda x, c=c, s=s: math.tanh(s * (x - c)) + 0.1 * (x - c), -5.0, 5.0))
    return cases


@pytest.mark.parametrize("xtol", [1e-4, 2e-12])
def test_brentq_matches_scipy(xtol):
    for f, a, b in _roots_cases():
        ours = brentq(f, a, b, xtol=xtol)
        ref = scipy_optimize.brentq(f, a, b, xtol=xtol)
        assert abs(ours - ref) <= 1e-12 * max(1.0, abs(ref)), (ours, ref)


def test_brentq_rejects_same_sign_and_returns_endpoint_roots():
    with pytest.raises(ValueError):
        brentq(lambda x: x * x + 1.0, -1.0, 1.0)
    assert brentq(lambda x: x - 1.0, 1.0, 2.0) == 1.0
    assert brentq(lambda x: x - 2.0, 1.0, 2.0) == 2.0


@pytest.mark.parametrize("xatol", [1e-3, 1e-5])
def test_minimize_scalar_bounded_matches_scipy(xatol):
    rng = np.random.default_rng(3)
    funcs = [(lambda x: (x - 1.3) ** 2, -2.0, 4.0),
             (lambda x: math.cos(x), 2.0, 5.0),
             (lambda x: abs(x - 0.7) + 0.1 * x * x, -1.0, 3.0),
             (lambda x: x, 0.0, 1.0),  # minimum on the bound
             (lambda x: -math.exp(-((x - 5.0) ** 2)), 0.0, 6.0)]
    for _ in range(20):
        c, w = rng.uniform(-3, 3), rng.uniform(0.2, 3)
        funcs.append((lambda x, c=c, w=w: math.log1p(((x - c) / w) ** 2) + 0.01 * x, -4.0, 4.0))
    for f, a, b in funcs:
        x, fx = minimize_scalar_bounded(f, a, b, xatol=xatol)
        ref = scipy_optimize.minimize_scalar(f, bounds=(a, b), method="bounded", options={"xatol": xatol})
        assert x == pytest.approx(float(ref.x), abs=1e-12, rel=1e-12)
        assert fx == pytest.approx(float(ref.fun), abs=1e-14, rel=1e-12)


def test_gammainc_matches_scipy():
    for a in [0.05, 0.5, 1.0, 2.5, 10.0, 77.7, 1e3, 1e5]:
        for x in a * np.array([1e-6, 0.01, 0.3, 0.9, 1.0, 1.1, 2.0, 5.0]) + np.array([0, 0, 0, 0, 0, 0, 0, 1.0]):
            x = float(x)
            p_ref, q_ref = scipy_special.gammainc(a, x), scipy_special.gammaincc(a, x)
            if p_ref > 1e-300:
                assert gammainc_p(a, x) == pytest.approx(p_ref, rel=1e-10)
            if q_ref > 1e-300:
                assert gammainc_q(a, x) == pytest.approx(q_ref, rel=1e-10)


def test_chi2_cdf_sf_match_scipy():
    for nu in NU[:-1]:
        for x in nu * np.array([0.01, 0.5, 1.0, 1.5, 3.0]):
            assert chi2_cdf(float(x), nu) == pytest.approx(scipy_stats.chi2.cdf(x, nu), rel=1e-10, abs=1e-300)
            assert chi2_sf(float(x), nu) == pytest.approx(scipy_stats.chi2.sf(x, nu), rel=1e-10, abs=1e-300)
    assert chi2_cdf(0.0, 3.0) == 0.0 and chi2_sf(-1.0, 3.0) == 1.0


@pytest.mark.parametrize("nu", NU[:-1])
def test_chi2_ppf_matches_scipy(nu):
    for p in P:
        assert chi2_ppf(p, nu) == pytest.approx(scipy_stats.chi2.ppf(p, nu), rel=1e-10)


def test_chi2_ppf_dense_grid():
    """A dense nu grid (a Newton step at rounding level once sent the iteration off the bracket)."""
    for nu in np.geomspace(0.1, 1e6, 301):
        for p in (1e-10, 1e-3, 0.025, 0.16, 0.5, 0.84, 0.975, 1 - 1e-10):
            assert chi2_ppf(p, nu) == pytest.approx(scipy_stats.chi2.ppf(p, nu), rel=1e-10), (p, nu)


@pytest.mark.parametrize("nu", [1e6, 1.9e6, 2.1e6, 1e7, 1e9])
def test_chi2_ppf_large_nu(nu):
    """The upper tail against scipy; the lower tail, where scipy's incomplete gamma loses ~1e-5 relative at
    nu ~ 1e6, by the round trip through our own series/continued fraction (checked above) and against
    Wilson-Hilferty (error O(1/nu) relative)."""
    for p in P:
        x = chi2_ppf(p, nu)
        if p >= 0.5:
            assert x == pytest.approx(scipy_stats.chi2.ppf(p, nu), rel=1e-10)
        z = scipy_stats.norm.ppf(p)
        wh = nu * (1.0 - 2.0 / (9.0 * nu) + z * math.sqrt(2.0 / (9.0 * nu))) ** 3
        assert x == pytest.approx(wh, rel=50.0 / nu)
        if nu <= 2.1e6:  # the Cornish-Fisher branch above 2e6 checked against the exact inversion
            back = chi2_cdf(x, nu) if p <= 0.5 else 1.0 - chi2_sf(x, nu)
            assert back == pytest.approx(p, rel=1e-7)


def test_chi2_ppf_edges():
    assert chi2_ppf(0.0, 3.0) == 0.0
    assert chi2_ppf(1.0, 3.0) == math.inf
    assert math.isnan(chi2_ppf(0.5, 0.0)) and math.isnan(chi2_ppf(1.5, 2.0))
