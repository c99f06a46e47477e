"""Pure-Python root finding, bounded minimisation and chi-square quantiles for the live fit (no scipy).

`companion run` refits its online report with :mod:`companion.allan.fit`; importing ``scipy.optimize`` and
``scipy.stats`` for the three small things it needs would take the process from ~28 MiB to ~100 MiB
resident. These functions reproduce those calls within numerical tolerance (tests/allan/test_special.py
compares them with scipy over a grid):

- :func:`brentq`: root of a bracketing function, Brent (1973) as in scipy's ``brentq``.
- :func:`minimize_scalar_bounded`: Brent's bounded minimiser (scipy ``minimize_scalar(method="bounded")``).
- :func:`gammainc_p`, :func:`gammainc_q`: regularised incomplete gamma functions P(a, x), Q(a, x).
- :func:`chi2_ppf`, :func:`chi2_cdf`, :func:`chi2_sf`: chi-square quantile and distribution functions.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np

__all__ = ["brentq", "minimize_scalar_bounded", "gammainc_p", "gammainc_q", "chi2_cdf", "chi2_sf", "chi2_ppf", "Z95"]

#: double-precision machine epsilon: series and root searches stop at rounding
_EPS = 2.220446049250313e-16
#: a denominator below this is replaced by it in the continued fraction (Lentz's method): no division by 0
_FPMIN = 1e-300
#: the standard normal of the Wilson-Hilferty / Cornish-Fisher starting points
_STD_NORMAL = NormalDist()
#: two-sided 95 % standard normal quantile
Z95 = 1.959963984540054


def brentq(f, a: float, b: float, xtol: float = 2e-12, rtol: float = 4 * _EPS, maxiter: int = 100) -> float:
    """Root of ``f`` in [a, b] (f(a), f(b) of opposite sign) by Brent's method.

    Each step takes inverse quadratic interpolation through the last three points (secant when two
    coincide) if it stays well inside the bracket and shrinks fast enough, else bisection. Stops when
    half the bracket is below delta = (xtol + rtol |x|) / 2, i.e. |x - x*| <= xtol + rtol |x| as in
    ``scipy.optimize.brentq``.

    Reference: R. P. Brent, *Algorithms for Minimization Without Derivatives*, Prentice-Hall (1973), ch. 4;
    the step logic of scipy's ``brentq.c``.
    """
    xpre, xcur = float(a), float(b)
    fpre, fcur = float(f(xpre)), float(f(xcur))
    if fpre * fcur > 0:
        raise ValueError("brentq: f(a) and f(b) must have different signs")
    if fpre == 0:
        return xpre
    if fcur == 0:
        return xcur
    xblk = fblk = spre = scur = 0.0
    for _ in range(maxiter):
        if fpre != 0 and fcur != 0 and (fpre < 0) != (fcur < 0):
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(xcur)) / 2.0
        sbis = (xblk - xcur) / 2.0
        if fcur == 0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:  # secant
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:  # inverse quadratic interpolation
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            if 2.0 * abs(stry) < min(abs(spre), 3.0 * abs(sbis) - delta):
                spre, scur = scur, stry  # interpolation accepted
            else:
                spre = scur = sbis
        else:
            spre = scur = sbis
        xpre, fpre = xcur, fcur
        xcur += scur if abs(scur) > delta else (delta if sbis > 0 else -delta)
        fcur = float(f(xcur))
    return xcur


def minimize_scalar_bounded(f, a: float, b: float, xatol: float = 1e-5, maxfun: int = 500) -> tuple[float, float]:
    """``(x, f(x))`` minimising ``f`` on [a, b] by Brent's method (golden section + parabolic steps).

    A parabola through the three best points x, w, v gives the step p/q; it is taken when it falls inside
    (a, b) and is smaller than half the step before last, else a golden-section step
    c = (3 - sqrt 5)/2 into the larger segment. Stops when |x - m| <= 2 tol1 - (b - a)/2 with
    m = (a + b)/2 and tol1 = sqrt(eps) |x| + xatol/3 -- the semantics of scipy's
    ``minimize_scalar(method="bounded", options={"xatol": ...})`` (``_minimize_scalar_bounded``).

    Reference: R. P. Brent (1973), ch. 5; Press et al., *Numerical Recipes*, 3rd ed., section 10.3 (``brent``).
    """
    sqrt_eps = math.sqrt(2.2e-16)  # the rounded eps of scipy and of Brent's fmin, so the steps match
    golden_mean = 0.5 * (3.0 - math.sqrt(5.0))
    a, b = float(a), float(b)
    if a > b:
        raise ValueError("minimize_scalar_bounded: lower bound above upper bound")
    fulc = a + golden_mean * (b - a)
    nfc = xf = fulc
    rat = e = 0.0
    x = xf
    fx = float(f(x))
    num = 1
    ffulc = fnfc = fx
    xm = 0.5 * (a + b)
    tol1 = sqrt_eps * abs(xf) + xatol / 3.0
    tol2 = 2.0 * tol1
    while abs(xf - xm) > (tol2 - 0.5 * (b - a)):
        golden = True
        if abs(e) > tol1:  # try a parabolic step
            golden = False
            r = (xf - nfc) * (fx - ffulc)
            q = (xf - fulc) * (fx - fnfc)
            p = (xf - fulc) * q - (xf - nfc) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            r = e
            e = rat
            if abs(p) < abs(0.5 * q * r) and q * (a - xf) < p < q * (b - xf):
                rat = p / q
                x = xf + rat
                if (x - a) < tol2 or (b - x) < tol2:
                    rat = tol1 if xm >= xf else -tol1
            else:
                golden = True
        if golden:
            e = (a - xf) if xf >= xm else (b - xf)
            rat = golden_mean * e
        x = xf + (1.0 if rat >= 0 else -1.0) * max(abs(rat), tol1)
        fu = float(f(x))
        num += 1
        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            fulc, ffulc = nfc, fnfc
            nfc, fnfc = xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if fu <= fnfc or nfc == xf:
                fulc, ffulc = nfc, fnfc
                nfc, fnfc = x, fu
            elif fu <= ffulc or fulc == xf or fulc == nfc:
                fulc, ffulc = x, fu
        xm = 0.5 * (a + b)
        tol1 = sqrt_eps * abs(xf) + xatol / 3.0
        tol2 = 2.0 * tol1
        if num >= maxfun:
            break
    return xf, fx


def _log_gamma_prefactor(a: float, x: float) -> float:
    """log(x^a e^-x / Gamma(a)).

    For a >= 10 written as a (log1p(t) - t) + (1/2) log(a / 2 pi) - s(a), t = (x - a)/a, with the Stirling
    remainder s(a) = lgamma(a) - (a - 1/2) log a + a - (1/2) log 2 pi = 1/(12a) - 1/(360a^3) + 1/(1260a^5)
    - 1/(1680a^7) (A&S 6.1.41), so that the large terms a log x, x, lgamma(a) do not cancel (absolute error
    ~eps |x - a| instead of ~eps a).
    """
    if a < 10.0:
        return a * math.log(x) - x - math.lgamma(a)
    t = (x - a) / a
    ia2 = 1.0 / (a * a)
    stirl = (1.0 / 12.0 - ia2 * (1.0 / 360.0 - ia2 * (1.0 / 1260.0 - ia2 / 1680.0))) / a
    return a * (math.log1p(t) - t) + 0.5 * math.log(a / (2.0 * math.pi)) - stirl


def _gser(a: float, x: float) -> float:
    """P(a, x) by its series, P = x^a e^-x / Gamma(a) * sum_n x^n / (a (a+1) ... (a+n)); for x < a + 1."""
    if a > 50.0:
        # x near a: the terms fall like e^(-n^2 / 2a), so about sqrt(72 a) of them matter; summed as arrays
        # (the same products in the same order) instead of thousands of Python steps
        k = int(math.sqrt(80.0 * a)) + 60
        terms = np.cumprod(x / (a + np.arange(1.0, k + 1.0))) / a
        total = 1.0 / a + float(terms.sum())
        if terms[-1] < _EPS * total * 1e-3:
            return total * math.exp(_log_gamma_prefactor(a, x))
    ap = a
    term = total = 1.0 / a
    for _ in range(100000):
        ap += 1.0
        term *= x / ap
        total += term
        if abs(term) < abs(total) * _EPS:
            break
    return total * math.exp(_log_gamma_prefactor(a, x))


def _gcf(a: float, x: float) -> float:
    """Q(a, x) by its continued fraction (modified Lentz), Q = x^a e^-x / Gamma(a) *
    1/(x+1-a- 1(1-a)/(x+3-a- 2(2-a)/(x+5-a- ...))); for x >= a + 1."""
    b = x + 1.0 - a
    c = 1.0 / _FPMIN
    d = 1.0 / b
    h = d
    for i in range(1, 100000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        if abs(d) < _FPMIN:
            d = _FPMIN
        c = b + an / c
        if abs(c) < _FPMIN:
            c = _FPMIN
        d = 1.0 / d
        step = d * c
        h *= step
        if abs(step - 1.0) < _EPS:
            break
    return h * math.exp(_log_gamma_prefactor(a, x))


def gammainc_p(a: float, x: float) -> float:
    """Regularised lower incomplete gamma P(a, x) = gamma(a, x) / Gamma(a) = (1/Gamma(a)) int_0^x t^(a-1) e^-t dt.

    Series for x < a + 1, 1 - (continued fraction for Q) otherwise.
    Reference: Press et al., *Numerical Recipes*, 3rd ed., section 6.2 (``gammp``, ``gser``, ``gcf``);
    Abramowitz & Stegun 6.5.29 and 6.5.31.
    """
    if a <= 0 or x < 0:
        raise ValueError("gammainc_p: need a > 0 and x >= 0")
    if x == 0:
        return 0.0
    if math.isinf(x):
        return 1.0
    return _gser(a, x) if x < a + 1.0 else 1.0 - _gcf(a, x)


def gammainc_q(a: float, x: float) -> float:
    """Regularised upper incomplete gamma Q(a, x) = 1 - P(a, x), accurate in the upper tail (see :func:`gammainc_p`)."""
    if a <= 0 or x < 0:
        raise ValueError("gammainc_q: need a > 0 and x >= 0")
    if x == 0:
        return 1.0
    if math.isinf(x):
        return 0.0
    return 1.0 - _gser(a, x) if x < a + 1.0 else _gcf(a, x)


def chi2_cdf(x: float, nu: float) -> float:
    """Chi-square distribution function F(x; nu) = P(nu/2, x/2) (A&S 26.4.19)."""
    return 0.0 if x <= 0 else gammainc_p(0.5 * nu, 0.5 * x)


def chi2_sf(x: float, nu: float) -> float:
    """Chi-square survival function 1 - F(x; nu) = Q(nu/2, x/2), accurate in the upper tail."""
    return 1.0 if x <= 0 else gammainc_q(0.5 * nu, 0.5 * x)


_CF_NU = 2.0e6  # above this, the Cornish-Fisher expansion is exact to rounding and the series/CF are slow


def chi2_ppf(p: float, nu: float) -> float:
    """Chi-square quantile x with F(x; nu) = p, i.e. the inverse of P(nu/2, x/2) = p.

    y = x/2 solves P(a, y) = p (p <= 1/2) or Q(a, y) = 1 - p (p > 1/2, the tail that keeps its digits),
    a = nu/2, by Halley's method on the residual with derivative dP/dy = y^(a-1) e^-y / Gamma(a) and
    d2P/dy2 / (dP/dy) = (a - 1)/y - 1, safeguarded by a bracket (bisection when a step leaves it).
    Start: Wilson-Hilferty for a > 1, the small-y form y = (p Gamma(a + 1))^(1/a) otherwise.
    For nu > 2e6 the Cornish-Fisher expansion x = nu + z s + (2/3)(z^2 - 1) + (z^3 - 7z)/(9 s)
    - (6z^4 + 14z^2 - 32)/(405 nu) + (9z^5 + 256z^3 - 433z)/(4860 nu s), s = sqrt(2 nu), z = Phi^-1(p),
    whose neglected terms are O(nu^-2) (relative error < 1e-13).

    References: Press et al., *Numerical Recipes*, 3rd ed., section 6.2.1 (``invgammp``);
    Abramowitz & Stegun 26.4.17 (Wilson-Hilferty) and 26.2.49-26.4.18 (Cornish-Fisher).
    """
    p, nu = float(p), float(nu)
    if not nu > 0 or not 0.0 <= p <= 1.0:
        return math.nan
    if p == 0.0:
        return 0.0
    if p == 1.0:
        return math.inf
    if nu > _CF_NU:
        z = _STD_NORMAL.inv_cdf(p)
        s = math.sqrt(2.0 * nu)
        return (nu + z * s + (2.0 / 3.0) * (z * z - 1.0) + (z**3 - 7.0 * z) / (9.0 * s)
                - (6.0 * z**4 + 14.0 * z * z - 32.0) / (405.0 * nu)
                + (9.0 * z**5 + 256.0 * z**3 - 433.0 * z) / (4860.0 * nu * s))
    a = 0.5 * nu
    lower = p <= 0.5
    target = p if lower else 1.0 - p
    gln = math.lgamma(a)
    # starting point
    if a > 1.0:
        z = _STD_NORMAL.inv_cdf(p)
        y = max(1e-3 * a, a * (1.0 - 1.0 / (9.0 * a) + z / (3.0 * math.sqrt(a))) ** 3)
    else:
        t = 1.0 - a * (0.253 + a * 0.12)
        if p < t:
            y = math.exp((math.log(p) + math.lgamma(a + 1.0)) / a)
        else:
            y = 1.0 - math.log1p(-(p - t) / (1.0 - t))
    y = max(y, 1e-300)

    def resid(yv):  # increasing in y, zero at the root
        return gammainc_p(a, yv) - target if lower else target - gammainc_q(a, yv)

    lo, hi = 0.0, math.inf
    for _ in range(300):
        r = resid(y)
        if r == 0.0:
            return 2.0 * y
        if r < 0:
            lo = y
        else:
            hi = y
        try:
            dens = math.exp((a - 1.0) * math.log(y) - y - gln)
            step = r / dens
            step = step / max(1.0 - 0.5 * step * ((a - 1.0) / y - 1.0), 0.5)  # Halley, damped
            y_new = y - step
        except (OverflowError, ZeroDivisionError):
            y_new = math.nan
        if abs(y_new - y) <= 4.0 * _EPS * y:  # the residual is at rounding level: converged
            return 2.0 * y_new
        if not lo < y_new < hi:  # outside the bracket: bisect (geometrically over wide ranges)
            if math.isinf(hi):
                y_new = 2.0 * y if y > 0 else 1.0
            elif lo > 0 and hi > 4.0 * lo:
                y_new = math.sqrt(lo * hi)
            else:
                y_new = 0.5 * (lo + hi)
        if (hi - lo) <= 4.0 * _EPS * hi < math.inf:
            return 2.0 * y_new
        y = y_new
    return 2.0 * y
