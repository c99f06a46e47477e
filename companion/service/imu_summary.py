"""The run summary of a :class:`~companion.service.pipeline.Pipeline` per IMU: rate, still data used,
health, counts, the active faults in words, the notes, and per axis the final terms against the baseline
(the rows :func:`companion.service.runner.summary_lines` prints)."""

from __future__ import annotations

from companion.health.detector import STATE_NAMES
from companion.health.faults import FAULT, FaultEvent
from companion.service.rate_tracker import RATE_SWITCHES_LOGGED


def summary_rows(pipeline) -> list[dict]:
    """One row per IMU, sorted by instance."""
    out = []
    for imu, ch in sorted(pipeline.channels.items()):
        notes = (ch.too_slow(), ch.all_zero(), ch.transient_note(), rate_note(pipeline, ch))
        row = {"imu": imu, "message": ch.message, "rate_hz": ch.rate_hz, "still_s": ch.fed_s,
               "other_rates": ch.kept_rates(), "health": STATE_NAMES[pipeline.health(ch)], "counts": ch.counts,
               "axes": {}, "faults": fault_texts(pipeline, ch), "notes": [n for n in notes if n]}
        if ch.fast and ch.fed_s > 0:
            ch.flush()
            for ax in ch.axes:
                terms = final_terms(pipeline, ch, ax)
                row["axes"][ax] = {"current": ch.current_params(ax, terms), "terms": terms,
                                   "baseline": pipeline.baseline.get(imu, ax) if pipeline.baseline else None}
        out.append(row)
    return out


def fault_texts(pipeline, ch) -> list[str]:
    """The active faults of an IMU in plain words, most severe first (what the STATUSTEXTs said)."""
    out = []
    for kind, ax in ch.faults.active():
        if kind == "disagree":
            ev = FaultEvent(ch.imu, ax, kind, FAULT, detail=pipeline.group.detail(ch.imu, ax))
        elif kind == "allan":
            r, p = ch.allan_worst(ax)
            ev = FaultEvent(ch.imu, ax, kind, FAULT, detail=f"degrading: {p} {r:.1f}x baseline")
        else:
            ev = ch.faults.event_of(kind, ax)
        out.append(ev.text())
    return out


def rate_note(pipeline, ch) -> str | None:
    """The summary's word on an IMU whose rate switched more often than the log said line by line."""
    if ch.rate_switches <= RATE_SWITCHES_LOGGED:
        return None
    rates = [r for _, imu, old, new in pipeline.rate_log if imu == ch.imu for r in (old, new) if r]
    if not rates:
        return None
    lo, hi = min(rates), max(rates)
    return (f"IMU{ch.imu}: the stream's rate changed {ch.rate_switches} times, between {lo:.1f} and {hi:.1f} Hz: "
            "the Allan estimates of each rate are kept apart (a rate is another sampling of the noise), so each "
            "holds only part of the still data (on a live link: ask for one rate, --rate, and keep other clients "
            "from changing it)")


def final_terms(pipeline, ch, ax: str) -> list[dict]:
    """The terms of the summary (a fresh model selection on all data fed so far), computed once per state
    of the estimators: :func:`send_final` sends exactly these, so the last report and the summary agree."""
    ch.flush()
    key = (ch.imu, ax)
    stamp = (id(ch.fast.get(ax)), ch.fed_s)
    hit = pipeline._final.get(key)
    if hit is None or hit[0] != stamp:
        hit = pipeline._final[key] = (stamp, ch.report_terms(ax, full=True))
    return hit[1]


def send_final(pipeline) -> int:
    """At the end of a live run: the summary's terms of every reported IMU set and sent at once (values,
    sigmas, bounds), then its health and fault code, so the last values a ground station got are the
    summary's. Returns the number of NAMED_VALUE_FLOAT sent."""
    n = 0
    reporter = pipeline.reporter
    for imu, ch in sorted(pipeline.channels.items()):
        if not ch.fast or ch.fed_s < pipeline.cfg.min_report_s:
            continue
        for ax in ch.axes:
            reporter.set_online_terms(imu, ax, final_terms(pipeline, ch, ax))
        pipeline._set_state(ch)
        prefix = f"IMU{imu}"
        t = ch.last_t or 0.0
        for name, v in sorted(reporter.values.items()):
            if name.startswith(prefix) and not name[len(prefix)].isdigit():
                reporter.send_now(name, v, t)
                n += 1
    return n
