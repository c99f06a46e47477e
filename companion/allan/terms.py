"""Analytic Allan variance of each noise effect (IEEE Std 952-1997, Annex C; rate data, two-sided PSDs).

One canonical vocabulary across code, JSON and YAML. A *term* is a dict such as
``{"effect": "white_noise", "N": 1e-3}``; every parameter is SI (rad, rad/s, s, Hz for gyros;
m/s, m/s^2 for accelerometers).

=================  ======================  =====================================================
effect             parameters              AVAR sigma^2(tau)
=================  ======================  =====================================================
quantization       Q (rad)                 3 Q^2 / tau^2
white_noise        N (rad/s/sqrt(Hz)),     N^2 / tau; with a low-pass filter: see avar_white_noise
                   [filter_hz, sample_hz,
                   filter_order]
bias_instability   B (rad/s), [f0 (Hz)]    (2 ln2 / pi) B^2 (plateau), or the cosine-integral form
random_walk        K (rad/s^1.5)           K^2 tau / 3
ramp               R (rad/s^2)             R^2 tau^2 / 2
gauss_markov       sigma (rad/s), tau_c    (qc Tc)^2/tau [1 - Tc/(2 tau)(3 - 4 e^(-tau/Tc) + e^(-2 tau/Tc))],
                   (s)                     qc^2 = 2 sigma^2 / Tc
sinusoid           amplitude (rad/s),      A^2 [sin^2(pi f0 tau) / (pi f0 tau)]^2
                   freq_hz (Hz)
=================  ======================  =====================================================

References: IEEE Std 952-1997 Annex C; Miao et al. 2014 eq. (2.1)-(2.5) and (3.6) (note: their eq. (2.3)
misprints the bias-instability AVAR; eq. (3.6)'s 2 ln2 B^2 / pi is used); the thesis seed eq. (3.16) for
the cosine-integral bias-instability form, restored in ../shared/REFERENCE.md:
sigma^2 = (2 B^2/pi) [ln2 - sin^3 x/(2 x^2) (sin x + 4 x cos x) + Ci(2x) - Ci(4x)], x = pi f0 tau.
"""

from __future__ import annotations

import math
from typing import Iterable, Mapping

import numpy as np

from companion.allan.filtered_white import aliasing_gain, avar_filtered_white

#: the canonical effects (docs/architecture.md), in the order a model lists them
EFFECTS = (
    "quantization",
    "white_noise",
    "bias_instability",
    "random_walk",
    "ramp",
    "gauss_markov",
    "sinusoid",
)

#: Required parameters per effect (in this order), then optional ones.
PARAMS: dict[str, tuple[str, ...]] = {
    "quantization": ("Q",),
    "white_noise": ("N",),
    "bias_instability": ("B",),
    "random_walk": ("K",),
    "ramp": ("R",),
    "gauss_markov": ("sigma", "tau_c"),
    "sinusoid": ("amplitude", "freq_hz"),
}
#: the keys of a white-noise term's low-pass filter (``filter_order`` 2 when absent)
FILTER_KEYS = ("filter_hz", "sample_hz", "filter_order")
OPTIONAL_PARAMS: dict[str, tuple[str, ...]] = {"bias_instability": ("f0",), "white_noise": FILTER_KEYS}

#: The five linear terms of Miao et al. 2014, x = [Q N B K R], eq. (3.5).
LINEAR_EFFECTS = ("quantization", "white_noise", "bias_instability", "random_walk", "ramp")
#: the usual gyro model (IEEE 952): every subset of these is compared by BIC (companion.allan.fit)
BASE_EFFECTS = ("white_noise", "bias_instability", "random_walk")
#: the magnitude parameter of each linear effect (its square is the design column's coefficient)
LINEAR_PARAM = {"quantization": "Q", "white_noise": "N", "bias_instability": "B", "random_walk": "K", "ramp": "R"}

BIAS_PLATEAU = 2.0 * math.log(2.0) / math.pi  # 0.4413: AVAR plateau / B^2 (ADEV plateau 0.6643 B)


def avar_quantization(tau, Q):
    """Quantization noise: sigma^2 = 3 Q^2 / tau^2 (IEEE 952 C.1; Miao eq. (2.1))."""
    tau = np.asarray(tau, dtype=float)
    return 3.0 * Q**2 / tau**2


def avar_white_noise(tau, N, filter_hz=None, sample_hz=None, filter_order=2):
    """Angle (velocity) random walk, white rate noise of two-sided PSD N^2: sigma^2 = N^2 / tau (IEEE 952 C.2).

    With ``filter_hz``: the same white noise seen through a Butterworth low-pass of cut-off f_c and order
    ``filter_order`` (2: the LowPassFilter2p of ArduPilot's INS_GYRO_FILTER and PX4's IMU_GYRO_CUTOFF, run far
    above f_c; 1: a first-order roll-off, the shape of a Gauss-Markov process of tau_c = 1 / (2 pi f_c)), either

    * point-sampled (decimated) at ``sample_hz`` (ArduPilot DataFlash IMU, sensor_gyro), or
    * averaged over each sample interval (``sample_hz`` None: PX4 sensor_combined = delta angle / dt; the AVAR
      of averaged samples at tau = m tau0 equals the continuous-time one).

    sigma^2(tau) = (4 D(tau) - D(2 tau)) / (2 tau^2), D(t) = E[(x(t0 + t) - x(t0))^2] the phase structure
    function (:mod:`companion.allan.filtered_white`, the one implementation of filtered white noise).
    Equivalently, for two-sided PSD S(f) = N^2 |H(f)|^2,
    sigma^2(tau) = 2 int_{-inf}^{inf} S(f) sin^4(pi f tau) / (pi f tau)^2 df (IEEE 952 eq. C.2's general form;
    NIST SP 1065 eq. (65) one-sided), with aliasing of S into [-fs/2, fs/2] for point sampling, which the
    autocovariance form carries exactly. It tends to N^2 / tau for tau >> 1/f_c: N keeps its meaning (the
    white level of the logged samples, the plateau of ADEV sqrt(tau)).
    """
    tau = np.asarray(tau, dtype=float)
    if not filter_hz:
        return N**2 / tau
    # the white level of the logged samples is N: the density before the filter is N / sqrt(aliasing gain)
    order = int(filter_order)
    return avar_filtered_white(tau, N / math.sqrt(aliasing_gain(filter_hz, sample_hz, order)), filter_hz, sample_hz,
                               order)


def white_filter_of(flt: Mapping | None) -> dict | None:
    """The low-pass filter ({"filter_hz", "sample_hz"[, "filter_order"]}, the keywords of
    :func:`avar_white_noise`) of a white-noise term or a filter dict (the log's, a fit's ``filter`` summary);
    None without a cut-off. Unset values are left out, and order 2, the default."""
    w = {k: v for k, v in dict(flt or {}).items() if k in FILTER_KEYS and v is not None}
    if w.get("filter_order") == 2:
        del w["filter_order"]
    return w if w.get("filter_hz") else None


def avar_bias_instability(tau, B, f0=None):
    """Bias instability (flicker rate noise).

    Without ``f0``: the plateau (2 ln2 / pi) B^2 (Miao eq. (3.6)). With the cut-off ``f0`` (Hz) of the
    two-sided rate PSD (B^2 / 2 pi) / f, f <= f0: the full form of IEEE 952 C.3 / thesis eq. (3.16),
    (2 B^2/pi) [ln2 - sin^3 x / (2 x^2) (sin x + 4 x cos x) + Ci(2x) - Ci(4x)], x = pi f0 tau, which tends to
    the plateau for tau >> 1/f0.
    """
    tau = np.asarray(tau, dtype=float)
    if f0 is None:
        return np.full_like(tau, BIAS_PLATEAU * B**2)
    from scipy.special import sici  # only for the cut-off form (keeps scipy out of start-up)

    x = math.pi * f0 * tau
    _, ci2 = sici(2.0 * x)
    _, ci4 = sici(4.0 * x)
    s = np.sin(x)
    bracket = math.log(2.0) - s**3 / (2.0 * x**2) * (s + 4.0 * x * np.cos(x)) + ci2 - ci4
    return 2.0 * B**2 / math.pi * bracket


def avar_random_walk(tau, K):
    """Rate random walk: sigma^2 = K^2 tau / 3 (IEEE 952 C.4; Miao eq. (2.4))."""
    tau = np.asarray(tau, dtype=float)
    return K**2 * tau / 3.0


def avar_ramp(tau, R):
    """Rate ramp: sigma^2 = R^2 tau^2 / 2 (IEEE 952 C.5; Miao eq. (2.5))."""
    tau = np.asarray(tau, dtype=float)
    return R**2 * tau**2 / 2.0


def avar_gauss_markov(tau, sigma, tau_c):
    """First-order Gauss-Markov (exponentially correlated) rate noise of std ``sigma``, correlation time ``tau_c``.

    sigma^2(tau) = (qc Tc)^2 / tau [1 - Tc/(2 tau) (3 - 4 e^(-tau/Tc) + e^(-2 tau/Tc))], qc^2 = 2 sigma^2 / Tc
    (IEEE 952 C.6). Peak ADEV 0.617 sigma at tau = 1.89 Tc. For tau << Tc it tends to a rate random walk
    with K^2 = qc^2 (sigma^2 = qc^2 tau / 3); for tau >> Tc to white noise with N^2 = (qc Tc)^2.
    """
    tau = np.asarray(tau, dtype=float)
    Tc = float(tau_c)
    qc2 = 2.0 * sigma**2 / Tc
    u = tau / Tc
    # bracket = 1 - (3 - 4 e^-u + e^-2u) / (2u); below u = 1e-3 the series u^2/3 - u^3/4 + 7 u^4/60 avoids
    # the cancellation (3 - 4e^-u + e^-2u = 2u - 2u^3/3 + u^4/2 - 7u^5/30 + ...).
    us = np.maximum(u, 1e-3)
    bracket = np.where(
        u < 1e-3,
        u**2 / 3.0 - u**3 / 4.0 + 7.0 * u**4 / 60.0,
        1.0 - (3.0 - 4.0 * np.exp(-us) + np.exp(-2.0 * us)) / (2.0 * us),
    )
    return qc2 * Tc**2 / tau * bracket


def avar_sinusoid(tau, amplitude, freq_hz):
    """Sinusoidal rate of amplitude A and frequency f0: sigma^2 = A^2 [sin^2(pi f0 tau) / (pi f0 tau)]^2.

    (IEEE 952 C.7.) Peak ADEV 0.725 A at tau = 0.371 / f0.
    """
    tau = np.asarray(tau, dtype=float)
    x = math.pi * freq_hz * tau
    return amplitude**2 * (np.sin(x) ** 2 / x) ** 2


#: the analytic AVAR of each effect, by name
_AVAR = {
    "quantization": avar_quantization,
    "white_noise": avar_white_noise,
    "bias_instability": avar_bias_instability,
    "random_walk": avar_random_walk,
    "ramp": avar_ramp,
    "gauss_markov": avar_gauss_markov,
    "sinusoid": avar_sinusoid,
}


def validate_term(term: Mapping) -> None:
    """Raise ValueError (with a message that names the effect and key) if ``term`` is not a valid term."""
    effect = term.get("effect")
    if effect not in PARAMS:
        raise ValueError(f"unknown effect {effect!r}; expected one of: {', '.join(EFFECTS)}")
    allowed = set(PARAMS[effect]) | set(OPTIONAL_PARAMS.get(effect, ())) | {"effect"}
    for p in PARAMS[effect]:
        if p not in term:
            raise ValueError(f"effect {effect!r} needs parameter {p!r}")
    for k, v in term.items():
        if k == "effect":
            continue
        if k not in allowed:
            raise ValueError(f"effect {effect!r} has no parameter {k!r} (allowed: {', '.join(sorted(allowed - {'effect'}))})")
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise ValueError(f"effect {effect!r} parameter {k!r} must be a finite number, got {v!r}")
        if v < 0:
            raise ValueError(f"effect {effect!r} parameter {k!r} must be non-negative, got {v!r}")
    if effect == "gauss_markov" and term["tau_c"] <= 0:
        raise ValueError("effect 'gauss_markov' parameter 'tau_c' must be positive")
    if effect == "sinusoid" and term["freq_hz"] <= 0:
        raise ValueError("effect 'sinusoid' parameter 'freq_hz' must be positive")
    order = term.get("filter_order") if effect == "white_noise" else None
    if order is not None and order not in (1, 2, 3, 4):
        raise ValueError(f"effect 'white_noise' parameter 'filter_order' must be 1, 2, 3 or 4, got {order!r}")


def avar_term(term: Mapping, tau) -> np.ndarray:
    """Allan variance of one term (a dict with ``effect`` and its SI parameters) at cluster times ``tau``."""
    effect = term["effect"]
    fn = _AVAR[effect]
    kwargs = {p: term[p] for p in PARAMS[effect]}
    for p in OPTIONAL_PARAMS.get(effect, ()):
        if term.get(p) is not None:
            kwargs[p] = term[p]
    return fn(tau, **kwargs)


def avar_model(terms: Iterable[Mapping], tau) -> np.ndarray:
    """Sum of the Allan variances of independent terms (IEEE 952: independent sources add in AVAR)."""
    tau = np.asarray(tau, dtype=float)
    total = np.zeros_like(tau)
    for term in terms:
        total = total + avar_term(term, tau)
    return total


def adev_model(terms: Iterable[Mapping], tau) -> np.ndarray:
    return np.sqrt(avar_model(terms, tau))


def linear_basis(tau, effects: Iterable[str] = LINEAR_EFFECTS) -> np.ndarray:
    """Columns d sigma^2 / d(p^2) for the linear effects: AVAR = basis @ [p^2 ...] (Miao eq. (3.6)).

    Returns an array (len(tau), len(effects)); e.g. for white_noise the column is 1/tau.
    """
    tau = np.asarray(tau, dtype=float)
    cols = []
    for effect in effects:
        p = LINEAR_PARAM[effect]
        cols.append(avar_term({"effect": effect, p: 1.0}, tau))
    return np.column_stack(cols)
