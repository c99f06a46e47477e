"""Independent evidence between look-alikes the Allan curve cannot separate: the periodogram for a sinusoid
(:mod:`companion.gap.spectral`) and the log's temperature channel for a temperature-driven rate
(:mod:`companion.gap.temperature_candidate`)."""

from __future__ import annotations

import math
from typing import NamedTuple

from companion.gap import selection
from companion.gap.spectral import line_evidence
from companion.gap.temperature_candidate import regression_check


class Ruling(NamedTuple):
    """The explanation a piece of independent evidence takes (None: none), and the note that says why."""

    taken: object
    note: str


def spectral_line(ranked, y, rate_hz) -> Ruling:
    """The strongest sinusoid explanation that fell short of its level (chi^2_2(1 - ALPHA) = 18.4, the
    frequency searched over the Allan profile) is taken at the level of a known-shape term
    (chi^2_1(1 - ALPHA_RECAL) = 10.8) when the periodogram confirms a line at its frequency carrying its
    power (:func:`companion.gap.spectral.line_evidence`, itself a test at 1e-3 over the band's bins):
    the frequency is then a property of the data, as a log's filter cut-off is."""
    for x in ranked[:6]:
        if x.effect != "sinusoid" or x.recal:
            continue
        t = x.added_term()
        if x.delta_dev - x.inflation * selection.RECAL_PENALTY <= 0:
            return Ruling(None, "")
        ev = line_evidence(y, rate_hz, t["freq_hz"], t["amplitude"])
        if ev is None or not ev["confirmed"]:
            return Ruling(None, "")
        x.penalty = selection.RECAL_PENALTY
        return Ruling(x, f"sinusoid at {t['freq_hz']:.4g} Hz: LR {x.lr:.1f} on the Allan curve is short of the "
                         f"{selection.add_penalty(2):.1f} of a searched frequency, but the periodogram shows the "
                         f"line ({ev['peak_ratio']:.1f}x the local level at {ev['f_peak']:.4g} Hz, carrying "
                         f"{ev['amplitude_psd'] / t['amplitude']:.2f} of its amplitude): taken at the level of a "
                         f"known frequency, {selection.RECAL_PENALTY:.1f}")
    return Ruling(None, "")


class LineVeto:
    """A veto for :func:`companion.gap.selection.choose`: a sinusoid explanation whose line the periodogram
    rules out (no significant peak in its band, where a line of half its amplitude would show with
    probability >= 1 - 1e-3: :func:`companion.gap.spectral.line_evidence`). Its Allan bump is then some
    other shape: near the Nyquist frequency a line's bump sits on the shortest cluster times, as angle
    quantisation's rise does. Where the periodogram lacks the resolution (a slow line in a short record)
    the sinusoid stays in the running on the Allan curve alone. Calling it returns the reason or None."""

    def __init__(self, y, rate_hz: float):
        self.y = y
        self.rate_hz = rate_hz
        #: periodogram evidence by (log frequency, log amplitude): the same line is asked for at every step
        self.cache: dict = {}

    def __call__(self, x) -> str | None:
        if x.effect != "sinusoid" or x.delta_dev <= 0 or self.y is None:
            return None
        t = x.added_term()
        key = (round(math.log(t["freq_hz"]), 6), round(math.log(max(t["amplitude"], 1e-300)), 6))
        if key not in self.cache:
            self.cache[key] = line_evidence(self.y, self.rate_hz, t["freq_hz"], t["amplitude"])
        ev = self.cache[key]
        if ev is None or not ev["ruled_out"]:
            return None
        return (f"a sinusoid at {t['freq_hz']:.4g} Hz (amplitude {t['amplitude']:.3g}, score {x.score:.1f} on the "
                f"Allan curve) is ruled out by the periodogram: peak {ev['peak_ratio']:.3g}x the local level against "
                f"{ev['threshold']:.3g} needed, where a line of half that amplitude would show with probability "
                f"{ev['power']:.4f}")


#: drift-like effects a temperature-driven rate is a look-alike of on the Allan curve
DRIFTS = ("ramp", "random_walk", "gauss_markov", "sinusoid", "bias_instability")


def thermal_arbitration(ranked, chosen, y_segs, t_smooth, rate_hz) -> Ruling:
    """The temperature channel as independent evidence between look-alikes the Allan curve cannot
    separate: a drift-like winner gives way to the temperature explanation when that one also passes its
    level on the Allan curve (score > 0) and the direct regression of the rate on the channel confirms its
    coefficient; a temperature winner that the regression does not confirm gives way to the best other
    explanation."""
    temp = next((x for x in ranked if x.effect == "temperature" and not x.recal), None)
    if chosen.effect == "temperature":
        chk = regression_check(y_segs, t_smooth, chosen.added_term()["coef"], rate_hz)
        if chk["confirmed"]:
            return Ruling(chosen, "")
        other = next((x for x in ranked if x.effect != "temperature" and x.score > 0), None)
        return Ruling(other, "a temperature-shaped drift fits the Allan curve but the regression on the "
                             f"temperature channel does not confirm it (slope t = {chk['t']:.1f}, ratio "
                             f"{chk.get('ratio', 0):.2g}): not named")
    if chosen.effect in DRIFTS and temp is not None and temp.score > 0:
        chk = regression_check(y_segs, t_smooth, temp.added_term()["coef"], rate_hz)
        if chk["confirmed"]:
            return Ruling(temp, f"{chosen.effect} and a temperature-driven rate both explain the Allan curve "
                                f"(scores {chosen.score:.1f}, {temp.score:.1f}); the temperature channel decides: "
                                f"regression slope t = {chk['t']:.1f}, coefficient ratio {chk['ratio']:.2f}")
        return Ruling(chosen, f"{chosen.effect} and a temperature-driven rate both explain the Allan curve "
                              f"(scores {chosen.score:.1f}, {temp.score:.1f}); the temperature channel does not "
                              f"confirm the latter beyond a straight drift (regression t = {chk['t']:.1f}, "
                              f"coefficient ratio {chk['ratio']:.2g}): {chosen.effect} is named")
    return Ruling(chosen, "")
