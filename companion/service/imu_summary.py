"""The run summary of a :class:`~companion.service.pipeline.Pipeline` per IMU: rate, still data used,
health, counts, the active faults in words, the notes, and per axis the final terms against the baseline
(the rows :func:`companion.service.run_session.summary_lines` prints)."""

from __future__ import annotations

import math

from companion.health.degradation import STATE_NAMES
from companion.health.block_stats import MIN_NOISE_SAMPLES
from companion.health.faults import FaultEvent
from companion.health.hold import FAULT
from companion.service.blocks import MIN_WATCH_RATE_HZ
from companion.service.channel import INT16_MESSAGES
from companion.service.final_analysis import final_analysis
from companion.service.rate_tracker import RATE_SWITCHES_LOGGED


def summary_rows(pipeline) -> list[dict]:
    """One row per IMU, sorted by instance."""
    out = []
    for imu, ch in sorted(pipeline.channels.items()):
        notes = (too_slow_note(ch), all_zero_note(ch), transient_note(ch), rate_note(pipeline, ch),
                 below_resolution_note(pipeline, ch))
        row = {"imu": imu, "message": ch.message, "rate_hz": ch.rate_hz, "still_s": ch.fed_s,
               "other_rates": ch.kept_rates(), "health": STATE_NAMES[pipeline.health(ch)], "counts": ch.counts,
               "axes": {}, "faults": fault_texts(pipeline, ch), "notes": [n for n in notes if n],
               # a float gyro whose every sample read exactly 0: dead even where the record is too short for the
               # dead test (an int16 gyro may be a quiet one below its 1 mrad/s step): the exit status says it
               "all_zero": bool(notes[1]) and ch.message not in INT16_MESSAGES}
        if ch.fast and ch.fed_s > 0:
            ch.flush()
            for ax in ch.axes:
                terms = final_terms(pipeline, ch, ax)
                row["axes"][ax] = {"current": ch.current_params(ax, terms), "terms": terms,
                                   "baseline": pipeline.baseline.get(imu, ax) if pipeline.baseline else None}
            # analyze's figure on the still samples fed (service.final_analysis), beside the online terms
            row["final"] = final_analysis(ch)
        out.append(row)
    return out


def fault_texts(pipeline, ch) -> list[str]:
    """The active faults of an IMU in plain words, most severe first (what the STATUSTEXTs said)."""
    out = []
    for kind, ax in ch.faults.active():
        if kind == "disagree":
            ev = FaultEvent(ch.imu, ax, kind, FAULT, detail=pipeline.group.detail(ch.imu, ax))
        elif kind == "allan":
            r, p = ch.allan.worst(ax)
            ev = FaultEvent(ch.imu, ax, kind, FAULT, detail=f"degrading: {p} {r:.1f}x baseline")
        else:
            ev = ch.faults.event_of(kind, ax)
        out.append(ev.text())
    return list(dict.fromkeys(out))  # one line per fault: two detectors may hold the same one (block, sample)


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
    """At the end of a live run: the summary's online terms of every reported IMU set and sent at once (values,
    sigmas, bounds), then its health and fault code, so the last values a ground station got are the
    summary's ``online`` lines (its final analysis, analyze's figure, is printed, not sent). Returns the number
    of NAMED_VALUE_FLOAT sent."""
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


def all_zero_note(ch) -> str | None:
    """A note when every gyro sample of the run read exactly 0 but no fault says so (a record too short
    for the dead test); else None."""
    n = ch.cutter.counts["samples"]
    if ch.gyro_moved or n == 0 or ch.faults.active():
        return None
    dur = f" ({n / ch.rate_hz:.1f} s)" if ch.rate_hz else ""
    why = ("dead, or a gyro quieter than the message's 1 mrad/s at rest" if ch.message in INT16_MESSAGES
           else "dead, absent or not started (a live gyro's float never reads exactly 0)")
    return (f"IMU{ch.imu}: gyro X, Y, Z read exactly 0 in all {n} samples{dur}: {why}; too few for the dead "
            "test to name it")


def transient_note(ch) -> str | None:
    """What the Allan estimates leave out for transient faults (the summary's note), or None."""
    if ch.restored_s <= 0:
        return None
    return (f"IMU{ch.imu}: {ch.restored_s:.0f} s of still data fed during noise or spike faults were taken "
            "back out of the Allan estimates when the faults cleared")


def too_slow_note(ch) -> str | None:
    """What a stream too slow for the per-IMU fault tests is watched for, in words; None when it is not."""
    if not ch.rate_hz:
        slow = ch.cutter.too_slow_hz
        if slow is None:
            return None
        hint = " (is the CSV's time column in ms or us? --time-unit)" if ch.message == "CSV" else ""
        return (f"IMU{ch.imu}: its samples come {1.0 / slow:.3g} s apart ({slow:.2g} Hz), below the "
                f"{MIN_WATCH_RATE_HZ:g} Hz companion watches: not judged{hint}")
    per_block = int(math.floor(ch.cfg.block_s * ch.rate_hz + 0.5)) + 1
    if per_block >= MIN_NOISE_SAMPLES:
        return None
    return (f"IMU{ch.imu}: at {ch.rate_hz:.1f} Hz a {ch.cfg.block_s:g}-s block holds {per_block} samples, "
            f"fewer than the {MIN_NOISE_SAMPLES} the noise, bias, spikes and stuck-at-rest tests need: watched are a "
            "gyro that holds one value (0: dead) while the vehicle moves, sample by sample, a reading at the "
            "message's range, a disagreement with another IMU and the Allan terms, whose Q and N are aliased "
            f"below {2.0 * ch.rate_hz:.2g} Hz of noise bandwidth (stream it at 4 Hz or more)")


def below_resolution_note(pipeline, ch) -> str | None:
    """A note for an integer-coded gyro whose axes read 0 at rest but changed while the vehicle moved
    (health/frozen_watch.py): alive, its noise at rest below the message's step; else None."""
    if ch.message not in INT16_MESSAGES:
        return None
    axes = pipeline.frozen.below_resolution(ch.imu)
    if not axes:
        return None
    names = ", ".join(ax[1].upper() for ax in axes)
    step = (ch.gyro_lsb or 1e-3) * 1e3
    return (f"IMU{ch.imu}: gyro {names} read exactly 0 at rest and changed while the vehicle moved: alive, its noise "
            f"at rest below {ch.message}'s {step:.3g} mrad/s step (not dead); ask for HIGHRES_IMU (float rad/s) "
            "to measure it at rest")
