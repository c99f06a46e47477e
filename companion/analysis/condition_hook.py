"""The ground and flight conditions in ``analyze``'s report: the hook of
:func:`companion.analysis.source.analyze_source` (numpy and scipy only).

:func:`add_conditions` gives every stream entry its ``flight`` and ``ground`` (:mod:`companion.analysis.inflight`);
:func:`entries_without_still` makes the entries of a log without still data when it has either condition,
so that it is analysed, not refused.
"""

from __future__ import annotations

from companion.analysis.inflight import CONDITIONS, condition_reports
from companion.errors import CompanionError


def _has_figures(cond: dict) -> bool:
    return any(c.get(k, {}).get("axes") for c in cond.values() for k in CONDITIONS)


def _filters(meta):
    from companion.analysis.stream import stream_filters

    return lambda s: stream_filters(s, meta)


def add_conditions(entries: list, streams, meta: dict, summary: dict) -> None:
    """Each entry of ``entries`` (one per analysed stream, in ``streams``' order by key) gains ``flight`` and
    ``ground``; the summary's notes get the one-IMU sentence where it applies."""
    still = {(e["sysid"], e["compid"], e["message"], e["instance"]): e for e in entries}
    by_key = {s.key: still.get((s.key.sysid, s.key.compid, s.key.message, s.key.instance)) for s in streams}
    cond, notes = condition_reports(streams, meta, _filters(meta), {k: v for k, v in by_key.items() if v})
    summary["notes"] += notes
    source = next((e["source"] for e in entries if "source" in e), None)
    added = False
    for s in streams:
        e = by_key.get(s.key)
        if e is None and _has_figures({s.key: cond.get(s.key, {})}):
            # a redundant IMU left out at rest (its gyro changed alone while the vehicle was still) keeps its
            # ground and flight figures: an IMU that misbehaves is the one whose in-flight noise matters
            e = by_key[s.key] = _condition_only_entry(s, source)
            e["warnings"].append("not analysed at rest (the notes say why): its ground and flight figures only")
            added = True
        if e is None:
            continue
        for c in CONDITIONS:
            e[c] = cond.get(s.key, {}).get(c) or {"axes": {}, "seconds": 0.0, "method": "none",
                                                  "notes": ["not one of the vehicle's redundant IMU streams"]}
    if added:  # in the streams' order, as the analysed ones are
        entries[:] = [by_key[s.key] for s in streams if by_key.get(s.key) is not None]


def _condition_only_entry(stream, source) -> dict:
    """The entry of a stream with ground or flight figures and no still analysis."""
    from companion.analysis.stream import analyze_stream

    e = analyze_stream(stream, [], "octave", ranges=[])
    e["warnings"] = []
    if source is not None:
        e["source"] = source
    return e


def entries_without_still(spec, streams, meta: dict, summary: dict, taus, reason: str) -> list:
    """The entries of a log without still data: one per stream with a condition figure (no still axes), or
    the CompanionError ``reason`` when neither the ground nor the flight condition gives one."""
    from companion.analysis.stream import analyze_stream

    cond, notes = condition_reports(streams, meta, _filters(meta))
    if not _has_figures(cond):
        why = sorted({f"{c}: {n}" for per in cond.values() for c in CONDITIONS
                      for n in (per.get(c) or {}).get("notes", [])[:1]})
        extra = "; ".join(notes + why)
        raise CompanionError(reason + (f"; {extra}" if extra else ""))
    summary["notes"] += notes
    summary["notes"].append("no still data: the ground and flight conditions only")
    entries = []
    for s in streams:
        if s.key not in cond:
            continue
        e = analyze_stream(s, [], taus, ranges=[])
        e["warnings"] = []
        e["source"] = str(spec)
        for c in CONDITIONS:
            e[c] = cond[s.key].get(c) or {"axes": {}, "seconds": 0.0, "method": "none", "notes": []}
        entries.append(e)
    return entries
