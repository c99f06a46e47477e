"""The result of the gap workflow (:func:`companion.gap.workflow.run_gap`) and what it says about the gap
left: G over the cluster times the record resolves, and a long-tau term named from too short a record."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from companion.gap.compare import Measured, gap_metric, model_avar
from companion.gap.null import resolved_subset

#: the gap metric G is 1 on average for a right model; above this the model does not fit within the noise
#: (the null benchmark of docs/gap.md gives G's spread)
NOISE_FLOOR_G = 2.0


@dataclass
class GapResult:
    axis: str
    measured: Measured
    terms_before: list
    terms_after: list
    gap_before: float
    gap_after: float
    gap_sim_before: float | None = None
    gap_sim_after: float | None = None
    sim_check_before: float | None = None  # simulated vs analytic, model before
    sim_check_after: float | None = None
    sim_avar_before: np.ndarray | None = None
    sim_avar_after: np.ndarray | None = None
    regions_before: list = field(default_factory=list)
    regions_after: list = field(default_factory=list)
    added: list = field(default_factory=list)  # [{"effect", params..., "ci95", "explanation"}]
    recalibrated: list = field(default_factory=list)  # [{"effect", "param", "model", "fitted", "ratio", ...}]
    iterations: list = field(default_factory=list)
    fits_within_noise: bool = False
    notes: list = field(default_factory=list)
    quantization: dict | None = None
    alternatives: list = field(default_factory=list)  # per chosen step: its runner-up and the margin
    #: G after over the cluster times the record resolves (tau <= a tenth of the longest segment: the
    #: analysis' rule, companion.allan.fit.RESOLVE_RECORD_FACTOR), when longer ones were measured
    gap_after_resolved: float | None = None
    resolved_tau_max: float | None = None
    #: when a gap remains: G's spread for the model after on this record's layout (companion.gap.null)
    gap_after_null: dict | None = None
    #: the analysis' white level of the same data ({"N", "ci95"} or {"N": None, "bound"}, SI), when the
    #: caller computed it (``companion gap`` on a log): the N the datasheet verdict reports
    white: dict | None = None

    def to_dict(self) -> dict:
        m = self.measured
        return {
            "axis": self.axis,
            "gap_before": self.gap_before,
            "gap_after": self.gap_after,
            "gap_metric": "G = mean_i nu_i (a_i/s_i - 1 - ln(a_i/s_i)) / E0(nu_i); 1 on average when the model is right",
            "noise_floor": NOISE_FLOOR_G,
            "gap_after_resolved": self.gap_after_resolved,
            "resolved_tau_max": self.resolved_tau_max,
            "gap_after_null": self.gap_after_null,
            "white": self.white,
            "gap_sim_before": self.gap_sim_before,
            "gap_sim_after": self.gap_sim_after,
            "sim_check_before": self.sim_check_before,
            "sim_check_after": self.sim_check_after,
            "fits_within_noise": self.fits_within_noise,
            "added": self.added,
            "recalibrated": self.recalibrated,
            "iterations": self.iterations,
            "alternatives": self.alternatives,
            "disagreements_before": [r.as_dict() for r in self.regions_before],
            "disagreements_after": [r.as_dict() for r in self.regions_after],
            "terms_before": self.terms_before,
            "terms_after": self.terms_after,
            "quantization": self.quantization,
            "notes": self.notes,
            "measured": {"tau": m.tau.tolist(), "adev": np.sqrt(m.avar).tolist(), "edf": m.nu_raw.tolist(),
                         "rate_hz": m.rate_hz, "samples": m.n},
        }


def strongest_left(res: GapResult) -> str:
    """'; the strongest explanation left, ...' from the last iteration's ranking when nothing was chosen."""
    last = res.iterations[-1] if res.iterations else {}
    t = last.get("test")
    if not t or last.get("chosen") or t["lr"] <= 0:
        return ""
    top = (last.get("explanations") or [{}])[0]
    params = ", ".join(f"{k} = {v:.3g}" for k, v in top.get("params", {}).items())
    params = f" ({params})" if params else ""
    return (f"; the strongest explanation left, {t['effect']}{params}, has LR {t['lr']:.1f} < {t['threshold']:.1f}: "
            "suggestive, not significant at the documented level")


def record_rule_notes(res: GapResult, record_s: float, rate_hz: float) -> None:
    """A long-tau term added from a record shorter than the analysis needs to resolve it
    (:func:`companion.allan.fit.record_needed`): the gap is real, its size is not pinned -- `companion analyze`
    reports a bound for it on the same data, and the two must not read as a contradiction."""
    from companion.allan.fit import record_needed

    added = {a["effect"] for a in res.added}
    plain = [t for t in res.terms_after if t.get("effect") in ("white_noise", "bias_instability", "random_walk",
                                                                "quantization", "ramp")]
    for effect, need in record_needed(plain, 1.0 / rate_hz).items():
        if effect in added and need > record_s:
            res.notes.append(f"{effect} is named from {record_s:.3g} s of data, shorter than the {need:.3g} s a "
                             "resolved value needs (the analysis' record rule): the curve rises there, but the "
                             "size is not pinned; `companion analyze` gives it as a bound on the same data")


def resolved_gap(res: GapResult, meas: Measured, record_s: float) -> None:
    """G after over the cluster times the record resolves: tau up to a tenth of the longest segment, where
    an Allan variance still has an EDF of about 5 or more whatever the noise (the analysis' rule for a
    long-tau term, companion.allan.fit.RESOLVE_RECORD_FACTOR). Longer octaves are measured and used by the
    fits, but a gap carried by them alone is one the record cannot tell from noise of a few EDF."""
    from companion.allan.fit import RESOLVE_RECORD_FACTOR

    tau_max = record_s / RESOLVE_RECORD_FACTOR
    sub = resolved_subset(meas, tau_max)
    if sub is None:
        return
    res.gap_after_resolved = gap_metric(sub, model_avar(res.terms_after, sub.tau, meas.rate_hz))
    res.resolved_tau_max = float(tau_max)


def resolved_text(res: GapResult, meas: Measured) -> str:
    if res.gap_after_resolved is None:
        return ""
    out = meas.tau > res.resolved_tau_max
    edf = ", ".join(f"{v:.0f}" for v in meas.nu_raw[out])
    return (f"; over the cluster times the record resolves (tau <= {res.resolved_tau_max:.3g} s, a tenth of the "
            f"record) G = {res.gap_after_resolved:.2f}: the rest sits in {int(out.sum())} longer octave(s) of EDF "
            f"{edf}")
