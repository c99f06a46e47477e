"""Measured Allan variance with its confidence, the gap metric, and where model and measurement disagree.

Statistics (NIST SP 1065 sec. 5.3; IEEE Std 952 Annex C):

* An overlapping AVAR estimate a at cluster time tau with nu equivalent degrees of freedom (EDF) is
  distributed as s chi^2_nu / nu around the true AVAR s. Its 95 % band is
  [nu a / chi^2_{0.975,nu}, nu a / chi^2_{0.025,nu}] (SP 1065 eq. (32)).
* The EDF come from :mod:`companion.gap._edf` (SP 1065 Table 5), with the noise type taken from the local
  log-log slope of a smooth reference fitted to the *measurement* (:func:`reference_curve`), not of any model,
  so that every model compared against the same measurement is judged by the same likelihood.
* Deviance of a model s against the measurement (twice the negative log-likelihood ratio against the
  saturated fit, Gamma family):  d_i = nu_i (a_i/s_i - 1 - ln(a_i/s_i)).  Its expectation when the model is
  right is E0(nu) = nu (ln(nu/2) - psi(nu/2)) (psi: digamma), about 1 + 1/(3 nu).
* **Gap metric** G = mean_i d_i / E0(nu_i): 1 on average when the model is right, whatever the EDF; a model
  off by a factor r in AVAR over a region with nu EDF adds about nu (r - 1 - ln r) per point.
* Per-point score z_i = Phi^-1( F_chi2(nu_i a_i / s_i; nu_i) ): the measurement is outside the model's band
  where |z_i| > 1.96; the disagreement table groups consecutive such points of the same sign.
* Measured vs *simulated* curve (both estimates): z_i = ln(a_i / b_i) / sqrt(psi'(nu_a/2) + psi'(nu_b/2))
  (psi': trigamma, the variance of ln chi^2_nu), G_sim = mean z_i^2, 1 on average when they agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special, stats

from companion.allan.adev import oavar
from companion.gap._edf import local_slope, oavar_edf
from companion.gap.candidates import fit_terms
from companion.gap.likelihood import (MODEL_FLOOR, Measured, deviance, deviance_points, expected_deviance,
                                      gap_metric, model_avar, term_avar)

# the likelihood names moved to companion.gap.likelihood (no import cycle); re-exported here for callers
__all__ = ["MODEL_FLOOR", "Measured", "Region", "deviance", "deviance_points", "disagreements", "expected_deviance",
           "gap_metric", "gap_vs_simulation", "measure", "measure_pooled", "model_avar", "reference_curve", "term_avar", "z_scores"]


def measure(y, rate_hz: float, spec="octave", min_terms: int = 1, model_floor: float = MODEL_FLOOR) -> Measured:
    """Overlapping AVAR of rate samples ``y`` at ``rate_hz`` with EDF and 95 % band.

    ``nu_raw`` are the EDF of the estimates (band of the plot); the statistics use
    nu = 1 / (1/nu_raw + model_floor^2 / 2), i.e. var(ln a) = 2/nu_raw + model_floor^2: a model is not
    asked to be better than ``model_floor`` (5 % in AVAR, 2.5 % in ADEV), which also absorbs the
    correlation of neighbouring octave estimates where the EDF run into the thousands.
    """
    y = np.asarray(y, dtype=float)
    if y.shape[0] < 16:
        raise ValueError(f"too few samples for an Allan analysis ({y.shape[0]}); need at least 16")
    tau, avar, m, n_terms = oavar(y, rate_hz, spec=spec)
    keep = (n_terms >= min_terms) & (avar > 0)
    tau, avar, m = tau[keep], avar[keep], m[keep]
    n_phase = y.shape[0] + 1
    meas = Measured(tau=tau, avar=avar, m=m, nu=oavar_edf(n_phase, m, np.full(m.shape, -1.0)),
                    rate_hz=float(rate_hz), n=int(y.shape[0]))
    for _ in range(2):  # EDF from the slopes of a smooth reference curve, refined once
        ref = reference_curve(meas)
        meas.nu = oavar_edf(n_phase, m, local_slope(tau, ref))
    meas.nu_raw = meas.nu
    meas.nu = 1.0 / (1.0 / meas.nu + model_floor**2 / 2.0)
    meas.lo = meas.nu_raw * meas.avar / stats.chi2.ppf(0.975, meas.nu_raw)
    meas.hi = meas.nu_raw * meas.avar / stats.chi2.ppf(0.025, meas.nu_raw)
    return meas


def measure_pooled(segments, rate_hz: float, spec="octave", model_floor: float = MODEL_FLOOR) -> Measured:
    """Overlapping AVAR pooled over several rate segments of one record (still segments between motion;
    no cluster crosses a gap: :func:`companion.allan.pooled.pooled_oavar`), with EDF and 95 % band.

    The pooled estimate is sum_s w_s a_s with w_s the segments' shares of the second differences
    (:func:`companion.allan.pooled.segment_weights`); the segments are independent, so its EDF is
    1 / sum_s (w_s^2 / nu_s) with nu_s the EDF of segment s (:mod:`companion.gap._edf`, noise type from the
    local slope of the smooth reference curve). ``n`` of the result is the total sample count."""
    from companion.allan.pooled import pooled_cluster_sizes, pooled_oavar, segment_weights

    segs = [np.asarray(s, dtype=float) for s in segments if np.asarray(s).shape[0] >= 16]
    if not segs:
        raise ValueError("too few samples for an Allan analysis; need a segment of at least 16")
    lengths = [s.shape[0] for s in segs]
    m = pooled_cluster_sizes(lengths, spec)
    tau, avar, m, counts = pooled_oavar(segs, rate_hz, m=m)
    keep = (counts >= 1) & (avar > 0)
    tau, avar, m = tau[keep], avar[keep], m[keep]
    w = segment_weights(lengths, m)

    def edf(slope):
        inv = np.zeros(m.shape[0])
        for k, n_s in enumerate(lengths):
            nu_s = np.nan_to_num(oavar_edf(n_s + 1, m, slope), nan=1.0)
            inv += np.where(w[k] > 0, w[k] ** 2 / np.maximum(nu_s, 1.0), 0.0)
        return np.maximum(1.0 / np.where(inv > 0, inv, 1.0), 1.0)

    meas = Measured(tau=tau, avar=avar, m=m, nu=edf(np.full(m.shape, -1.0)), rate_hz=float(rate_hz),
                    n=int(sum(lengths)))
    for _ in range(2):
        meas.nu = edf(local_slope(tau, reference_curve(meas)))
    meas.nu_raw = meas.nu
    meas.nu = 1.0 / (1.0 / meas.nu + model_floor**2 / 2.0)
    meas.lo = meas.nu_raw * meas.avar / stats.chi2.ppf(0.975, meas.nu_raw)
    meas.hi = meas.nu_raw * meas.avar / stats.chi2.ppf(0.025, meas.nu_raw)
    return meas


def reference_curve(meas: Measured) -> np.ndarray:
    """Smooth reference AVAR: maximum-likelihood sum of the five power-law terms Q, N, B, K, R.

    Its local slope picks the noise type, hence the EDF, of each point. The measured curve's own slope is
    useless for that where its estimates scatter (long tau). Being a sum of power laws, the reference cannot
    fall after a Gauss-Markov or sinusoid bump; there it takes the flatter slope, whose EDF is smaller, the
    cautious side.
    """
    terms = [{"effect": e, p: 1.0} for e, p in (("quantization", "Q"), ("white_noise", "N"),
                                                 ("bias_instability", "B"), ("random_walk", "K"),
                                                 ("ramp", "R"))]
    return fit_terms(meas, terms).s


def z_scores(meas: Measured, s) -> np.ndarray:
    """Signed score: + where the measurement lies above the model; |z| > 1.96 is outside the 95 % band."""
    s = np.maximum(np.asarray(s, dtype=float), 1e-300)
    x = meas.nu * meas.avar / s
    # two tails computed separately keep precision far out in either tail
    lower = stats.chi2.logcdf(x, meas.nu)
    upper = stats.chi2.logsf(x, meas.nu)
    z = np.where(lower < upper, stats.norm.ppf(np.exp(lower)), -stats.norm.ppf(np.exp(upper)))
    return np.clip(np.nan_to_num(z, nan=0.0, posinf=40.0, neginf=-40.0), -40.0, 40.0)


def gap_vs_simulation(meas: Measured, sim_avar, sim_nu) -> float:
    """G_sim = mean z_i^2, z_i = ln(a_i/b_i) / sqrt(psi'(nu_a/2) + psi'(nu_b/2))."""
    var = special.polygamma(1, meas.nu / 2.0) + special.polygamma(1, np.asarray(sim_nu) / 2.0)
    z = np.log(meas.avar / np.maximum(sim_avar, 1e-300)) / np.sqrt(var)
    return float(np.mean(z * z))


@dataclass
class Region:
    """A tau range where the measurement leaves the model's 95 % band."""

    tau_lo: float
    tau_hi: float
    direction: str  # "above" (measured above model) or "below"
    points: int
    worst_tau: float
    worst_ratio: float  # measured ADEV / model ADEV at the worst point
    worst_z: float

    def as_dict(self) -> dict:
        return {"tau_lo": self.tau_lo, "tau_hi": self.tau_hi, "direction": self.direction,
                "points": self.points, "worst_tau": self.worst_tau, "adev_ratio": self.worst_ratio,
                "z": self.worst_z}


def disagreements(meas: Measured, s, z_limit: float = 1.96) -> list[Region]:
    """Consecutive cluster times where |z| > z_limit with the same sign, worst point of each."""
    z = z_scores(meas, s)
    ratio = np.sqrt(meas.avar / np.maximum(s, 1e-300))
    out: list[Region] = []
    i, n = 0, z.shape[0]
    while i < n:
        if abs(z[i]) <= z_limit:
            i += 1
            continue
        sign = np.sign(z[i])
        j = i
        while j + 1 < n and abs(z[j + 1]) > z_limit and np.sign(z[j + 1]) == sign:
            j += 1
        k = i + int(np.argmax(np.abs(z[i:j + 1])))
        out.append(Region(float(meas.tau[i]), float(meas.tau[j]), "above" if sign > 0 else "below",
                          j - i + 1, float(meas.tau[k]), float(ratio[k]), float(z[k])))
        i = j + 1
    return out
