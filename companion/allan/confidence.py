"""Confidence of overlapping Allan variance estimates: equivalent degrees of freedom and chi-square intervals.

Two ways to the EDF, both published:

* :func:`edf_simple`: the approximations of Howe, Allan & Barnes (1981) tabulated in NIST SP 1065
  (Riley 2008), Table 5 ("Simple EDF approximations for the overlapping Allan variance"), one formula per
  power-law noise alpha = 2 (white PM), 1 (flicker PM), 0 (white FM), -1 (flicker FM), -2 (random-walk FM),
  with N the number of *phase* points and m the averaging factor.
* :func:`oavar_covariance` / :func:`edf_model`: the exact second moments of the overlapping estimator for
  Gaussian noise with a *given* mixture of terms -- the computation Greenhall's EDF (Greenhall & Riley
  2003, "Uncertainty of stability variances based on finite differences") carries out for one power law,
  here for the sum of the IEEE 952 terms actually fitted, and also across cluster sizes (the covariance of
  the estimates at tau_m and tau_m', which the fit needs because neighbouring points are strongly
  correlated). With the second differences d_i(m) = x_{i+2m} - 2 x_{i+m} + x_i of the phase x and
  M = N_phase - 2m of them,

      v_m = sum_i d_i(m)^2 / (2 tau_m^2 M),
      Cov(v_m, v_m') = 2 sum_{i<M} sum_{j<M'} c(j - i)^2 / (4 tau_m^2 tau_m'^2 M M'),
      c(l) = Cov(d_0(m), d_l(m')) = sum_p sum_q a_p b_q G(l + q - p),

  with the taps a = (1, -2, 1) at (0, m, 2m), b at (0, m', 2m') and G the generalised covariance of the
  phase of each term (h in samples, tau0 = 1/fs); independent terms add in G:

      quantization      G = Q^2 [h = 0]                          (white PM)
      white_noise       G = -N^2 tau0 |h| / 2                     (white FM)
        with filter_hz  G = -D(|h| tau0) / 2, D the phase structure function of the filtered white noise
                        (companion.allan.filtered_white.phase_structure_white)
      bias_instability  G = (B^2 tau0^2 / 2 pi) h^2 ln|h|         (flicker FM)
      random_walk       G = K^2 tau0^3 |h|^3 / 12                 (random-walk FM)
      gauss_markov      G = -sigma^2 Tc^2 (u - 1 + e^-u), u = |h| tau0 / Tc
      sinusoid          G = A^2 / (2 w^2) cos(w h tau0), w = 2 pi f (random phase, Gaussian approximation)

  Each G reproduces its AVAR of :mod:`companion.allan.terms` exactly through 6 G(0) - 8 G(m) + 2 G(2m) =
  2 tau^2 sigma^2(tau). A deterministic ramp R adds d_r = R tau^2 to every d_i and the cross term
  4 d_r(m) d_r(m') sum sum c(j - i) / (4 tau^2 tau'^2 M M'). Then EDF = 2 v_m^2 / Var(v_m).

Intervals (:func:`adev_ci`): v_hat EDF / v ~ chi^2(EDF), so the ``level`` interval of ADEV is
[adev sqrt(EDF / chi2_{(1+level)/2}), adev sqrt(EDF / chi2_{(1-level)/2})] (NIST SP 1065 eq. (37)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping, NamedTuple

import numpy as np

from companion.allan.memo import BoundedMemo, release_free_memory

#: power-law exponent alpha of the rate PSD (S_y ~ f^alpha) for the effects that are power laws
ALPHA = {"quantization": 2, "white_noise": 0, "bias_instability": -1, "random_walk": -2}


def edf_simple(n_phase, m, alpha) -> np.ndarray:
    """EDF of the overlapping AVAR, NIST SP 1065 Table 5 (Howe, Allan & Barnes 1981).

    ``n_phase``: number of phase points (rate samples + 1); ``m``: averaging factor(s); ``alpha`` in
    {2, 1, 0, -1, -2}. Matches ``allantools.edf_simple``.
    """
    N = float(n_phase)
    m = np.asarray(m, dtype=float)
    if alpha == 2:
        edf = (N + 1.0) * (N - 2.0 * m) / (2.0 * (N - m))
    elif alpha == 1:
        edf = np.exp(np.sqrt(np.log((N - 1.0) / (2.0 * m)) * np.log((2.0 * m + 1.0) * (N - 1.0) / 4.0)))
    elif alpha == 0:
        edf = (3.0 * (N - 1.0) / (2.0 * m) - 2.0 * (N - 2.0) / N) * 4.0 * m**2 / (4.0 * m**2 + 5.0)
    elif alpha == -1:
        edf = np.where(m == 1, 2.0 * (N - 2.0) / (2.3 * N - 4.9), 5.0 * N**2 / (4.0 * m * (N + 3.0 * m)))
    elif alpha == -2:
        edf = (N - 2.0) / m * ((N - 1.0) ** 2 - 3.0 * m * (N - 1.0) + 4.0 * m**2) / (N - 3.0) ** 2
    else:
        raise ValueError(f"alpha must be one of 2, 1, 0, -1, -2, got {alpha!r}")
    return edf


def adev_ci(adev, edf, level: float = 0.95):
    """Chi-square interval ``(lo, hi)`` of an Allan deviation estimate with ``edf`` degrees of freedom.

    The EDF is floored at 1 (one squared second difference: the last cluster time of a record), which
    keeps the upper end finite.
    """
    # the pure-Python quantile, not scipy.stats: importing scipy.stats costs 0.7-1.4 s of CPU at start-up (more
    # on a small board) and `analyze` needs nothing else from it
    from companion.allan.special import chi2_ppf

    adev = np.asarray(adev, dtype=float)
    edf = np.asarray(edf, dtype=float)
    edf = np.where(np.isfinite(edf), np.maximum(edf, 1.0), 1e12)
    a = (1.0 - level) / 2.0
    q_hi = np.array([chi2_ppf(1.0 - a, v) for v in edf.ravel()]).reshape(edf.shape)
    q_lo = np.array([chi2_ppf(a, v) for v in edf.ravel()]).reshape(edf.shape)
    lo = adev * np.sqrt(edf / q_hi)
    hi = adev * np.sqrt(edf / q_lo)
    return lo, hi


def _gcov(term: Mapping, h: np.ndarray, tau0: float):
    """Generalised covariance G(h) of the phase of one term (see the module docstring); None if deterministic."""
    e = term["effect"]
    ah = np.abs(h).astype(float)
    if e == "quantization":
        return None  # white phase: summed exactly in _quantization_sums
    if e == "white_noise":
        if term.get("filter_hz"):
            # low-pass filtered white noise: G = -D/2 with the phase structure function D of the term
            from companion.allan.filtered_white import phase_structure_white

            return -0.5 * phase_structure_white(ah * tau0, term["N"], term["filter_hz"], term.get("sample_hz"),
                                                int(term.get("filter_order") or 2))
        return -0.5 * term["N"] ** 2 * tau0 * ah
    if e == "bias_instability":
        with np.errstate(divide="ignore", invalid="ignore"):
            g = ah**2 * np.log(np.where(ah > 0, ah, 1.0))
        return term["B"] ** 2 * tau0**2 / (2.0 * math.pi) * g
    if e == "random_walk":
        return term["K"] ** 2 * tau0**3 * ah**3 / 12.0
    if e == "gauss_markov":
        Tc = float(term["tau_c"])
        u = ah * tau0 / Tc
        return -term["sigma"] ** 2 * Tc**2 * (u - 1.0 + np.exp(-u))
    if e == "sinusoid":
        w = 2.0 * math.pi * term["freq_hz"]
        return term["amplitude"] ** 2 / (2.0 * w * w) * np.cos(w * ah * tau0)
    return None  # ramp: deterministic


def _tail(terms, m2: int, tau0: float) -> int:
    """How far beyond the filter support c(l) must be summed for the long-memory terms."""
    t = 0
    for term in terms:
        e = term["effect"]
        if e in ("bias_instability", "sinusoid"):
            t = max(t, 8 * m2)
        elif e == "gauss_markov":
            t = max(t, min(8 * m2, int(math.ceil(30.0 * term["tau_c"] / tau0))))
        elif e == "white_noise" and term.get("filter_hz"):
            t = max(t, min(8 * m2, int(math.ceil(3.0 / (term["filter_hz"] * tau0)))))
    return t


#: the magnitude each term's G is proportional to (G of a term is its magnitude^2 times G of the unit term)
_MAGNITUDE = {"white_noise": "N", "bias_instability": "B", "random_walk": "K", "gauss_markov": "sigma",
              "sinusoid": "amplitude"}
#: pair sums per (pair geometry, term shapes): a fit asks for the same ones many times (each iteration, each
#: re-selection of the online report as the record grows)
_PAIR_FORMS = BoundedMemo(8192)


@dataclass(frozen=True)
class _Mixture:
    """The terms of a covariance as the pair sums use them, made once per matrix: the kernel terms, their squared
    magnitudes a (the quantization's Q^2 last when present) and shapes (:func:`_shape`)."""

    kern: list
    has_q: bool
    a: np.ndarray
    shapes: tuple

    @classmethod
    def of(cls, terms) -> "_Mixture":
        kern = [t for t in terms if t["effect"] in _MAGNITUDE]
        Q2 = sum(t["Q"] ** 2 for t in terms if t["effect"] == "quantization")
        a = np.array([float(t[_MAGNITUDE[t["effect"]]]) ** 2 for t in kern] + ([Q2] if Q2 else []))
        return cls(kern, bool(Q2), a, tuple(_shape(t) for t in kern))


def _pair_sums(terms, m1: int, m2: int, M1: int, M2: int, tau0: float, step_div: int = 32):
    """(sum_ij c(j-i)^2, sum_ij c(j-i)) for cluster sizes m1 <= m2 (Riemann sum with step ~ m1/step_div);
    ``terms``: the term dicts or their :class:`_Mixture`.

    c is linear in the terms' squared magnitudes a_k (c = sum a_k c_k, c_k of the unit term), and the number
    of pairs at lag l is M1 + f(l) with f fixed by m1 and m2 (M1 - M2 = 2 (m2 - m1)) while the lags stay
    within the record; so both sums are quadratic / linear forms in a with M1 as a factor:
    s2 = step (M1 a'G0 a + a'Gf a), s1 = step (M1 h0'a + hf'a). The forms depend only on the pair's geometry
    and the terms' shapes (filter, tau_c, frequency) and are remembered. Lags clipped by a short record
    (the longest cluster sizes) are summed with their own counts and not remembered."""
    mix = terms if isinstance(terms, _Mixture) else _Mixture.of(terms)
    if mix.a.size == 0:
        return 0.0, 0.0
    return _sums_of(_pair_plan(mix, m1, m2, M1, M2, tau0, step_div), mix.a)


def _sums_of(plan, a) -> tuple[float, float]:
    """(s2, s1) of :func:`_pair_sums` from a pair's forms and ``mm`` (:func:`_pair_plan`) and magnitudes ``a``."""
    (G0, Gf, h0, hf), mm = plan
    return float(mm * (a @ G0 @ a) + a @ Gf @ a), float(mm * (h0 @ a) + hf @ a)


def _pair_plan(mix: "_Mixture", m1: int, m2: int, M1: int, M2: int, tau0: float, step_div: int = 32):
    """The forms (G0, Gf, h0, hf) of one pair for the mixture's shapes and the factor ``mm`` of G0 and h0 (M1 where
    the lags stay within the record, else 0: see :func:`_pair_sums`)."""
    kern, has_q = mix.kern, mix.has_q
    tail = _tail(kern, m2, tau0) if m2 <= 16 * m1 else 0  # long-memory tails: only near pairs correlate
    lo0, hi0 = -(2 * m2 + tail), 2 * m1 + tail
    lo, hi = max(lo0, -(M1 - 1)), min(hi0, M2 - 1)
    inside = lo == lo0 and hi == hi0
    if inside:
        key = (m1, m2, M1 - M2, lo, hi, tau0, step_div, mix.shapes, has_q)
        forms = _PAIR_FORMS.get(key, lambda: _pair_forms(kern, has_q, m1, m2, M1, M2, lo, hi, tau0, step_div,
                                                          inside))
    else:
        forms = _pair_forms(kern, has_q, m1, m2, M1, M2, lo, hi, tau0, step_div, inside)
    return forms, (float(M1) if inside else 0.0)


#: c_k(l) of one unit term per pair geometry: a fit's iterations change one term's shape (a Gauss-Markov tau_c)
#: and keep the others', whose rows (the costly part of a pair's forms) are then looked up. 24 MB holds the rows
#: of one axis' fit (13 MB on average for 1 M samples); other axes share few of them (:func:`forget_rows`)
_UNIT_ROWS = BoundedMemo(1 << 16, read_only=True, max_bytes=24 << 20)


def forget_rows() -> None:
    """Drop the remembered unit-term rows and give the freed pages back: called when one record's analysis is
    done (another record's filter and Gauss-Markov shapes differ, so its rows would only hold memory)."""
    _UNIT_ROWS.clear()
    release_free_memory()


def _shape(term: Mapping) -> tuple:
    """What fixes a term's G up to its magnitude."""
    return (term["effect"], term.get("filter_hz"), term.get("sample_hz"), term.get("filter_order"), term.get("tau_c"),
            term.get("freq_hz"))


class _Lags(NamedTuple):
    """The lags of one pair's rows: ``l`` with the tap ``shift`` and ``weight``; where every shift is a multiple of
    the ``step``, the nine rows of lags l + shift are shifted copies of one ``grid`` of spacing ``step`` (the row
    ``offsets`` into it), filled into the one ``rows`` buffer of the pair."""

    l: np.ndarray
    shift: np.ndarray
    weight: np.ndarray
    grid: np.ndarray | None
    offsets: list | None
    rows: np.ndarray | None

    @classmethod
    def of(cls, l, shift, weight, step) -> "_Lags":
        if not np.all(shift % step == 0):
            return cls(l, shift, weight, None, None, None)
        lo_shift = int(shift.min())
        grid = np.arange(l[0] + lo_shift, l[-1] + int(shift.max()) + 1, step, dtype=np.int64)
        offsets = ((shift - lo_shift) // step).tolist()
        return cls(l, shift, weight, grid, offsets, np.empty((shift.shape[0], l.shape[0])))


def _unit_row(term, lags: _Lags, tau0) -> np.ndarray:
    """c(l) = sum_pq a_p b_q G(l + q - p) of one unit term at the lags of ``lags``."""
    if lags.grid is not None:
        # the term evaluated once per grid point (a quarter to a ninth of the lags), the rows its slices (the
        # same matrix an index array gathers, at half the cost)
        g = _gcov(term, lags.grid, tau0)
        rows, n = lags.rows, lags.l.shape[0]
        for r, o in enumerate(lags.offsets):
            rows[r] = g[o:o + n]
        return lags.weight @ rows
    return lags.weight @ _gcov(term, lags.l[None, :] + lags.shift[:, None], tau0)


def _pair_forms(kern, has_q, m1, m2, M1, M2, lo, hi, tau0, step_div, inside):
    """(G0, Gf, h0, hf) of :func:`_pair_sums` for the unit terms ``kern`` (+ a unit quantization term last
    when ``has_q``) over lags lo..hi; with ``inside`` False the counts are the record's own and G0, h0 zero."""
    step = max(1, m1 // step_div)
    if not inside:
        # the record clips the lags: the pair counts then change over the number of clusters M, not over m,
        # and the sum of c (the ramp's cross term) is a difference of large parts. A step of m1/32 where M is
        # 10 clusters put s1 of the longest cluster size (512 of 1033 samples) 37 % low, its correlation with
        # the next point above 1 (not a covariance) and a ramp's interval 30x too narrow
        step = max(1, min(step, min(M1, M2) // step_div))
    l = np.arange(lo, hi + 1, step, dtype=np.int64)
    taps_a = ((0, 1.0), (m1, -2.0), (2 * m1, 1.0))
    taps_b = ((0, 1.0), (m2, -2.0), (2 * m2, 1.0))
    # the nine tap pairs in one call per term: offsets q - p and weights a_p b_q
    shift = np.array([q - p for p, _ in taps_a for q, _ in taps_b], dtype=np.int64)
    weight = np.array([ap * bq for _, ap in taps_a for _, bq in taps_b])
    unit = [dict(t, **{_MAGNITUDE[t["effect"]]: 1.0}) for t in kern]
    k = len(unit) + (1 if has_q else 0)
    C = np.zeros((k, l.shape[0]))
    lags = None
    for i, term in enumerate(unit):
        key = (_shape(term), m1, m2, lo, hi, step, tau0)
        row = _UNIT_ROWS.peek(key)
        if row is None:
            lags = lags or _Lags.of(l, shift, weight, step)  # once per pair, for the rows not remembered
            row = _UNIT_ROWS.get(key, lambda term=term: _unit_row(term, lags, tau0))
        C[i] = row
    # pairs (i, j), 0 <= i < M1, 0 <= j < M2, with j - i = l: M1 + f(l) within the record
    count = (np.minimum(M1 - 1, M2 - 1 - l) - np.maximum(0, -l) + 1).astype(float)
    f = count - M1 if inside else np.maximum(count, 0.0)
    G0 = step * (C @ C.T) if inside else np.zeros((k, k))
    Gf = step * ((C * f) @ C.T)
    h0 = step * C.sum(axis=1) if inside else np.zeros(k)
    hf = step * (C @ f)
    if has_q:
        # white phase: c_Q(l) = Q^2 sum a_p b_q [l = p - q], spikes at nine lags; the smooth part c(l) is
        # evaluated there exactly (cross term 2 c c_Q) and the spikes add c_Q^2 -- in place of the Riemann
        # sum's row for Q (which is zero: _gcov has no smooth part for quantization).
        # the spikes' lags are the nine -shift (some coincide when m2 is a multiple of m1): weights summed per lag
        lag, at = np.unique(-shift, return_inverse=True)
        cq = np.bincount(at, weights=weight)
        lag, cq = lag[cq != 0.0], cq[cq != 0.0]
        cnt = (np.minimum(M1 - 1, M2 - 1 - lag) - np.maximum(0, -lag) + 1).astype(float)
        fq = cnt - M1 if inside else np.maximum(cnt, 0.0)
        cs = np.zeros((k - 1, lag.shape[0]))
        for i, term in enumerate(unit):
            cs[i] = _gcov(term, lag[:, None] + shift[None, :], tau0) @ weight
        q = k - 1
        if inside:
            G0[q, :q] = G0[:q, q] = cs @ cq
            G0[q, q] = cq @ cq
            h0[q] = cq.sum()
        Gf[q, :q] = Gf[:q, q] = cs @ (fq * cq)
        Gf[q, q] = (fq * cq) @ cq
        hf[q] = fq @ cq
    return G0, Gf, h0, hf


def oavar_covariance(terms: Iterable[Mapping], m, n: int, rate_hz: float, max_ratio: int = 256) -> np.ndarray:
    """Covariance matrix of the overlapping AVAR estimates at cluster sizes ``m`` for ``n`` rate samples
    of Gaussian noise made of ``terms`` (SI term dicts). Pairs farther apart than ``max_ratio`` in m are
    taken as uncorrelated (their correlation is small)."""
    terms = list(terms)
    m = np.asarray(m, dtype=np.int64)
    tau0 = 1.0 / rate_hz
    n_phase = int(n) + 1
    M = n_phase - 2 * m
    tau = m * tau0
    ramp = sum(t["R"] for t in terms if t["effect"] == "ramp") if terms else 0.0
    ramp_sq = sum(t["R"] ** 2 for t in terms if t["effect"] == "ramp")
    k = m.shape[0]
    cov = np.zeros((k, k))
    mix = _Mixture.of(terms)
    plans = _matrix_plan(mix, m, M, tau0, max_ratio) if mix.a.size else None
    for i in range(k):
        for j in range(i, k):
            if m[j] > max_ratio * m[i]:
                break
            s2, s1 = _sums_of(plans[(i, j)], mix.a) if plans is not None else (0.0, 0.0)
            v = 2.0 * s2
            if ramp_sq:
                v += 4.0 * ramp_sq * tau[i] ** 2 * tau[j] ** 2 * s1
            cov[i, j] = cov[j, i] = v / (4.0 * tau[i] ** 2 * tau[j] ** 2 * M[i] * M[j])
    del ramp
    return cov


#: every pair's plan of one covariance matrix, by its cluster sizes, record and the terms' shapes: a fit asks for
#: the matrix of the same shapes many times with new magnitudes only, and the per-pair look-ups cost more than the
#: two quadratic forms each pair then needs
_MATRIX_PLANS = BoundedMemo(512)


def _matrix_plan(mix: _Mixture, m: np.ndarray, M: np.ndarray, tau0: float, max_ratio: int) -> dict:
    """{(i, j): :func:`_pair_plan`} of the pairs :func:`oavar_covariance` sums (j >= i, m_j <= max_ratio m_i)."""
    key = (tuple(m.tolist()), tuple(M.tolist()), tau0, max_ratio, mix.shapes, mix.has_q)

    def build() -> dict:
        out = {}
        for i in range(m.shape[0]):
            for j in range(i, m.shape[0]):
                if m[j] > max_ratio * m[i]:
                    break
                out[(i, j)] = _pair_plan(mix, int(m[i]), int(m[j]), int(M[i]), int(M[j]), tau0)
        return out

    return _MATRIX_PLANS.get(key, build)


def edf_model(terms: Iterable[Mapping], m, n: int, rate_hz: float) -> np.ndarray:
    """EDF of each overlapping AVAR estimate for a noise made of ``terms``: 2 sigma^4 / Var(v_m)."""
    from companion.allan.terms import avar_model

    terms = list(terms)
    m = np.asarray(m, dtype=np.int64)
    avar = avar_model(terms, m / rate_hz)
    var = np.array([_var_one(terms, int(mi), n, rate_hz) for mi in m])
    with np.errstate(divide="ignore", invalid="ignore"):
        edf = np.where(var > 0, 2.0 * avar**2 / np.where(var > 0, var, 1.0), np.inf)
    return edf


def _var_one(terms, m: int, n: int, rate_hz: float) -> float:
    return float(oavar_covariance(terms, [m], n, rate_hz)[0, 0])


#: flicker_sampling_excess by cluster size: each costs a spectral sum and the fits ask for the same few m
_FLICKER_EXCESS: dict[int, float] = {}


def flicker_sampling_excess(m) -> np.ndarray:
    """Relative departure of a *sampled* flicker rate noise's AVAR from the plateau (2 ln2 / pi) B^2 at cluster
    size ``m``: the discrete sequence whose two-sided PSD is (B^2 / 2 pi) / |f| up to the Nyquist frequency
    (the power above it folded in, as sampling without an anti-alias filter does) has
    sigma^2(m) = int_{-1/2}^{1/2} S(f) 2 sin^4(pi f m) / (m^2 sin^2(pi f)) df (fs = 1): +18.9 % at m = 1,
    +8.9 % at 2, +2.9 % at 4, +0.9 % at 8, below 0.1 % past 64 (taken as 0 there). A flicker band-limited
    below the Nyquist frequency (a filter) lies below the plateau at the same m instead, so the fit counts
    this excess as the size of an uncertain shape, not as a correction."""
    m = np.atleast_1d(np.asarray(m, dtype=np.int64))
    out = np.zeros(m.shape[0])
    for i, mi in enumerate(m):
        mi = int(mi)
        if mi < 1 or mi > 64:
            continue
        r = _FLICKER_EXCESS.get(mi)
        if r is None:
            # midpoint rule, 2000 points per lobe of sin^4(pi f m): the integrand is smooth (~ f near 0)
            k = 2000 * mi
            f = (np.arange(k) + 0.5) * (0.5 / k)
            g = (1.0 / (2.0 * math.pi * f)) * 4.0 * np.sin(math.pi * f * mi) ** 4 / (mi * mi * np.sin(math.pi * f) ** 2)
            r = float(g.sum() * (0.5 / k)) / (2.0 * math.log(2.0) / math.pi) - 1.0
            _FLICKER_EXCESS[mi] = r
        out[i] = r
    return out
