"""One source end to end: load it, select its still segments, analyse every IMU stream."""

from __future__ import annotations

import math

from companion.errors import EXIT_FAULTS, CompanionError, NoUsableData

#: Log parameters copied into the source summary (low-pass filters, fast sampling, batch logging).
SUMMARY_PARAMS = ("INS_GYRO_FILTER", "INS_ACCEL_FILTER", "INS_FAST_SAMPLE", "INS_LOG_BAT_OPT", "INS_LOG_BAT_MASK",
                  "IMU_GYRO_CUTOFF", "IMU_ACCEL_CUTOFF", "IMU_INTEG_RATE")


def analyze_source(spec, axes, taus="octave", *, config=None, duration=None, start=None, end=None,
                   use_all=False, min_still=10.0, online=False, progress=None, warn=None,
                   time_unit=None) -> tuple[list[dict], dict]:
    """Load one source, select its still segments and analyse every IMU stream: (stream entries, summary).

    The summary holds the source, the inspect notes (the same sentences ``companion inspect`` prints) and
    the still selection (:func:`companion.sources.still.select_still`). ``progress(steps, values)``, if
    given, makes an object with ``step(label)`` and ``close()``; ``warn(text)`` receives the --taus cluster
    times beyond the record. ``time_unit``: of a CSV's time column ("s", "ms", "us")."""
    from companion.analysis.notes import notes as inspect_notes
    from companion.analysis.stream import analyze_stream, stream_filters
    from companion.sources import load
    from companion.sources.still import select_still

    res = load(spec, config=config, duration=duration, time_unit=time_unit)
    streams = res.imu_streams()
    require_a_rate(spec, streams)
    if isinstance(taus, str):
        check_taus_reachable(taus, streams, warn)
    sel = select_still(streams, res.meta, start=start, end=end, use_all=use_all, min_segment_s=min_still)
    summary = {"source": str(spec), "notes": inspect_notes(res), "selection": sel.to_dict(),
               "format": res.meta.get("format", "tlog/csv/live"),
               "params": {k: v for k, v in (res.meta.get("params") or {}).items() if k in SUMMARY_PARAMS}}
    summary["notes"] += [n for n in sel.notes if sel.intervals]
    summary["frozen_gyros"] = frozen_gyros(streams, axes, sel, res.meta, summary["notes"], warn)
    dead = dead_gyros(streams)
    # a gyro fault among the axes asked for: the exit status says it (companion.errors.EXIT_FAULTS)
    summary["dead_gyros"] = dead_gyros(streams, axes)
    ap = autopilot_entry(res, streams, dead, sel)
    if not sel.intervals:
        # a dead gyro, and an IMU its autopilot flags, are said first: the reason to look at this log
        said = dead + [f"autopilot: {c['line']}" for c in (ap or {}).get("cross_check", []) if c["autopilot_flagged"]]
        first = "; ".join(said) + "; " if said else ""
        reason = f"{spec}: {first}{sel.notes[0] if sel.notes else 'no still data'} ({sel.describe()})"
        if summary["dead_gyros"]:  # a dead gyro stays the error: the reason to look at this log
            raise CompanionError(reason, EXIT_FAULTS)
        from companion.analysis.condition_hook import entries_without_still  # ground and flight instead

        if ap is not None:
            summary["autopilot"] = ap
        return entries_without_still(spec, streams, res.meta, summary, taus, reason), summary
    if dead and warn is not None:
        for d in dead:
            warn(d)
    if ap is not None:
        summary["autopilot"] = ap
    total = sum(s.samples for s in streams) * len(axes)
    bar = progress(len(streams) * len(axes), total) if progress is not None else None
    entries = []
    try:
        for s in streams:
            ranges = sel.ranges(s)
            if not ranges:  # say so: a stream must never vanish from the table silently
                if sel.excluded_s(s.key.instance) > 0:
                    summary["notes"].append(f"{s.key.label()}: not analysed: its gyro changed alone wherever the "
                                            "vehicle was still (the note on IMU instance "
                                            f"{s.key.instance} above)")
                else:
                    a, b = s.longest_segment()
                    fix = ("; --all analyses it over the whole record (its longest gap-free piece holds "
                           f"{b - a} samples)" if b - a >= 16 and not use_all else "")
                    summary["notes"].append(f"{s.key.label()}: not analysed: {s.samples} samples at "
                                            f"{s.rate_hz:.3g} Hz, none of its gap-free pieces inside the still "
                                            f"stretches holds 16 samples (too short for any Allan estimate){fix}")
                continue
            e = analyze_stream(s, axes, taus, bar, online=online, ranges=ranges, filters=stream_filters(s, res.meta))
            e["source"] = str(spec)
            if ap is not None:
                e["autopilot"] = next((c for c in ap["cross_check"] if c["instance"] == s.key.instance), None)
            entries.append(e)
    finally:
        if bar is not None:
            bar.close()
    from companion.analysis.condition_hook import add_conditions  # each stream's ground and flight figures

    add_conditions(entries, streams, res.meta, summary)
    return entries, summary


def nothing_analysed(summaries) -> str:
    """The refusal of a run whose every stream was left out: what the selection kept and each stream's reason
    (which names --all where that would analyse the stream)."""
    parts = []
    for sm in summaries:
        reasons = [n for n in sm["notes"] if ": not analysed: " in n]
        parts.append(f"{sm['source']} ({sm['selection']['description']}): " + ("; ".join(reasons) or "no stream"))
    return "no IMU stream analysed: " + "; ".join(parts)


def autopilot_entry(res, streams, dead: list[str], sel) -> dict | None:
    """The autopilot's own view of its IMUs beside our findings (dead gyros, a gyro that changed alone)."""
    from companion.sources.autopilot_health import check_report

    ours: dict[int, list[str]] = {}
    for s in streams:
        found = [d for d in dead if d.startswith(s.key.label())]
        if sel.excluded_s(s.key.instance) > 0:
            found.append(f"gyro changed alone while the vehicle was still ({sel.excluded_s(s.key.instance):.0f} s)")
        ours[s.key.instance] = found
    return check_report(res.meta.get("autopilot"), ours, sorted(ours))


def frozen_gyros(streams, axes, sel, meta: dict, notes: list, warn=None) -> list[str]:
    """The sentences naming every gyro axis (among ``axes``) frozen while the vehicle moved
    (analysis/frozen_spans.py), said in ``notes`` and through ``warn``; the IMU's frozen spans are left out of
    its still analysis (``sel.excluded``) and, through ``meta["frozen"]``, of the ground and flight figures."""
    from companion.analysis.frozen_spans import frozen_spans, leave_out

    spans = frozen_spans(streams, axes)
    leave_out(spans, sel, meta)
    out = [sp.text() for sp in spans]
    notes += out
    for text in out if warn is not None else []:
        warn(text)
    return out


def dead_gyros(streams, axes=None) -> list[str]:
    """The sentences naming every dead gyro (health.dead) of the IMU streams; with ``axes``, only the streams
    with a dead axis among them (a model of gx alone simulates gy, gz as 0: not a fault of an analysis of gx)."""
    from companion.health.dead import constant_axes, dead_gyro_text
    from companion.samples import GYRO_AXES

    out = []
    for s in streams:
        if axes is not None and not any(GYRO_AXES[a] in axes for a in constant_axes(s.gyro)):
            continue
        text = dead_gyro_text(s.key.label(), s.gyro, getattr(s, "gyro_lsb", None))
        if text:
            out.append(text)
    return out


def require_a_rate(spec, streams) -> None:
    """A source whose every IMU stream is too short for a sample rate (a log cut after a few messages) has
    nothing to analyse: said as such, not as a --taus or still-selection problem."""
    if streams and not any(s.rate_hz > 0 and math.isfinite(s.rate_hz) for s in streams):
        each = ", ".join(f"{s.key.label()} {s.samples} sample(s)" for s in streams)
        raise NoUsableData(f"{spec}: too few samples for a sample rate in every IMU stream ({each}): nothing to "
                           "analyse")


def check_taus_reachable(spec: str, streams, warn=None) -> None:
    """--taus cluster times beyond a record are reported through ``warn``, or refused when none is reachable."""
    from companion.analysis.taus import taus_beyond

    reachable = False
    for st in streams:
        a, b = st.longest_segment()
        rate = float(st.rate_hz)
        if not (rate > 0 and math.isfinite(rate)):
            continue
        beyond = taus_beyond(spec, b - a, rate)
        asked = taus_beyond(spec, 0, rate)  # every valid seconds value (none for octave etc.)
        if len(beyond) < len(asked) or not asked:
            reachable = True
        if beyond and warn is not None:
            longest = (b - a) // 2 / rate
            warn(f"--taus {', '.join(f'{x:g}' for x in beyond)} s beyond "
                 f"{st.key.label()}: its longest segment ({(b - a) / rate:.0f} s) reaches tau {longest:.4g} s; "
                 "not shown")
    if streams and not reachable:
        raise CompanionError(f"--taus {spec}: every cluster time is beyond the record (overlapping Allan deviation "
                             "reaches half the longest gap-free segment)")
