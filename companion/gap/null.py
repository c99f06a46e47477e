"""How often a right model leaves a gap as large as the one left: the spread of G on records like this one.

The noise floor G <= 2 is one number for every record, but G's spread under a right model depends on the
record: on a long record G is a mean over many points of large EDF (null benchmark, 2 h at 20 Hz: 95th
percentile 0.76), on a 33 s log over ten points whose last ones have EDF 6 and 2 (95th percentile 1.54,
99th 2.27). When a gap remains, the model after is simulated on the record's own layout (the same still
segments' lengths, the same pooling and EDF, the log's temperature for a temperature term) and measured
as the data were: the share of simulated records whose G is at least the one left is the p-value of the
remaining gap, for G and for G over the cluster times the record resolves.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from companion.allan.adev import oavar
from companion.gap._edf import local_slope, oavar_edf
from companion.gap.compare import Measured, gap_metric, gap_vs_simulation, measure, measure_pooled, model_avar
from companion.gap.lowpass_check import synthesize_filtered_white
from companion.sim.synth import synthesize_axis

#: simulated records at most (a share of 1 % is then resolved)
NULL_DRAWS = 200
#: samples simulated in all, which bounds the cost (a 2 h record at 50 Hz gets 11 draws: skipped)
NULL_MAX_SAMPLES = 4_000_000
#: fewer draws than this give no usable 95th percentile: the check is skipped
NULL_MIN_DRAWS = 40
#: samples of the model simulated at most for the check against the analytic curve (bounds its cost)
SIM_MAX_SAMPLES = 2_000_000


class SimCheck(NamedTuple):
    """The model's Allan variance by simulation (None when the record is too long to simulate whole)."""

    avar: object  #: simulated AVAR at the measured cluster times
    gap_vs_measured: float | None  #: G of the measurement against the simulated curve
    gap_vs_analytic: float | None  #: G of the simulated curve against the analytic one


def synthesize_model(terms, rate_hz: float, n: int, rng, t_series=None) -> np.ndarray:
    """``n`` rate samples of the model ``terms`` as the log holds them: plain terms by the simulator, a
    white term with a cut-off through the autopilot's filter and decimation, a temperature term as its
    coefficient times ``t_series`` (the log's smoothed temperature, deterministic), a sinusoid averaged
    over each interval when the samples are averages (PX4 sensor_combined)."""
    averaged = any(t.get("integrate") for t in terms)
    plain = [t for t in terms if not t.get("cutoff_hz") and t["effect"] != "temperature"
             and not (averaged and t["effect"] == "sinusoid")]
    y = synthesize_axis(plain, rate_hz, n, rng) if plain else np.zeros(n)
    if averaged:
        # a vibration line is averaged over each interval like the noise (a 112 Hz line at 248.6 Hz keeps
        # 0.70 of its amplitude; point samples would keep all of it)
        tk = np.arange(n) / rate_hz
        for t in terms:
            if t["effect"] == "sinusoid":
                w, ph = 2.0 * math.pi * t["freq_hz"], rng.uniform(0.0, 2.0 * math.pi)
                y = y + t["amplitude"] * (np.sin(w * (tk + 1.0 / rate_hz) + ph) - np.sin(w * tk + ph)) / (w / rate_hz)
    for t in terms:
        if t.get("cutoff_hz"):  # the autopilot's filter and decimation, simulated at 8x the log's rate
            y = y + synthesize_filtered_white(t["N"], t["cutoff_hz"], rate_hz, n, rng, int(t.get("order", 2)),
                                              integrate=bool(t.get("integrate", False)))
        if t["effect"] == "temperature" and t_series is not None and t_series.shape[0] >= n:
            y = y + t["coef"] * t_series[:n]
    return y


def resolved_subset(meas: Measured, tau_max: float) -> Measured | None:
    """The points of ``meas`` at tau <= tau_max (None when that leaves fewer than 3 or all of them)."""
    keep = meas.tau <= tau_max * (1.0 + 1e-9)
    if keep.all() or np.count_nonzero(keep) < 3:
        return None
    return Measured(tau=meas.tau[keep], avar=meas.avar[keep], m=meas.m[keep], nu=meas.nu[keep],
                    rate_hz=meas.rate_hz, n=meas.n, nu_raw=meas.nu_raw[keep])


def null_gap(terms, seg_lengths, rate_hz: float, g_obs: float, g_res_obs: float | None, tau_max: float | None,
             seed: int = 0, t_segs=None, draws: int | None = None) -> dict | None:
    """The shares of records simulated from ``terms`` on the layout ``seg_lengths`` (samples per still
    segment) with G >= ``g_obs`` and, over tau <= ``tau_max``, G >= ``g_res_obs``; with G's median and 95th
    percentile. None when the sample budget allows fewer than NULL_MIN_DRAWS records."""
    n_all = int(sum(seg_lengths))
    if draws is None:
        draws = min(NULL_DRAWS, NULL_MAX_SAMPLES // max(n_all, 1))
    if draws < NULL_MIN_DRAWS or not terms:
        return None
    rng = np.random.default_rng(seed)
    g, g_res = [], []
    for _ in range(draws):
        segs = [synthesize_model(terms, rate_hz, int(n), rng, None if t_segs is None else t_segs[k])
                for k, n in enumerate(seg_lengths)]
        m = measure_pooled(segs, rate_hz) if len(segs) > 1 else measure(segs[0], rate_hz)
        g.append(gap_metric(m, model_avar(terms, m.tau, rate_hz)))
        sub = resolved_subset(m, tau_max) if tau_max is not None else None
        if sub is not None:
            g_res.append(gap_metric(sub, model_avar(terms, sub.tau, rate_hz)))
    g = np.array(g)
    out = {"draws": draws, "seed": seed, "share_ge": float(np.mean(g >= g_obs)), "mean": float(np.mean(g)),
           "median": float(np.median(g)),
           "p95": float(np.percentile(g, 95)), "share_above_floor": float(np.mean(g > 2.0))}
    if g_res and g_res_obs is not None:
        gr = np.array(g_res)
        out.update({"share_ge_resolved": float(np.mean(gr >= g_res_obs)), "median_resolved": float(np.median(gr)),
                    "p95_resolved": float(np.percentile(gr, 95)),
                    "share_above_floor_resolved": float(np.mean(gr > 2.0))})
    return out


def null_text(nl: dict, g_obs: float, g_res_obs: float | None) -> str:
    """'; a right model leaves G >= 2.47 in 1.0 % of 200 simulated records like this one (95th percentile
    1.54) ...'"""
    txt = (f"; the model after, simulated on this record's layout, leaves G >= {g_obs:.2f} in "
           f"{100 * nl['share_ge']:.1f} % of {nl['draws']} records (median {nl['median']:.2f}, 95th percentile "
           f"{nl['p95']:.2f})")
    if "share_ge_resolved" in nl and g_res_obs is not None:
        txt += (f", and G >= {g_res_obs:.2f} over the resolved cluster times in {100 * nl['share_ge_resolved']:.1f} % "
                f"(95th percentile {nl['p95_resolved']:.2f})")
    return txt


def simulate_avar(terms, meas: Measured, seed: int, t_series=None):
    """Simulate the model at the measurement's rate and length; its AVAR at the same m, with EDF."""
    n = min(meas.n, SIM_MAX_SAMPLES)
    if not terms:
        return None, None
    y = synthesize_model(terms, meas.rate_hz, n, np.random.default_rng(seed), t_series)
    m = meas.m[meas.m <= n // 2]
    if m.shape[0] < meas.m.shape[0]:
        return None, None
    _, avar, _, _ = oavar(y, meas.rate_hz, m=m)
    s = model_avar(terms, meas.tau, meas.rate_hz)
    nu = oavar_edf(n + 1, m, local_slope(meas.tau, s))
    return avar, nu


def sim_checks(terms, meas: Measured, seed: int, t_series=None) -> SimCheck:
    """The model simulated at the measurement's rate and length (:func:`simulate_avar`): G of the measurement
    against the simulated curve, and of the simulated curve against the analytic one."""
    avar, nu = simulate_avar(terms, meas, seed, t_series)
    if avar is None:
        return SimCheck(None, None, None)
    g_meas_sim = gap_vs_simulation(meas, avar, nu)
    sim_meas = Measured(tau=meas.tau, avar=np.maximum(avar, 1e-300), m=meas.m, nu=1.0 / (1.0 / nu + 0.05**2 / 2),
                        rate_hz=meas.rate_hz, n=meas.n)
    g_sim_analytic = gap_metric(sim_meas, model_avar(terms, meas.tau, meas.rate_hz))
    return SimCheck(avar, g_meas_sim, g_sim_analytic)
