"""The analysis report as a text table in datasheet units."""

from __future__ import annotations

from companion import units
from companion.allan.terms import PARAMS
from companion.analysis.condition_table import condition_lines
from companion.samples import ACCEL_AXES, GYRO_AXES
from companion.units import fmt_interval
from companion.units import fmt_value as _fmt



def term_parts(t: dict, axis: str, sep: str = " ") -> list[str]:
    """Each parameter of a fitted term in datasheet units with its interval, ``'B 28.4 [26.1, 31.0] deg/h'``
    (``sep`` between name and value: the plot's legend writes ``B=...``); one rule for table and figure."""
    parts = []
    for p in PARAMS[t["effect"]]:
        v = units.to_datasheet(p, t[p], axis)
        ci = t.get("ci95", {}).get(p)
        s = (f"{p}{sep}{fmt_interval(v, units.to_datasheet(p, ci[0], axis), units.to_datasheet(p, ci[1], axis))}"
             if ci else f"{p}{sep}{_fmt(v)}")
        parts.append(s + " " + units.datasheet_unit(p, axis))
    return parts


def format_term(t: dict, axis: str) -> str:
    """'B 28.4 [26.1, 31.0] deg/h' style text of a fitted term in datasheet units."""
    return ", ".join(term_parts(t, axis))


def format_table(report: dict) -> str:
    lines = []
    for st in report["streams"]:
        src = f"{st['source']}: " if len(report.get("sources", [])) > 1 and st.get("source") else ""
        tm = st.get("timing") or {}
        extra = ", ".join(f"{tm[k]} {k}" for k in ("gaps", "duplicates", "backwards", "resets") if tm.get(k))
        # a stream with ground/flight figures only: "0 samples, 0.0 s" would read as an empty stream
        used = (f"{st['samples']} samples at {st['rate_hz']:.4g} Hz, {st['duration_s']:.1f} s" if st["samples"]
                else f"{st['rate_hz']:.4g} Hz, no still samples")
        lines.append(f"{src}{st['message']}[{st['instance']}] sys{st['sysid']}/comp{st['compid']}: {used}"
                     + (f" in {st['still_segments']} still segments" if st.get("still_segments", 1) > 1 else "")
                     + (f" ({extra} in the stream)" if extra else "")
                     + (f"; filter {', '.join(f'{k} {v:g} Hz' for k, v in st['filters_hz'].items())}"
                        if st.get("filters_hz") else ""))
        for w in st.get("warnings", []):
            lines.append(f"  WARNING: {w}")
        for group, names in (("gyro", GYRO_AXES), ("accel", ACCEL_AXES)):
            axes = [a for a in names if a in st["axes"]]
            if not axes or all(st["axes"][a]["status"] == "absent" for a in axes):
                continue  # no header for a sensor the stream does not carry (a batch of accelerometer data)
            ref = axes[0]
            u = {p: units.datasheet_unit(p, ref) for p in ("N", "B", "K")}
            lines.append(f"  {group:<5} {'N [' + u['N'] + ']':<28}{'B [' + u['B'] + ']':<26}"
                         f"{'K [' + u['K'] + ']':<26}other terms / notes")
            for a in axes:
                r = st["axes"][a]
                if r["status"] == "absent":
                    continue
                if r["status"] != "ok":
                    lines.append(f"  {a:<5} {r['status']}: {r.get('note', '')}")
                    continue
                cells, other = {}, []
                for t in r["terms"]:
                    p = {"white_noise": "N", "bias_instability": "B", "random_walk": "K"}.get(t["effect"])
                    if p:
                        lo, hi = t["ci95"][p]
                        cells[p] = fmt_interval(units.to_datasheet(p, t[p], a), units.to_datasheet(p, lo, a),
                                                units.to_datasheet(p, hi, a))
                    else:
                        other.append(format_term(t, a))
                for t in r.get("bounds") or ():
                    p = {"white_noise": "N", "bias_instability": "B", "random_walk": "K"}.get(t["effect"])
                    if p and p not in cells:
                        cells[p] = f"< {_fmt(units.to_datasheet(p, t[p], a))}"
                if r.get("fit") and r["fit"].get("model_error"):
                    other.append(f"misfit: +{100 * r['fit']['model_error']:.0f} % model error")
                for n_ in (r.get("fit") or {}).get("notes", []):
                    if n_.startswith(("N from a local", "cluster times below", "the record is too short", "low-pass",
                                      "N not resolved", "N's interval spans")):
                        other.append(n_)
                q = r.get("quantization")
                if q and q.get("note"):
                    other.append(q["note"])
                lines.append(f"  {a:<5} {cells.get('N', '-'):<28}{cells.get('B', '-'):<26}{cells.get('K', '-'):<26} "
                             + "; ".join(other))
                if r.get("online") is not None:
                    lines.append("  " + _online_row(r, a))
        lines += condition_lines(st)  # the ground and flight figures (companion.analysis.inflight)
    return "\n".join(lines)


def _online_row(r: dict, a: str) -> str:
    """'online N 1.05 [1.04, 1.06] ... B < 31 ...': the online report (companion.estimators.online_report, the same
    text as `companion run`'s summary): resolved values with 95 % intervals, 95 % upper bounds as '< x'."""
    from companion.estimators.online_report import cell, extra_text

    cells = {p: cell(r["online"], p, a) for p in ("N", "B", "K")}
    return (f"{'online':<5} {cells['N']:<28}{cells['B']:<26}{cells['K']:<26} "
            + "; ".join(extra_text(r["online"], a)))
