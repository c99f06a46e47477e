"""Fleet report: every IMU's coefficients across flights, its trend test, IMUs ranked by evidence of
degradation; as a list of dicts (``fleet report --json``) and as one self-contained HTML file.

An IMU is (vehicle, sysid, compid, message, imu instance). Its flights are the logs holding it, in
start-time order; the trend test is :func:`companion.fleet.trends.imu_trend`. Ranking: flagged IMUs
first, then by decreasing evidence.
"""

from __future__ import annotations

import base64
import html
import time
from collections import defaultdict
from itertools import groupby
from operator import itemgetter

import numpy as np

from companion.fleet.trends import EVIDENCE_THRESHOLD, MIN_RISE, TREND_PARAMS, imu_trend


def fleet_trends(store, threshold: float = EVIDENCE_THRESHOLD, min_rise: float = MIN_RISE) -> list[dict]:
    """Ranked IMU entries; each carries its ``_series`` and ``_tests`` (for plots; not JSON)."""
    entries = []
    shared = store.shared_folders()
    # an IMU's trend per condition (still, ground, flight: each condition's figures are their own series)
    key = itemgetter("vehicle", "sysid", "compid", "message", "imu", "condition")
    for (vehicle, sysid, compid, message, imu, condition), group in groupby(store.all_results(), key=key):
        rows = list(group)  # one IMU at a time: the rows arrive sorted by IMU, then flight time
        if all(r["status"] == "absent" for r in rows):
            continue  # a stream without these axes (an accelerometer batch in an older database): not an IMU here
        order: dict = {}
        for r in rows:  # rows are in flight-time order
            order.setdefault(r["hash"], len(order))
        flights = len(order)
        acc: dict = defaultdict(lambda: ([], [], [], []))
        for r in rows:
            if r["status"] != "ok":
                continue
            for p in TREND_PARAMS:
                if r[p] is not None:
                    a = acc[(r["axis"], p)]
                    a[0].append(order[r["hash"]])
                    a[1].append(r[p])
                    a[2].append(r[p + "_lo"] if r[p + "_lo"] is not None else np.nan)
                    a[3].append(r[p + "_hi"] if r[p + "_hi"] is not None else np.nan)
        series = {k: tuple(np.asarray(x, dtype=float) for x in v) for k, v in acc.items()}
        tr = imu_trend(series, flights, threshold, min_rise)
        w = tr.worst
        times = [r["start_time"] for r in rows if r["start_time"] is not None]
        logs = {r["hash"]: r for r in rows}.values()
        by_mtime = sum(r.get("start_source") == "mtime" for r in logs)
        identity_note = None
        if flights >= 2 and vehicle == f"sys{sysid}" and not any(r.get("board_id") for r in logs):
            # no board id in any of its logs: the logs are grouped by MAVLink system id alone (every
            # DataFlash log without a boot banner id is sys0), and may be different vehicles' IMUs
            identity_note = (f"{flights} logs with no board id, grouped by system id {sysid} alone: they may come "
                             "from different vehicles"
                             + (f"; {by_mtime} ordered by file time (no time of day in the log)" if by_mtime else "")
                             + "; where each vehicle's logs sit in their own folder, fleet analyze --vehicle dir")
        folder = rows[0]["folder"]
        if folder in shared:
            # one folder, several boards: its logs are not one vehicle's, so each board is ranked apart
            boards = shared[folder]
            if vehicle != folder:
                identity_note = (f"folder {folder} holds the logs of {len(boards)} boards ({', '.join(boards)}): "
                                 f"each board's IMUs ranked apart, as {folder}/<board id>")
            else:
                identity_note = (f"{flights} logs with no board id in folder {folder}, which holds the logs of "
                                 f"{len(boards)} boards: they may come from any of them")
        last_n = {}
        for (axis, p), (idx, v, lo, hi) in series.items():
            if p == "N" and len(v):
                last_n[axis] = float(v[-1])
        entries.append({
            "vehicle": vehicle, "sysid": int(sysid), "compid": int(compid), "message": message, "imu": int(imu),
            "condition": condition or "still", "flights": flights, "flagged": tr.flagged, "evidence": round(float(tr.evidence), 3),
            "axis": tr.axis, "param": tr.param, "trend": float(w.ratio) if w else None,
            "t": float(w.t) if w else None, "dispersion": float(w.phi) if w else None,
            "tests": len(tr.tests), "note": tr.note,
            "first_flight": min(times) if times else None, "last_flight": max(times) if times else None,
            "last_N": last_n, "identity_note": identity_note,
            "_series": series, "_tests": tr.tests, "_folder": folder})
    entries.sort(key=lambda e: (not e["flagged"], -e["evidence"], e["vehicle"], e["sysid"], e["message"], e["imu"],
                                e["condition"] != "still", e["condition"]))
    return entries


def public(entry: dict) -> dict:
    """The JSON fields of an entry (no arrays)."""
    return {k: v for k, v in entry.items() if not k.startswith("_")}


def report_json(store, entries: list[dict], threshold: float, min_rise: float) -> dict:
    return {"database": store.path, "generated": time.time(), "threshold": threshold, "min_rise": min_rise,
            "logs": store.counts(), "imus": [public(e) for e in entries]}


def ranking_lines(entries: list[dict], top: int) -> list[str]:
    """The printed ranking: a headline, a header, one line per IMU (the first ``top``; 0: all) and how many
    more there are."""
    flagged = sum(e["flagged"] for e in entries)
    lines = [f"{len(entries)} IMUs, {flagged} flagged (evidence >= {EVIDENCE_THRESHOLD:g}, rise >= {MIN_RISE:g}x)"]
    # board ids in full (a 96-bit MCU id is 24 hex digits, with its board name and a folder more)
    wv = max([18] + [len(e["vehicle"]) for e in entries])
    lines.append(f"{'#':>4} {'vehicle':<{wv}} {'sys':>3} {'IMU':<16} {'flights':>7} {'flag':>4} {'evidence':>8} "
                 f"{'worst':<6} {'trend':>6}")
    shown = entries if top == 0 else entries[:top]
    for i, e in enumerate(shown, 1):
        worst = f"{e['axis']} {e['param']}" if e["axis"] else "-"
        trend = f"{e['trend']:.2f}x" if e["trend"] is not None else "-"
        imu = str(e["imu"]) + " " + e["message"] + ("" if e.get("condition", "still") == "still" else f" {e['condition']}")
        lines.append(f"{i:>4} {e['vehicle']:<{wv}} {e['sysid']:>3} {imu:<16} "
                     f"{e['flights']:>7} {'YES' if e['flagged'] else 'no':>4} {e['evidence']:>8.1f} {worst:<6} {trend:>6}"
                     + (f"  ({e['note']})" if e["note"] and not e["axis"] else ""))
    if len(shown) < len(entries):
        lines.append(f"... {len(entries) - len(shown)} more (--top 0 for all)")
    return lines


def nothing_to_rank(counts: dict[str, int]) -> str:
    """Why no IMU could be ranked, from the database's log counts."""
    if counts["failed"] and not counts["ok"]:
        return f"all {counts['failed']} log(s) failed"
    return f"no analysed IMU data ({counts['ok']} logs ok, {counts['failed']} failed)"


def _fmt_time(t) -> str:
    return time.strftime("%Y-%m-%d", time.gmtime(t)) if t else "-"


CSS = """body{font-family:system-ui,sans-serif;margin:1.5em;color:#222}table{border-collapse:collapse;font-size:13px}
td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}th{background:#eee}td.l,th.l{text-align:left}
tr.flag td{background:#fde2e2}.flag{color:#b00;font-weight:bold}section{margin:1em 0;border-top:1px solid #ddd}
img{max-width:100%}small{color:#666}"""


def identity_notes(entries: list[dict]) -> list[tuple[str, str, bool]]:
    """Each identity note once: (``"vehicle V: "`` or ``""`` when the note names its folder, the note, whether
    a flagged IMU is among the logs it doubts)."""
    seen: dict = {}
    for e in entries:
        note = e.get("identity_note")
        if not note:
            continue
        split = e.get("_folder") not in (None, e["vehicle"])  # ranked per board: no doubt left to flag
        # once per folder of several boards, once per vehicle otherwise (its best-ranked IMU's words)
        k = e["_folder"] if split else ("vehicle", e["vehicle"], e["sysid"])
        who = "" if split else f"vehicle {e['vehicle']}: "
        if k not in seen:
            seen[k] = [who, note, False]
        seen[k][2] = seen[k][2] or (bool(e["flagged"]) and not split)
    return [tuple(v) for v in seen.values()]


def _nothing_ranked(fails, entries, counts) -> str:
    """The page's headline when no IMU could be ranked: why (every log failed, or none was analysed)."""
    if entries:
        return ""
    esc = html.escape
    if not counts["ok"] and counts["failed"]:
        why = "".join(f"<li>{n} log(s): {esc(r)}</li>" for n, r in failure_reasons(fails))
        return (f"<p id='nothing' class='flag'>No IMU could be ranked: all {counts['failed']} log(s) failed. "
                f"Commonest reasons:</p><ul>{why}</ul>")
    return ("<p id='nothing' class='flag'>No IMU could be ranked: no log in the database has analysed IMU "
            "data.</p>")


def _notes_html(entries: list[dict]) -> str:
    notes = identity_notes(entries)
    if not notes:
        return ""
    esc = html.escape
    return ("<ul id='notes'>" + "".join(f"<li>note: {esc(who)}{esc(note)}"
                                        + (" (a flagged IMU among them)" if flagged else "") + "</li>"
                                        for who, note, flagged in notes) + "</ul>")


def failure_reasons(fails, top: int = 5) -> list[tuple[int, str]]:
    """The commonest reasons of failed logs, ``[(count, reason)]``: the reason up to its details (" (...)"),
    numbers as N, so "no still data (0 still segments ...)" of 93 logs is one line."""
    import re

    counts: dict = defaultdict(int)
    for _, reason in fails:
        text = (reason or "failed").split(" (")[0]
        counts[re.sub(r"\d+(\.\d+)?", "N", text)] += 1
    return sorted(((n, r) for r, n in counts.items()), key=lambda x: (-x[0], x[1]))[:top]


def report_html(store, entries: list[dict], threshold: float, min_rise: float, max_plots: int = 100) -> str:
    """One self-contained HTML page (inline CSS, PNG plots as data: URIs; no script, no external file)."""
    from companion.plots.fleet_plot import imu_trend_png

    counts = store.counts()
    fails = store.failures()
    flagged = [e for e in entries if e["flagged"]]
    esc = html.escape
    out = ["<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
           "<title>companion fleet report</title>", f"<style>{CSS}</style></head><body>",
           "<h1>Gyro trends across flights</h1>",
           f"<p id='summary'>{len(entries)} IMUs, {counts['ok']} logs analysed, {counts['failed']} failed; "
           f"<span class='flag'>{len(flagged)} flagged</span> (evidence &ge; {threshold:g} and a fitted rise "
           f"&ge; {min_rise:g}x). Database <code>{esc(store.path)}</code>, generated "
           f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.</p>",
           _nothing_ranked(fails, entries, counts),
           _notes_html(entries),
           "<p><small>Evidence = -log10 of the Bonferroni-corrected one-sided p-value of the steepest rise of "
           "ln N, ln B or ln K across the IMU's flights (weighted regression on the per-flight 95 % intervals, "
           "dispersion-corrected); trend = fitted last/first ratio. Method: docs/fleet.md.</small></p>",
           "<table id='ranking'><tr><th>#</th><th class='l'>vehicle</th><th>sysid</th><th class='l'>IMU</th>"
           "<th>flights</th><th class='l'>first - last</th><th>flagged</th><th>evidence</th><th class='l'>worst</th>"
           "<th>trend</th><th>dispersion</th></tr>"]
    for i, e in enumerate(entries, 1):
        worst = f"{e['axis']} {e['param']}" if e["axis"] else esc(e["note"] or "-")
        trend = f"{e['trend']:.2f}x" if e["trend"] is not None else "-"
        disp = f"{e['dispersion']:.2f}" if e["dispersion"] is not None else "-"
        out.append(f"<tr class='{'flag' if e['flagged'] else ''}'><td>{i}</td><td class='l'>"
                   f"<a href='#imu{i}'>{esc(e['vehicle'])}</a></td><td>{e['sysid']}</td>"
                   f"<td class='l'>{e['imu']} ({esc(e['message'])})</td><td>{e['flights']}</td>"
                   f"<td class='l'>{_fmt_time(e['first_flight'])} - {_fmt_time(e['last_flight'])}</td>"
                   f"<td>{'YES' if e['flagged'] else 'no'}</td><td>{e['evidence']:.1f}</td>"
                   f"<td class='l'>{worst}</td><td>{trend}</td><td>{disp}</td></tr>")
    out.append("</table>")
    if fails:
        out.append(f"<details{' open' if not entries else ''}><summary>{len(fails)} failed log(s)</summary>"
                   "<table id='failed'><tr><th class='l'>path</th>"
                   "<th class='l'>reason</th></tr>")
        out += [f"<tr><td class='l'>{esc(p)}</td><td class='l'>{esc(r or '')}</td></tr>" for p, r in fails]
        out.append("</table></details>")
    plotted = 0
    for i, e in enumerate(entries, 1):
        if not e["flagged"] and plotted >= max_plots:
            continue
        png = imu_trend_png(e, e["_series"], e["_tests"])
        plotted += 1
        b64 = base64.b64encode(png).decode("ascii")
        head = (f"{'<span class=flag>FLAGGED</span> ' if e['flagged'] else ''}{esc(e['vehicle'])} IMU{e['imu']} "
                f"({esc(e['message'])}, sysid {e['sysid']})")
        detail = (f"evidence {e['evidence']:.1f}, worst {e['axis']} {e['param']}, trend {e['trend']:.2f}x over "
                  f"{e['flights']} flights" if e["axis"] else esc(e["note"]))
        note = f"<p class='note'>note: {esc(e['identity_note'])}</p>" if e.get("identity_note") else ""
        out.append(f"<section id='imu{i}'><h3>{i}. {head}</h3><p>{detail}</p>{note}"
                   f"<img alt='N per flight of {esc(e['vehicle'])} IMU{e['imu']}' src='data:image/png;base64,{b64}'>"
                   "</section>")
    if plotted < len(entries):
        out.append(f"<p><small>{len(entries) - plotted} unflagged IMUs not plotted (--max-plots).</small></p>")
    out.append("</body></html>")
    return "\n".join(out)


__all__ = ["fleet_trends", "report_json", "report_html", "public", "identity_notes", "failure_reasons"]
