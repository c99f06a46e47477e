"""Likelihood of a noise model against a measured Allan variance: the base of companion.gap.

Each overlapping AVAR estimate a_i at cluster time tau_i with nu_i EDF is s_i chi^2_nu / nu around the true
AVAR s_i (NIST SP 1065 sec. 5.3). The Gamma deviance d_i = nu_i (a_i/s_i - 1 - ln(a_i/s_i)) is -2 ln L up to a
constant; its mean when the model is right is E0(nu) = nu (ln(nu/2) - psi(nu/2)); the gap metric is
G = mean d_i / E0(nu_i).

This module imports nothing else of companion.gap (the modules import each other in one direction:
likelihood <- candidates <- compare <- selection <- workflow), so there is no import cycle.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import special, stats

from companion.allan.terms import avar_term
from companion.allan.filtered_white import avar_filtered_white


@dataclass
class Measured:
    """Overlapping AVAR of one axis with EDF and 95 % band (all arrays aligned on ``tau``)."""

    tau: np.ndarray
    avar: np.ndarray
    m: np.ndarray
    nu: np.ndarray
    rate_hz: float
    n: int
    lo: np.ndarray = field(default=None)
    hi: np.ndarray = field(default=None)
    nu_raw: np.ndarray = field(default=None)
    #: vibration lines the record's periodogram shows: ((frequency Hz, amplitude), ...)
    #: (:func:`companion.gap.spectral.significant_lines`); a sinusoid at one of these frequencies keeps it
    lines: tuple = ()

    def __post_init__(self):
        if self.nu_raw is None:
            self.nu_raw = self.nu
        if self.lo is None:
            self.lo = self.nu * self.avar / stats.chi2.ppf(0.975, self.nu)
            self.hi = self.nu * self.avar / stats.chi2.ppf(0.025, self.nu)


#: Relative accuracy (in AVAR) to which any model, or simulation, can be expected to hold: 5 %.
MODEL_FLOOR = 0.05


def term_avar(term, tau, rate_hz: float) -> np.ndarray:
    """AVAR of one term as the simulator produces it: a bias_instability term without ``f0`` gets the
    cut-off at the Nyquist frequency rate_hz/2 (thesis eq. (3.16)), which is how
    :func:`companion.sim.synth.flicker` synthesises it; a white_noise term with ``cutoff_hz`` (and
    ``order``) is the sensor's white noise N behind a low-pass filter, sampled at rate_hz
    (:mod:`companion.allan.filtered_white`; ``integrate``: each logged value is the mean over its interval); every other term as in :mod:`companion.allan.terms`."""
    if term["effect"] == "bias_instability" and term.get("f0") is None:
        term = dict(term, f0=rate_hz / 2.0)
    if term["effect"] == "temperature":
        # coef (rad/s per K) times the measured temperature record: its AVAR is coef^2 x the AVAR of the
        # temperature series itself, carried by the term on its own cluster times (companion.gap.temperature_candidate)
        t_tau, t_avar = np.asarray(term["unit_tau"], dtype=float), np.asarray(term["unit_avar"], dtype=float)
        ln = np.interp(np.log(np.asarray(tau, dtype=float)), np.log(t_tau), np.log(np.maximum(t_avar, 1e-300)))
        return term["coef"] ** 2 * np.exp(ln)
    if term["effect"] == "white_noise" and term.get("cutoff_hz"):
        # the logged white noise behind an autopilot's low-pass filter, sampled or averaged
        rate = None if term.get("integrate") else rate_hz
        return avar_filtered_white(tau, term["N"], term["cutoff_hz"], rate, int(term.get("order", 2)))
    return avar_term(term, tau)


def model_avar(terms, tau, rate_hz: float) -> np.ndarray:
    tau = np.asarray(tau, dtype=float)
    total = np.zeros_like(tau)
    for t in terms:
        total = total + term_avar(t, tau, rate_hz)
    return total


def expected_deviance(nu) -> np.ndarray:
    """E0(nu) = nu (ln(nu/2) - psi(nu/2)): the mean per-point deviance of a correct model."""
    nu = np.asarray(nu, dtype=float)
    return nu * (np.log(nu / 2.0) - special.digamma(nu / 2.0))


def deviance_points(meas: Measured, s) -> np.ndarray:
    """d_i = nu_i (a_i/s_i - 1 - ln(a_i/s_i)) (Gamma deviance)."""
    s = np.maximum(np.asarray(s, dtype=float), 1e-300)
    r = meas.avar / s
    return meas.nu * (r - 1.0 - np.log(r))


def deviance(meas: Measured, s) -> float:
    return float(np.sum(deviance_points(meas, s)))


def gap_metric(meas: Measured, s) -> float:
    """G = mean d_i / E0(nu_i); about 1 when the model ``s`` (AVAR at meas.tau) is right."""
    return float(np.mean(deviance_points(meas, s) / expected_deviance(meas.nu)))
