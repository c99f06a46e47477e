"""The words and the JSON document of a gap run on a log: the report of one axis (model before, gap
before, the regions outside the band, each step's test, what was added or recalibrated, model after),
the lines about the log (model source, still data, filter cut-off, rate), and the header of the updated
model file. Plain values in, strings and dicts out: no file is read or written here."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.errors import CompanionError
from companion.gap.explain import datasheet_verdict, describe_term
from companion.gap.gap_result import NOISE_FLOOR_G, GapResult

#: still samples an axis needs in all for an Allan variance worth comparing
MIN_STILL_SAMPLES = 64
#: samples the longest still segment needs (the shortest cluster time's estimate needs a few clusters)
MIN_SEGMENT_SAMPLES = 16
#: relative difference of the model's rate_hz from the data's beyond which the report says which is used
RATE_MISMATCH = 0.02
#: explanations named per step in the report (the JSON has the ranking's head)
REPORTED = 3


@dataclass
class LogContext:
    """What the report says about the log beside the workflow's result."""

    source: str  #: the log as given
    label: str  #: the IMU stream's label
    source_model: str  #: where the model came from (a file, or a datasheet with its sources)
    selection_text: str  #: the still selection in words
    selection: dict  #: the still selection as JSON
    ranges_s: list  #: [start, end] of each still segment used, s
    cutoff_hz: float | None  #: low-pass cut-off of the logged data
    cutoff_from_option: bool  #: the cut-off came from --cutoff, not from the log's parameters
    model_rate_hz: float
    rate_hz: float  #: the data's rate
    sheet: dict | None = None  #: the datasheet entry the model came from


def still_segments(col, temp, ranges, source, axis: str) -> tuple[list, list]:
    """The finite samples of ``col`` (and the temperature ``temp`` beside them, when there is one) in each
    still range [a, b)."""
    segs, tsegs = [], []
    for a, b in ranges:
        y = col[a:b]
        ok = np.isfinite(y)
        segs.append(y[ok])
        if temp is not None:
            tsegs.append(np.asarray(temp[a:b], dtype=float)[ok])
    if sum(y.shape[0] for y in segs) < MIN_STILL_SAMPLES or max(y.shape[0] for y in segs) < MIN_SEGMENT_SAMPLES:
        raise CompanionError(f"{source}: only {sum(y.shape[0] for y in segs)} still samples on {axis}; "
                             f"need at least {MIN_STILL_SAMPLES}")
    return segs, tsegs


def _iteration_lines(it: dict) -> list[str]:
    """A step of the workflow: its ranking's head, the tests behind its choice, the runner-up."""
    ex = it.get("explanations") or []
    top = "; ".join(f"{x['explanation']} {x['score']:.1f}" for x in ex[:REPORTED]) or "none fits above zero"
    out = [f"iteration {it['iteration']}: explanations by score (dD - overdispersion x penalty): {top}; "
           f"chosen: {it['chosen'] or 'none significant'}"]
    nt = it.get("nested")
    if nt:
        kept = "kept" if nt["lr"] < nt["threshold"] else "rejected"
        out.append(f"  gauss_markov vs its {nt['limit']} limit: LR {nt['lr']:.1f} (dD {nt['lr_raw']:.1f} / "
                   f"overdispersion {nt['inflation']:.2f}), {nt['threshold']:.1f} needed: {nt['limit']} {kept}")
    t = it.get("test")
    if t:
        verdict = "significant" if t["lr"] > t["threshold"] else "not significant"
        out.append(f"  evidence for {t['effect']}: LR {t['lr']:.1f} (dD {t['lr_raw']:.1f} / overdispersion "
                   f"{t['inflation']:.2f}), {t['threshold']:.1f} needed: {verdict}")
    ru = it.get("runner_up")
    if t and ru:
        out.append(f"  runner-up {ru['explanation']}: LR {ru['lr']:.1f} (dD {ru['delta_dev']:.1f} / overdispersion "
                   f"{ru['inflation']:.2f}), {ru['penalty']:.1f} needed, score {ru['score']:.1f} against "
                   f"{t.get('score', float('nan')):.1f}")
    return out


def _before_lines(r: GapResult) -> list[str]:
    """The model before, its gap and where the measurement leaves its band."""
    axis = r.axis
    out = ["model before:"]
    out += [f"  {describe_term(t, axis)}" for t in r.terms_before] or ["  (no terms)"]
    sim = ""
    if r.gap_sim_before is not None:
        sim = (f"; vs simulated model G_sim = {r.gap_sim_before:.3g} (simulation vs analytic "
               f"{r.sim_check_before:.3g})")
    out.append(f"gap before: G = {r.gap_before:.3g} (noise floor {NOISE_FLOOR_G:g}){sim}")
    if not r.regions_before:
        return out + ["  the measurement stays inside the model's 95 % band everywhere"]
    out.append("  where the measurement leaves the model's 95 % band:")
    out.append(f"  {'tau range (s)':>19}  {'measured':>8}  {'worst tau':>9}  {'ADEV ratio':>10}  {'z':>6}")
    for g in r.regions_before:
        out.append(f"  {g.tau_lo:9.3g}-{g.tau_hi:<9.3g}  {g.direction:>8}  {g.worst_tau:9.3g}  "
                   f"{g.worst_ratio:10.3g}  {g.worst_z:6.1f}" + ("  (single point)" if g.points == 1 else ""))
    return out


def format_report(r: GapResult, source: str, label: str) -> str:
    """The report of one axis: the model before and its gap, each step, what changed, the model after."""
    axis = r.axis
    m = r.measured
    out = [f"gap: {source} {label} axis {axis}: {m.n} samples at {m.rate_hz:.4g} Hz, tau {m.tau[0]:.3g}-"
           f"{m.tau[-1]:.4g} s ({len(m.tau)} octave points)"]
    out += _before_lines(r)
    for it in r.iterations:
        out += _iteration_lines(it)
    out += ["added: " + a["explanation"] for a in r.added]
    out += ["recalibrated: " + e["text"] for e in r.recalibrated if e["verdict"] != "consistent"]
    out += ["note: " + n for n in r.notes]
    if r.terms_after is not r.terms_before:
        out.append("model after:")
        out += [f"  {describe_term(t, axis)}" for t in r.terms_after]
        sim = f"; vs simulated model G_sim = {r.gap_sim_after:.3g}" if r.gap_sim_after is not None else ""
        out.append(f"gap after: G = {r.gap_after:.3g}{sim}")
        if r.regions_after:
            out.append("  remaining disagreements: " + "; ".join(
                f"{g.tau_lo:.3g}-{g.tau_hi:.3g} s {g.direction} (x{g.worst_ratio:.3g})" for g in r.regions_after))
    return "\n".join(out)


def axis_text(r: GapResult, ctx: LogContext) -> str:
    """The report of one axis with the lines about the log; with a datasheet, its verdict first."""
    text = format_report(r, ctx.source, ctx.label)
    if ctx.sheet is not None:
        text = datasheet_verdict(r.recalibrated, ctx.sheet["name"], r.axis, r.added, white=r.white) + "\n" + text
    text += f"\nmodel: {ctx.source_model}"
    text += f"\nstill data used: {ctx.selection_text}; {ctx.label}: {len(ctx.ranges_s)} segment(s), " + \
        ", ".join(f"{t0:.1f}-{t1:.1f} s" for t0, t1 in ctx.ranges_s)
    if ctx.cutoff_hz:
        text += f"\nlow-pass cut-off of the logged gyro data: {ctx.cutoff_hz:g} Hz " + \
            ("(--cutoff)" if ctx.cutoff_from_option else "(the log's parameter)")
    if abs(ctx.model_rate_hz - ctx.rate_hz) > RATE_MISMATCH * ctx.rate_hz:
        text += (f"\nnote: the model's rate_hz {ctx.model_rate_hz:g} differs from the data's {ctx.rate_hz:.4g} Hz; "
                 "the comparison uses the data's rate")
    return text


def axis_doc(r: GapResult, ctx: LogContext, text: str) -> dict:
    """The JSON document of one axis: the workflow's result and the log's context."""
    doc = r.to_dict()
    doc.update(source=ctx.source, stream=ctx.label, selection=ctx.selection, ranges_s=ctx.ranges_s,
               cutoff_hz=ctx.cutoff_hz, model_source=ctx.source_model)
    if ctx.sheet is not None:
        doc["datasheet"] = {k: v for k, v in ctx.sheet.items() if k != "si"} | {"si": ctx.sheet["si"]}
        doc["verdict"] = text.splitlines()[0]
    return doc


def left_lines(left_out: dict) -> list[str]:
    """Per axis, the log's own terms left out of the updated model ("gx: low-pass 20 Hz ...")."""
    return [f"{a}: {', '.join(v)}" for a, v in left_out.items() if v]


def model_header(source: str, label: str, axes, docs, rate_hz: float, model_rate_hz: float, left: list) -> str:
    """The comment block of the updated model file (``left``: :func:`left_lines`)."""
    header = [f"updated by companion gap from {source} ({label}), axes {', '.join(axes)}: "
              + ", ".join(f"{d['axis']} gap {d['gap_before']:.3g} -> {d['gap_after']:.3g}" for d in docs),
              f"rate_hz: the data's {rate_hz:.6g} Hz" + (f" (the input model had {model_rate_hz:g})"
                                                         if abs(model_rate_hz - rate_hz) > 1e-9 * rate_hz else "")]
    if left:
        header.append("not written, properties of the log that gap derives from it on every run: "
                      + "; ".join(left))
    return "\n".join(header)
