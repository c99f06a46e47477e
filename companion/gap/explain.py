"""Plain words for each effect: what it is on an Allan plot and what commonly causes it in a gyro.

Sources for the physics: IEEE Std 952-1997 Annex C (the seven terms and their slopes), the thesis seed
(sec. 3.1.4: ARW from white noise of the output, bias instability from flickering electronics, rate random
walk as the long-correlation limit of a Markov process, exponentially correlated noise), and
../shared/REFERENCE.md (rate rounding to an int16 LSB in ArduPilot RAW_IMU).
"""

from __future__ import annotations

import math

from companion.units import datasheet_unit, to_datasheet

#: what each effect looks like on the Allan curve (IEEE 952 Annex C)
WHAT = {
    "quantization": "angle quantisation: ADEV slope -1 at the shortest cluster times (IEEE 952 C.1)",
    "white_noise": "white rate noise (angle random walk): ADEV slope -1/2 (IEEE 952 C.2)",
    "bias_instability": "bias instability (flicker noise): a flat ADEV floor at 0.664 B (IEEE 952 C.3)",
    "random_walk": "rate random walk: ADEV rising with slope +1/2 at long cluster times (IEEE 952 C.4)",
    "ramp": "rate ramp (drift): ADEV rising with slope +1 at the longest cluster times (IEEE 952 C.5)",
    "gauss_markov": "first-order Gauss-Markov (exponentially correlated) noise: an ADEV bump peaking at "
                    "0.617 sigma near tau = 1.89 tau_c (IEEE 952 C.6)",
    "temperature": "a rate that follows the log's temperature channel: coef x T(t), its ADEV that of the "
                   "temperature record",
    "sinusoid": "a sinusoidal rate: an ADEV bump peaking at 0.725 A near tau = 0.371 / f0, then falling "
                "as 1/tau with notches (IEEE 952 C.7)",
}

#: the physical cause each effect usually has, for the report's plain words
CAUSES = {
    "quantization": "the digital output resolution of the angle/rate integration (ADC or output word length)",
    "white_noise": "thermo-mechanical and electronic noise of the sensing element; with int16 MAVLink fields "
                   "also the rounding of the rate to one LSB when the noise dithers it",
    "bias_instability": "flicker (1/f) noise of the electronics and of the sensing element",
    "random_walk": "slow wandering of the bias (aging, slow temperature change); the limit of a correlated "
                   "process whose correlation time is longer than the record",
    "ramp": "a slow monotonic drift: warm-up after power-on, a steady temperature change, or a true slow "
            "rotation (e.g. Earth rate on a tilting mount)",
    "gauss_markov": "a correlated bias with a finite memory such as a thermal effect of the board or of the "
                    "heater/fan cycle, or a mount or vibration-isolator effect",
    "temperature": "the temperature sensitivity of the gyro bias (warm-up, heater, airflow)",
    "sinusoid": "a periodic disturbance: thermostat or heater cycling, a fan, a pump, building or vehicle "
                "oscillation, or a beat between the sample clock and a vibration",
}


def fmt_param(param: str, value: float, axis: str) -> str:
    """``N = 2.1 deg/sqrt(h) (6.1e-04 SI)``: datasheet unit first, SI in brackets."""
    if param in ("tau_c", "freq_hz", "f0", "cutoff_hz"):
        unit = "s" if param == "tau_c" else "Hz"
        return f"{param} = {value:.4g} {unit}"
    if param == "coef":
        return f"coef = {value * 180 / 3.141592653589793 * 3600:.4g} deg/h per K ({value:.3g} rad/s/K)"
    if param == "integrate":
        return "averaged over each sample interval" if value else "point samples"
    if param == "order":
        return f"filter order {int(value)}"
    return f"{param} = {to_datasheet(param, value, axis):.4g} {datasheet_unit(param, axis)} ({value:.3g} SI)"


def describe_term(term, axis: str) -> str:
    return term["effect"] + " " + ", ".join(fmt_param(k, v, axis) for k, v in term.items()
                                            if k != "effect" and isinstance(v, (int, float)))


def explain_added(term, axis: str, rate_hz: float | None = None, spectral: dict | None = None) -> str:
    """One paragraph for an added effect: what it is, its parameters, what commonly causes it (for a
    sinusoid with ``spectral``, the periodogram check of :mod:`companion.gap.spectral`)."""
    effect = term["effect"]
    head = f"{describe_term(term, axis)}: {WHAT[effect]}."
    if effect == "gauss_markov" and rate_hz and term["tau_c"] * rate_hz < 10:
        cause = (f"Its correlation time is only {term['tau_c'] * rate_hz:.3g} samples: this is the signature of "
                 "white noise seen through a low-pass filter (the sensor's digital filter or the autopilot's "
                 "gyro filter) at the shortest cluster times, rather than a physical bias process.")
    elif effect == "gauss_markov":
        cause = (f"A correlated bias that forgets itself in about {term['tau_c']:.3g} s: commonly "
                 f"{CAUSES[effect]}.")
    elif effect == "sinusoid" and spectral is not None and not spectral["confirmed"]:
        cause = explain_spectral(spectral, term, axis)
    elif effect == "sinusoid":
        period = 1.0 / term["freq_hz"]
        cause = (f"A periodic disturbance at {term['freq_hz']:.3g} Hz (period {period:.3g} s): commonly "
                 f"{CAUSES[effect]}.")
        if spectral is not None:
            cause += " " + explain_spectral(spectral, term, axis)
    else:
        cause = f"Commonly caused by {CAUSES[effect]}."
    return head + " " + cause


def explain_missized(effect: str, param: str, ratio: float) -> str:
    """``white_noise N is 1.8x too small in the model``."""
    if ratio >= 1.0:
        return f"{effect} {param} is {ratio:.2f}x too small in the model (measured {ratio:.2f}x the model value)"
    return f"{effect} {param} is {1.0 / ratio:.2f}x too large in the model (measured {ratio:.2f}x the model value)"


def explain_rate_quantization(lsb: float, N_q: float, axis: str) -> str:
    return (f"rate quantisation: the samples are rounded to an LSB of {lsb:.4g} (SI); when the noise dithers "
            f"the rounding this adds white rate noise of variance LSB^2/12 per sample, N_q = LSB sqrt(tau0/12) = "
            f"{fmt_param('N', N_q, axis)[4:]}, slope -1/2 like the sensor's own white noise (not the -1 slope of "
            f"angle quantisation Q). It is named because the LSB is known; the Allan curve alone cannot tell it "
            f"from a larger N.")


def explain_alternative(alt, record_s: float, rate_hz: float) -> str:
    """Why a one-parameter limit was named instead of the Gauss-Markov term that fits nearly as well."""
    tau_c = alt["tau_c"]
    if alt["instead_of"] == "white_noise":
        return (f"A Gauss-Markov term (sigma = {alt['sigma']:.3g} rad/s, tau_c = {tau_c:.3g} s, "
                f"{tau_c * rate_hz:.3g} samples) fits almost as well (likelihood ratio {alt['lr']:.1f}, not "
                "significant): a correlation that short is white noise at every cluster time measured.")
    if alt["instead_of"] == "bias_instability":
        return (f"A Gauss-Markov term (sigma = {alt['sigma']:.3g} rad/s, tau_c = {tau_c:.3g} s) fits almost as "
                f"well (likelihood ratio {alt['lr']:.1f} for its extra parameter, below the 10.8 it must pass): "
                "flicker noise is a sum of such terms with spread correlation times, and over the cluster "
                "times measured one of them can pass for it; the one-parameter flicker is named.")
    return (f"A Gauss-Markov term (sigma = {alt['sigma']:.3g} rad/s, tau_c = {tau_c:.3g} s) fits almost as well "
            f"(likelihood ratio {alt['lr']:.1f}, corrected, not significant): the record ({record_s:.4g} s, "
            f"{record_s / tau_c:.3g} times that tau_c) is too short to tell a slow correlated bias from a rate "
            f"random walk. Telling them apart needs the fall of the ADEV after its peak at ~1.9 tau_c, i.e. a "
            f"record of about 100 tau_c or more; with less, even an ideal estimator cannot pin tau_c within "
            f"30 % (docs/gap.md, Limits).")


def explain_spectral(ev, term, axis: str) -> str:
    """The periodogram check of a sinusoid named from the Allan curve (companion.gap.spectral)."""
    amp = to_datasheet("amplitude", term["amplitude"], axis)
    amp_psd = to_datasheet("amplitude", ev["amplitude_psd"], axis)
    unit = datasheet_unit("amplitude", axis)
    if ev["confirmed"]:
        return (f"Periodogram check: a line at {ev['f_peak']:.4g} Hz, {ev['peak_ratio']:.3g}x the local noise "
                f"level, carrying {amp_psd:.3g} {unit} of the {amp:.3g} {unit}: confirmed.")
    return (f"Periodogram check: no line near {term['freq_hz']:.4g} Hz (largest bin {ev['peak_ratio']:.3g}x the "
            f"local level, {ev['threshold']:.3g}x needed; it carries {amp_psd:.3g} of the {amp:.3g} {unit}): the "
            "Allan bump is the picture of a broader spectral shape, e.g. the roll-off of the sensor's or the "
            "autopilot's low-pass filter, not a periodic disturbance. The term is kept because it reproduces "
            "the Allan curve; do not read it as a vibration line.")


def explain_runner_up(chosen: str, chosen_score: float, runner: str | None, runner_score: float | None) -> str:
    """Why ``chosen`` and not the runner-up: both scored by the one criterion of companion.gap.selection
    (deviance removed minus the overdispersion-scaled penalty), on the same data and from the same state."""
    if runner is None:
        return f"{chosen} (score {chosen_score:.1f}) was the only explanation fitted with a positive gain."
    if runner_score is not None and runner_score > 0:
        how = "also significant on its own, but explains less net of its penalty"
    else:
        how = "not significant on its own"
    return (f"{chosen} (score {chosen_score:.1f}) was weighed against {runner} (score {runner_score:.1f}, "
            f"{how}); score = deviance removed - overdispersion x penalty, on the same data.")


def explain_lowpass(cutoff_hz: float, order: int, rate_hz: float, aliasing_gain: float, source: str,
                    axis: str) -> str:
    """The autopilot's low-pass filter (and the logger's decimation) on the white noise."""
    tau_f = (1.0 if order == 1 else 2.0 ** 0.5) / (2.0 * 3.141592653589793 * cutoff_hz)
    alias = (f"; sampling at {rate_hz:.4g} Hz folds the noise above {rate_hz / 2:.4g} Hz back in (aliasing from "
             f"decimation): the long-tau white level is {aliasing_gain ** 0.5:.3g}x the sensor's N in ADEV"
             if aliasing_gain > 1.01 else "")
    return (f"low-pass filter on the white noise of {axis}: cut-off {cutoff_hz:.3g} Hz ({source}), order {order}: "
            f"the logged data are filtered before logging, so the Allan deviation falls below the white-noise "
            f"line at cluster times up to a few x {tau_f:.2g} s{alias}. This is the autopilot's gyro filter "
            "(ArduPilot INS_GYRO_FILTER, PX4 IMU_GYRO_CUTOFF) or the sensor's own digital low-pass, not a "
            "property of the sensing element.")


def _measured_side(value: float, ci, model: float) -> str | None:
    """"above" / "below" where ``model`` lies outside the measured interval ``ci``, else None."""
    lo, hi = ci
    if lo > model:
        return "above"
    if hi < model:
        return "below"
    return None


def datasheet_verdict(recalibrated, name: str, axis: str, added=(), white=None) -> str:
    """First line of a report against a datasheet model: each datasheet term the measurement contradicts,
    "above" or "below" with the ratio ("white_noise N above the datasheet: 10.2 vs 0.212 deg/sqrt(h), x48"),
    then those it agrees with. ``recalibrated``: the workflow's per-term entries (model value, value fitted at
    the final state, its interval, the verdict). ``white``: the analysis' white level of the same data
    ({"N", "ci95"}, SI): the measured N is that one, and it contradicts the datasheet where the datasheet's N
    lies outside its interval."""
    parts, off = [], []
    for e in recalibrated:
        p, model, fitted = e["param"], e["model"], e["fitted"]
        ci = e.get("ci95") or [fitted, fitted]
        side = None if e["verdict"] == "consistent" else ("above" if fitted > model else "below")
        if e["effect"] == "white_noise" and white and white.get("N"):
            fitted, ci = white["N"], white.get("ci95") or [white["N"], white["N"]]
            side = _measured_side(fitted, ci, model)
        u = datasheet_unit(p, axis)
        dm, df = to_datasheet(p, model, axis), to_datasheet(p, fitted, axis)
        if side is not None:
            ratio = fitted / model if model > 0 else math.inf
            r = f"x{ratio:.3g}" if ratio >= 1 else f"x{ratio:.2g} (1/{1 / ratio:.3g})" if ratio > 0 else "x0"
            off.append((abs(math.log(ratio)) if 0 < ratio < math.inf else math.inf,
                        f"{e['effect']} {p} {side} the datasheet: {df:.3g} vs {dm:.3g} {u}, {r}"))
        else:
            parts.append(f"{e['effect']} {p} agrees with the datasheet within the noise ({df:.3g} vs {dm:.3g} {u})")
    if off:
        off.sort(key=lambda x: -x[0])
        head = f"{name} datasheet contradicted on {axis}: " + "; ".join(t for _, t in off)
    else:
        head = f"{name} datasheet on {axis}: no datasheet term is contradicted"
    if parts:
        head += "; " + "; ".join(parts)
    eff = [a["effect"] + (f" {a['cutoff_hz']:.3g} Hz" if "cutoff_hz" in a else "") +
           (f" {a['freq_hz']:.3g} Hz" if "freq_hz" in a else "") for a in added]
    if eff:
        head += "; missing from the datasheet model: " + ", ".join(eff)
    return head


def explain_temperature(coef: float, check: dict, axis: str) -> str:
    """A temperature-driven rate, with its check against the temperature channel."""
    k = 180.0 / 3.141592653589793 * 3600.0
    verdict = ("confirmed by the temperature channel" if check.get("confirmed") else
               "NOT confirmed by the temperature channel (the Allan curve's drift has the temperature's shape "
               "but the direct regression disagrees: treat it as a drift of unknown cause)")
    return (f"temperature-driven rate on {axis}: |coef| = {abs(coef) * k:.3g} deg/h per K ({abs(coef):.3g} rad/s/K): "
            f"{WHAT['temperature']}. Regression of the rate on the temperature: slope {check['slope'] * k:.3g} "
            f"+- {check['se'] * k:.2g} deg/h per K (t = {check['t']:.1f}); {verdict}. Commonly caused by "
            f"{CAUSES['temperature']}.")


def explain_trend(rec: dict) -> str:
    """Plain words for the ramp-or-random-walk decision (:mod:`companion.gap.ramp_or_walk`)."""
    walk = rec["named"] == "random_walk"
    head = (f"ramp or random walk: both explain the long-tau rise of the Allan curve (scores {rec['ramp_score']:.1f} "
            f"for the ramp, {rec['random_walk_score']:.1f} for the random walk); the record with its least-squares "
            f"line taken out fits what a random walk of K {rec['K_walk']:.3g} would leave there (deviance "
            f"{rec['dev_walk']:.1f}) {'better' if rec['dev_walk'] < rec['dev_line'] else 'worse'} than nothing left, "
            f"as after a ramp ({rec['dev_line']:.1f}); with the raw curve's difference ({rec['raw']:+.1f}, random "
            f"walk minus ramp) the evidence is {abs(rec['evidence']):.1f} for the {'random walk' if walk else 'ramp'}")
    if walk:
        return (f"{head}: the rise is not a straight line, so the random walk is named (a free random walk in the "
                f"detrended record: LR {rec['lr']:.1f})")
    return (f"{head}: the rise is a straight line, so the ramp is named (a free random walk in the detrended "
            f"record: LR {rec['lr']:.1f})")
