"""Synthesis of every IEEE Std 952 noise effect as SI rate samples (numpy only).

Each synthesiser reproduces the analytic Allan variance of :mod:`companion.allan.terms` (checked in
tests/sim/test_synth.py over many seeds, tolerance from the EDF). Rate y_k is sampled at fs = 1/tau0;
PSDs are two-sided (IEEE Std 952-1997 Annex C).

=================  =====================================================================================
effect             synthesis
=================  =====================================================================================
white_noise        y_k ~ N(0, N^2 fs): two-sided PSD N^2, AVAR N^2/tau (eq. C.2)
quantization       angle quantisation: white angle error e_k of std Q, y_k = (e_{k+1} - e_k) fs, so the
                   integrated angle carries white error Q and AVAR = 3 Q^2 / tau^2 (eq. C.1).  (Rounding
                   the *rate* to an LSB is a different thing: white rate noise LSB^2/12, see analyze.)
bias_instability   flicker rate noise by spectral shaping: unit white noise of length L = 2^ceil(log2 4n)
                   is filtered in the frequency domain by |H(f)|^2 = fs (B^2 / 2 pi) / f, i.e. two-sided
                   PSD (B^2/2pi)/f (one-sided B^2/(pi f)) between the low cut-off f_L = fs/L (< 1/(4 T))
                   and the high cut-off f0 (the term's optional ``f0``, default fs/2); DC removed. (Sampling aliases a little: +40 % AVAR at tau0, <1 %
                   beyond 5 tau0.)  AVAR: the cosine-integral form with
                   f0 = fs/2 (thesis eq. (3.16)), i.e. the plateau 2 ln2/pi B^2 for tau >> tau0.
random_walk        y_k = sum_{j<=k} w_j, w_j ~ N(0, K^2 tau0): PSD (K/2pi)^2 / f^2, AVAR K^2 tau/3 (C.4);
                   sampled exactly: K^2 tau/3 (1 + 1/(2 m^2)), m = tau/tau0 (+50 % at tau0, +3 % at 4 tau0)
ramp               y_k = R t_k, t_k = k tau0: AVAR R^2 tau^2 / 2 (C.5)
gauss_markov       exact discretisation of the first-order Markov process: y_0 ~ N(0, sigma^2),
                   y_k = phi y_{k-1} + sqrt(1 - phi^2) sigma w_k, phi = exp(-tau0/tau_c) (C.6); the
                   recursion is evaluated as a log2(n)-step prefix scan (exact, vectorised)
sinusoid           y_k = A sin(2 pi f t_k + phi), phi uniform in [0, 2 pi) (C.7)
=================  =====================================================================================
"""

from __future__ import annotations

import math
from typing import Iterable, Mapping

import numpy as np


from companion.allan.terms import validate_term

#: Canonical axis order; each axis gets its own child of the model seed (order of YAML keys does not matter).
AXIS_ORDER = ("gx", "gy", "gz", "ax", "ay", "az")


def white_noise(N: float, rate_hz: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """White rate noise of two-sided PSD N^2: per-sample std N sqrt(fs)."""
    return rng.normal(0.0, N * math.sqrt(rate_hz), n)


def quantization(Q: float, rate_hz: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """Angle quantisation noise (IEEE 952 C.1): rate = fs * first difference of a white angle error of std Q."""
    e = rng.normal(0.0, Q, n + 1)
    return np.diff(e) * rate_hz


def flicker(B: float, rate_hz: float, n: int, rng: np.random.Generator, f0: float | None = None) -> np.ndarray:
    """Flicker (1/f) rate noise, two-sided PSD (B^2 / 2 pi) / f for fs/L <= |f| <= f0 (L >= 4 n); the
    cut-off ``f0`` defaults to fs/2 (the whole band) and must lie in (0, fs/2]."""
    L = 1 << int(math.ceil(math.log2(max(4 * n, 2))))
    w = rng.standard_normal(L)
    W = np.fft.rfft(w)
    f = np.fft.rfftfreq(L, d=1.0 / rate_hz)
    H = np.zeros_like(f)
    H[1:] = np.sqrt(rate_hz * B**2 / (2.0 * math.pi * f[1:]))
    if f0 is not None:
        H[f > f0] = 0.0
    return np.fft.irfft(W * H, n=L)[:n]


def random_walk(K: float, rate_hz: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """Rate random walk: cumulative sum of white increments of variance K^2 tau0."""
    return np.cumsum(rng.normal(0.0, K / math.sqrt(rate_hz), n))


def ramp(R: float, rate_hz: float, n: int) -> np.ndarray:
    """Rate ramp R t."""
    return R * np.arange(n) / rate_hz


def gauss_markov(sigma: float, tau_c: float, rate_hz: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """Exact discrete first-order Gauss-Markov process (stationary start).

    y_k = phi y_{k-1} + e_k, phi = exp(-tau0/Tc), e_0 ~ N(0, sigma^2), e_k ~ N(0, (1 - phi^2) sigma^2).
    Solved by a prefix scan: after the passes s = 1, 2, 4, ..., y_k = sum_{j < 2s} phi^j e_{k-j}; stops
    once phi^s < 1e-18 (the omitted weights are below double precision) or s >= n.
    """
    phi = math.exp(-1.0 / (rate_hz * tau_c))
    y = rng.normal(0.0, sigma * math.sqrt(max(1.0 - phi * phi, 0.0)), n)
    if n:
        y[0] = rng.normal(0.0, sigma)
    s, ps = 1, phi
    while s < n and ps > 1e-18:
        y[s:] = y[s:] + ps * y[:-s]
        s *= 2
        ps *= ps
    return y


def sinusoid(amplitude: float, freq_hz: float, rate_hz: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """A sin(2 pi f t + phi) with a uniformly random phase phi."""
    phase = rng.uniform(0.0, 2.0 * math.pi)
    return amplitude * np.sin(2.0 * math.pi * freq_hz * np.arange(n) / rate_hz + phase)


def check_term_rate(term: Mapping, rate_hz: float) -> None:
    """Terms that cannot be sampled at ``rate_hz`` (ValueError): a sinusoid at or above the Nyquist frequency
    (it would alias to a lower one), a bias-instability cut-off f0 above it."""
    nyquist = rate_hz / 2.0
    e = term["effect"]
    if e == "sinusoid" and term["freq_hz"] >= nyquist:
        f = float(term["freq_hz"])
        alias = abs(f - rate_hz * round(f / rate_hz))
        raise ValueError(f"sinusoid freq_hz {f:g} is at or above the Nyquist frequency {nyquist:g} Hz of rate_hz "
                         f"{rate_hz:g} (it would show up at {alias:g} Hz); use freq_hz < {nyquist:g}")
    if e == "bias_instability" and term.get("f0") is not None and not 0 < term["f0"] <= nyquist * (1 + 1e-9):
        raise ValueError(f"bias_instability f0 {term['f0']:g} Hz must be in (0, {nyquist:g}] (rate_hz / 2)")


def check_model_rate(model) -> None:
    """:func:`check_term_rate` for every term of a model, the axis named in the message (ValueError)."""
    rate_hz = float(model["rate_hz"] if isinstance(model, Mapping) else model.rate_hz)
    axes = model["axes"] if isinstance(model, Mapping) else model.axes
    for axis, terms in axes.items():
        for term in terms:
            try:
                check_term_rate(term, rate_hz)
            except ValueError as exc:
                raise ValueError(f"axis {axis}: {exc}") from None


def synthesize_term(term: Mapping, rate_hz: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """Rate samples (SI) of one term dict, e.g. ``{"effect": "white_noise", "N": 1e-3}``."""
    validate_term(term)
    e = term["effect"]
    if e == "white_noise":
        return white_noise(term["N"], rate_hz, n, rng)
    if e == "quantization":
        return quantization(term["Q"], rate_hz, n, rng)
    check_term_rate(term, rate_hz)
    if e == "bias_instability":
        return flicker(term["B"], rate_hz, n, rng, term.get("f0"))
    if e == "random_walk":
        return random_walk(term["K"], rate_hz, n, rng)
    if e == "ramp":
        return ramp(term["R"], rate_hz, n)
    if e == "gauss_markov":
        return gauss_markov(term["sigma"], term["tau_c"], rate_hz, n, rng)
    if e == "sinusoid":
        return sinusoid(term["amplitude"], term["freq_hz"], rate_hz, n, rng)
    raise ValueError(f"unknown effect {e!r}")  # unreachable after validate_term


def synthesize_axis(terms: Iterable[Mapping], rate_hz: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """Sum of independent terms: ``n`` SI rate samples at ``rate_hz`` (AVARs add, IEEE 952)."""
    if rate_hz <= 0:
        raise ValueError("rate_hz must be positive")
    y = np.zeros(int(n))
    for term in terms:
        y += synthesize_term(term, rate_hz, int(n), rng)
    return y


def simulate_model(model, duration_s: float, seed: int | None = 0) -> dict[str, np.ndarray]:
    """Synthesise every axis of a model for ``duration_s`` seconds: ``{axis: rate samples}``.

    ``model`` is a :class:`companion.sim.model.NoiseModel` or a dict ``{"rate_hz": .., "axes": {..}}``.
    Each axis draws from its own child of ``SeedSequence(seed)`` (indexed by its canonical position
    gx, gy, gz, ax, ay, az), so an axis' samples do not depend on which other axes are present.
    """
    rate_hz = float(model["rate_hz"] if isinstance(model, Mapping) else model.rate_hz)
    axes = model["axes"] if isinstance(model, Mapping) else model.axes
    n = int(round(duration_s * rate_hz))
    children = np.random.SeedSequence(seed).spawn(len(AXIS_ORDER))
    out = {}
    for axis, terms in axes.items():
        idx = AXIS_ORDER.index(axis) if axis in AXIS_ORDER else len(AXIS_ORDER)
        seq = children[idx] if idx < len(children) else np.random.SeedSequence([seed or 0, abs(hash(axis)) % 2**32])
        out[axis] = synthesize_axis(terms, rate_hz, n, np.random.default_rng(seq))
    return out


#: standard gravity, m/s^2: the accelerometer of a level vehicle at rest when a model lists no accel axis
STANDARD_GRAVITY = 9.80665


def imu_arrays(model, duration_s: float, seed: int | None = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, gyro (n, 3), accel (n, 3))`` in SI for a noise model: the axes it lists synthesised, the others 0;
    with no accelerometer axis at all, az = -g (a level vehicle at rest)."""
    from companion.samples import ACCEL_AXES, GYRO_AXES

    data = simulate_model(model, duration_s, seed)
    n = int(round(duration_s * model.rate_hz))
    t = np.arange(n) / model.rate_hz
    gyro = np.column_stack([data.get(a, np.zeros(n)) for a in GYRO_AXES])
    accel = np.column_stack([data.get(a, np.zeros(n)) for a in ACCEL_AXES])
    if not any(a in model.axes for a in ACCEL_AXES):
        accel[:, 2] = -STANDARD_GRAVITY
    return t, gyro, accel
