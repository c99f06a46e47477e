"""The final report of ``companion run`` per IMU: the figure ``companion analyze`` computes, on the still samples
the run fed its estimators (:mod:`companion.service.still_record`), beside the online estimates it sent live.

One function for one figure: :func:`companion.analysis.stream.pieces_entry`, the function behind ``analyze``,
``gap`` and the Kalibr file, over the kept still pieces with the channel's low-pass filter, sampling and LSB.
Where it cannot give that figure the summary says why (:func:`final_analysis`'s ``note``).
"""

from __future__ import annotations

from companion.samples import GYRO_AXES

#: the fewest still seconds the final analysis is run on (``analyze`` refuses still stretches under 10 s)
MIN_FINAL_S = 10.0


def final_analysis(ch) -> dict:
    """``{"axes": {axis: analysis entry}, "kept_s", "dropped_s", "missing_s", "ranges_s", "note"}`` of one
    :class:`companion.service.channel.Channel` at its current rate: computed once per state of its still record
    (the summary is asked for more than once at the end of a run)."""
    bank = ch.bank
    rec = bank.record
    cached = bank.final_cache
    if cached is not None and cached[0] == rec.version:
        return cached[1]
    out = {"axes": {}, "kept_s": rec.kept_s, "dropped_s": rec.dropped_s,
           # still data the estimators hold but the record does not: fed before a restart from the state file
           "missing_s": max(0.0, ch.fed_s - rec.kept_s - rec.dropped_s),
           "ranges_s": [list(r) for r in rec.ranges_s()], "note": None}
    if not ch.rate_hz or not rec.pieces:
        out["note"] = "no still samples kept at this rate" + (" since the restart" if out["missing_s"] >= 1.0 else "")
    elif rec.kept_s < MIN_FINAL_S:
        out["note"] = f"only {rec.kept_s:.0f} s of still samples kept (< {MIN_FINAL_S:g} s): too few for the analysis"
    else:
        ts = rec.axis_pieces("t")  # read once: the rate and the splits both need it
        rate = kept_rate(ch, ts)
        out["rate_hz"] = rate
        cuts = split_points(ts, rate, ch.time_res)
        for ax in rec.axes:
            pieces = [p[a:b] for p, edges in zip(rec.axis_pieces(ax), cuts) for a, b in zip(edges[:-1], edges[1:])]
            out["axes"][ax] = axis_analysis(ch, ax, pieces, rate)
    bank.final_cache = (rec.version, out)
    return out


def kept_rate(ch, ts) -> float:
    """The sample rate of the kept still samples (``ts``: their pieces' times) by the rule ``analyze`` applies to a stream's intervals
    (:func:`companion.timebase.period_of`): the channel's rate was taken from its first blocks, and a rate
    0.2 % off moves N by 0.1 %."""
    import numpy as np

    from companion.timebase import period_of

    d = [np.diff(t) for t in ts if t.shape[0] > 1]
    period = period_of(np.concatenate(d), ch.time_res) if d else float("nan")
    return 1.0 / period if np.isfinite(period) and period > 0 else float(ch.rate_hz)


def split_points(ts, rate_hz: float, resolution: float) -> list[list[int]]:
    """Per kept piece (``ts``: the pieces' times) the edges of its parts: a step over ``analyze``'s split threshold (10 periods,
    :func:`companion.sources.timestamps.step_rules`) splits it as ``analyze`` splits a stream's segments, where
    the run's blocks go on over a shorter gap than its ``gap_s`` (0.5 s)."""
    import numpy as np

    from companion.sources.timestamps import step_rules

    split_s = step_rules(1.0 / rate_hz, resolution).split_s
    out = []
    for t in ts:
        cuts = (np.flatnonzero(np.diff(t) > split_s) + 1).tolist()
        out.append([0, *cuts, int(t.shape[0])])
    return out


def axis_analysis(ch, ax: str, pieces, rate_hz: float) -> dict:
    """The analysis of one axis' kept still pieces (the entry ``companion analyze`` gives for the same samples)."""
    from companion.analysis.stream import pieces_entry
    from companion.service.channel import INT16_MESSAGES
    from companion.sources.decode import DEFAULT_SCALES

    kind = "gyro" if ax in GYRO_AXES else "accel"
    fc = ch.cfg.estimator.get("filter_hz") or ch.filters.get(kind)
    if kind == "gyro":
        lsb = ch.gyro_lsb
    else:
        lsb = DEFAULT_SCALES["accel_scale"] if ch.message in INT16_MESSAGES else None
    return pieces_entry(pieces, rate_hz, ax, ch.message, {kind: fc} if fc else {}, "octave", lsb)


def analysis_text(entry: dict, axis: str) -> str:
    """'N 0.686 [0.68, 0.691] deg/sqrt(h); B < 11 deg/h; K < 210 deg/h^1.5; ...' of one analysis entry: the
    cells of ``companion analyze``'s table (values with 95 % intervals, 95 % upper bounds as '< x'); an
    entry without figures gives its status and note."""
    from companion import units
    from companion.analysis.report_table import format_term
    from companion.units import fmt_interval, fmt_value

    if entry.get("status") != "ok":
        return f"{entry.get('status')}: {entry.get('note', '')}".rstrip(": ")
    linear = {"white_noise": "N", "bias_instability": "B", "random_walk": "K"}
    cells, other = {}, []
    for t in entry.get("terms", []):
        p = linear.get(t["effect"])
        if p is None:
            other.append(format_term(t, axis))
            continue
        lo, hi = t["ci95"][p]
        cells[p] = fmt_interval(*(units.to_datasheet(p, x, axis) for x in (t[p], lo, hi)))
    for t in entry.get("bounds") or ():
        p = linear.get(t["effect"])
        if p and p not in cells:
            cells[p] = f"< {fmt_value(units.to_datasheet(p, t[p], axis))}"
    parts = [f"{p} {cells[p]} {units.datasheet_unit(p, axis)}" for p in ("N", "B", "K") if p in cells]
    return "; ".join(parts + other)


def summary_lines(row: dict) -> list[str]:
    """The summary's lines of one IMU row (:func:`companion.service.imu_summary.summary_rows`): per axis the
    final analysis, then the online estimate labelled as such, and why a final analysis is missing."""
    from companion.estimators.online_report import summary_line

    fin = row.get("final") or {}
    out = []
    head = final_head(fin)
    if head:
        out.append(f"  {head}")
    for ax, d in row["axes"].items():
        entry = (fin.get("axes") or {}).get(ax)
        if entry is not None:
            out.append(f"  {ax}: {analysis_text(entry, ax)}")
        text = summary_line(d["terms"], ax, d["baseline"])
        out.append(f"  {ax} online: " + (text or f"no estimate yet ({row['still_s']:.0f} s of still data at this "
                                                  "rate)"))
    return out


def final_head(fin: dict) -> str | None:
    """The line above the axes: what the final figures are (analyze's analysis of which still data), or why
    there are none; None without a final analysis."""
    if not fin:
        return None
    left = []
    if fin.get("dropped_s", 0.0) >= 1.0:
        left.append(f"the oldest {fin['dropped_s']:.0f} s left out (memory budget of the kept samples)")
    if fin.get("missing_s", 0.0) >= 1.0:
        left.append(f"{fin['missing_s']:.0f} s fed before the restart from the state file are in the online "
                    "estimates only")
    more = f" ({'; '.join(left)})" if left else ""
    if fin.get("note"):
        return f"final analysis: none, {fin['note']}{more}; the online estimates below are what was sent live"
    ranges = fin.get("ranges_s") or ()
    where = (f"at {', '.join(f'{a:.3f}-{b:.3f} s' for a, b in ranges)}" if len(ranges) <= 3
             else f"in {len(ranges)} pieces from {ranges[0][0]:.3f} to {ranges[-1][1]:.3f} s")
    return (f"final analysis (companion analyze's) of {fin['kept_s']:.0f} s of still data {where}{more}; "
            "'online': the estimates sent live (NAMED_VALUE_FLOAT)")
