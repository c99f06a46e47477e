"""The white-noise level N that ``companion analyze`` reports against the level the data show where they are flat.

Every log found in the shared data (../shared/data) and in a directory of fetched public logs (default
/work/reallogs, searched recursively; DataFlash .bin, PX4 .ulg, tlogs) is analysed as a user would:

    companion analyze LOG --json OUT --quiet [--start S --end E --all]

(a log refused for want of a still stretch is analysed whole, with --all, as the refusal suggests)

and, per axis of every IMU stream, this script finds the flat white regions on its own, from the printed
curve only (tau, adev, adev_lo, adev_hi, edf), by a rule of its own: a maximal run of consecutive cluster
times, each with EDF >= 100, whose ADEV*sqrt(tau) intervals (the 95 % ones the report prints) share a common
value, spanning at least 2x in tau. For white noise AVAR = N^2/tau, so ADEV*sqrt(tau) there is N itself; the
region's level is the EDF-weighted mean of AVAR*tau, square-rooted.

Target (issue 49): on every such region, the report's N within 3 % of the level and its 95 % interval
covering it. A filtered white curve approaches its level as 1 - c/tau, so a run an octave or two above the
filter's corner passes the flatness rule while it reads a few per cent low: each region is also judged against
its level with the reported filter's roll-off divided out. Prints one row per region (log, stream, axis, tau span, level, N and interval, pass/fail) and
per log the fraction of regions meeting the target.

    python -m benchmarks.bench_white_level [DIR or LOG ...] [--window LOG:START:END ...] [--quick]

``--quick`` reads only the shared data (the run recorded in RESULTS.md adds /work/reallogs).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks import results
from benchmarks.results import SHARED_DATA

EXTS = (".bin", ".ulg", ".tlog")
#: a flat region's least EDF per point and least span in tau
MIN_EDF = 100.0
MIN_SPAN = 2.0
#: the target: N within this fraction of the level, its interval covering the level
TOL = 0.03
#: windows analysed besides each log's own still selection (name substring, start s, end s): still stretches
#: the default selection leaves out or cuts short
WINDOWS = ()


def flat_regions(tau, adev, lo, hi, edf) -> list[tuple[int, int, float]]:
    """Runs [i, j] (inclusive) of consecutive points with EDF >= MIN_EDF whose ADEV*sqrt(tau) intervals
    intersect, spanning >= MIN_SPAN in tau, as (i, j, level): from every start the longest such run, those
    inside another left out."""
    runs = []
    n = len(tau)
    for i in range(n):
        if not (edf[i] >= MIN_EDF and math.isfinite(lo[i]) and math.isfinite(hi[i])):
            continue
        top, bot = hi[i] * math.sqrt(tau[i]), lo[i] * math.sqrt(tau[i])
        j = i
        while j + 1 < n and edf[j + 1] >= MIN_EDF:
            b2, t2 = max(bot, lo[j + 1] * math.sqrt(tau[j + 1])), min(top, hi[j + 1] * math.sqrt(tau[j + 1]))
            if b2 > t2:
                break
            bot, top, j = b2, t2, j + 1
        if tau[j] >= MIN_SPAN * tau[i] * (1 - 1e-9) and not any(a <= i and j <= b for a, b in runs):
            runs.append((i, j))
    out = []
    for i, j in runs:
        w = edf[i:j + 1]
        level = math.sqrt(sum(wk * adev[k] ** 2 * tau[k] for k, wk in zip(range(i, j + 1), w)) / sum(w))
        out.append((i, j, level))
    return out


def judged(regions, tau) -> list:
    """The region the target judges on an axis: where several overlap or disagree (a slow roll-off holds
    short flat runs), the widest in octaves, of equals the one at longer cluster times; the rest are listed."""
    if not regions:
        return []
    return [max(regions, key=lambda r: (round(math.log2(tau[r[1]] / tau[r[0]]), 6), tau[r[1]]))]


def white_n(entry) -> tuple[float | None, list | None]:
    """The report's N (SI) and its 95 % interval; (None, None) where N is a bound or absent."""
    for t in entry.get("terms", []):
        if t.get("effect") == "white_noise":
            return float(t["N"]), list(t.get("ci95", {}).get("N", [math.nan, math.nan]))
    return None, None


def analyze(log: Path, window=None, timeout: float = 600.0) -> tuple[dict | None, str]:
    """``companion analyze`` on ``log`` (a window: --start/--end --all); (the JSON document, error line)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "a.json"
        cmd = [sys.executable, "-m", "companion", "analyze", str(log), "--json", str(out), "--quiet"]
        if window == "all":
            cmd += ["--all"]
        elif window:
            cmd += ["--start", str(window[0]), "--end", str(window[1]), "--all"]
        try:
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return None, "timeout"
        if p.returncode != 0 or not out.exists():
            err = (p.stderr.strip().splitlines() or ["exit %d" % p.returncode])[-1]
            return None, err[:100]
        return json.loads(out.read_text()), ""


def rolloff(e: dict, i: int, j: int) -> float:
    """The reported filter's share of ADEV*sqrt(tau) over points i..j, EDF-weighted (1 without a filter): a
    filtered white curve approaches its level as 1 - c/tau, so a run an octave or two above the corner reads a
    few per cent low while it passes the flatness rule."""
    from companion.allan.terms import avar_term

    wn = next((t for t in e.get("terms", []) if t.get("effect") == "white_noise"), None)
    if wn is None or not wn.get("filter_hz"):
        return 1.0
    plain = {k: v for k, v in wn.items() if k not in ("ci95", "std")}
    bare = {k: v for k, v in plain.items() if k not in ("filter_hz", "sample_hz", "filter_order")}
    num = den = 0.0
    for k in range(i, j + 1):
        num += e["edf"][k] * avar_term(plain, e["tau"][k])
        den += e["edf"][k] * avar_term(bare, e["tau"][k])
    return math.sqrt(num / den)


def check_doc(doc: dict) -> list[dict]:
    """Every flat region of every axis of ``doc`` with the report's N against its level, as read and with the
    reported filter's roll-off divided out."""
    rows = []
    for s in doc.get("streams", []):
        label = f"{s.get('message')}[{s.get('instance')}]"
        for axis, e in s.get("axes", {}).items():
            if e.get("status") != "ok" or not e.get("edf"):
                continue
            N, ci = white_n(e)
            regions = flat_regions(e["tau"], e["adev"], e["adev_lo"], e["adev_hi"], e["edf"])
            main = judged(regions, e["tau"])
            for r in regions:
                i, j, level = r
                corr = level / rolloff(e, i, j)
                ok = N is not None and abs(N / level - 1) <= TOL and ci[0] <= level <= ci[1]
                ok_corr = N is not None and abs(N / corr - 1) <= TOL and ci[0] <= corr <= ci[1]
                rows.append({"stream": label, "axis": axis, "tau": (e["tau"][i], e["tau"][j]), "level": level,
                             "corr": corr, "edf": min(e["edf"][i:j + 1]), "N": N, "ci": ci, "ok": ok,
                             "ok_corr": ok_corr, "judged": r in main})
    return rows


def logs_in(dirs) -> list[Path]:
    from benchmarks.bench_reallogs import find_logs

    return find_logs(dirs, EXTS)


def _fmt(v):
    return "-" if v is None else f"{v:.4g}"


def _report(name: str, rows: list[dict]) -> tuple[int, int, int]:
    for r in rows:
        ci = "-" if r["N"] is None else f"[{r['ci'][0]:.4g}, {r['ci'][1]:.4g}]"
        dev = "-" if r["N"] is None else f"{100 * (r['N'] / r['level'] - 1):+.1f} %"
        verdict = "not judged (a wider region on the axis)"
        if r["judged"]:
            verdict = ("ok" if r["ok"] else "FAIL") + ("" if r["corr"] == r["level"] else
                                                        f"; filter-corrected {r['corr']:.4g}: "
                                                        f"{'ok' if r['ok_corr'] else 'FAIL'}")
        print(f"  {r['stream']:<22} {r['axis']}  tau {r['tau'][0]:.3g}-{r['tau'][1]:.3g} s  EDF>={r['edf']:.0f}  "
              f"level {r['level']:.4g}  N {_fmt(r['N'])} {ci} ({dev})  {verdict}")
    rows = [r for r in rows if r["judged"]]
    good = sum(r["ok"] for r in rows)
    good_corr = sum(r["ok_corr"] for r in rows)
    if rows:
        print(f"  {name}: {good}/{len(rows)} flat regions meet the target ({good_corr} against the "
              "filter-corrected level)")
    return good, good_corr, len(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dirs", nargs="*", default=[str(SHARED_DATA), "/work/reallogs"])
    ap.add_argument("--window", action="append", default=[], metavar="LOG:START:END",
                    help="also analyse LOG's window START-END s with --all (repeatable)")
    ap.add_argument("--timeout", type=float, default=600.0)
    ap.add_argument("--still-only", action="store_true", help="no whole-record (--all) analysis of a log refused "
                    "for want of a still stretch")
    args = results.parse_args(ap, {"dirs": [str(SHARED_DATA)]}, argv)
    logs = logs_in(args.dirs)
    jobs = [(p, None) for p in logs]
    for w in list(WINDOWS) + [tuple(x.rsplit(":", 2)) for x in args.window]:
        jobs += [(p, (float(w[1]), float(w[2]))) for p in logs if w[0] in str(p)]
    if not jobs:
        print("no logs found (the shared data and /work/reallogs are not on this machine)")
        return 0
    # per kind of analysis: the log's still selection (or a still window given), and a whole record with its
    # flight (a log refused for want of a still stretch): white noise sets few curves in flight
    tally = {k: {"good": 0, "corr": 0, "total": 0, "with": 0, "all": 0, "runs": 0} for k in ("still", "whole")}
    refused = 0
    for log, win in jobs:
        doc, err = analyze(log, win, args.timeout)
        if doc is None and win is None and "no still stretch" in err and not args.still_only:
            win = "all"  # the whole record, as the refusal suggests
            doc, err = analyze(log, win, args.timeout)
        name = log.name + (" [--all]" if win == "all" else f" [{win[0]:g}-{win[1]:g} s, --all]" if win else "")
        if doc is None:
            refused += 1
            print(f"{name}: no report ({err})")
            continue
        rows = check_doc(doc)
        print(f"{name}: {len(rows)} flat white region(s)")
        g, gc, n = _report(name, rows)
        t = tally["whole" if win == "all" else "still"]
        t["runs"] += 1
        t["good"], t["corr"], t["total"] = t["good"] + g, t["corr"] + gc, t["total"] + n
        if n:
            t["with"] += 1
            t["all"] += g == n
    print(f"\nsummary: {len(jobs)} logs and windows, {refused} without a report")
    for k, what in (("still", "still selection or window"), ("whole", "whole record with --all (flight included)")):
        t = tally[k]
        print(f"  {what}: {t['runs']} analyses, {t['with']} with a flat white region; {t['good']}/{t['total']} "
              f"regions ({100 * t['good'] / max(t['total'], 1):.0f} %) with N within {100 * TOL:.0f} % of the level "
              f"and its 95 % interval covering it, {t['all']}/{t['with']} analyses on every region; against the "
              f"level with the reported filter's roll-off divided out {t['corr']}/{t['total']} "
              f"({100 * t['corr'] / max(t['total'], 1):.0f} %)")
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
