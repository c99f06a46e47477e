"""``companion fleet report``: the trend test per IMU, the ranking, HTML and JSON (:mod:`companion.fleet.fleet_ranking`)."""

from __future__ import annotations

import argparse
import sys

from companion.errors import EXIT_FAULTS, CompanionError, NoUsableData

REPORT_DESCRIPTION = """\
Per IMU (vehicle, MAVLink system, message, instance) its coefficients across flights (oldest first) and a
trend test: a weighted regression of ln N, ln B and ln K on the flight index with the per-flight 95 %
intervals, widened when the flights scatter more than the intervals explain. Evidence is -log10 of the
Bonferroni-corrected one-sided p-value of the steepest rise; an IMU is flagged at evidence >= 4 (about
one false alarm in 10,000 healthy IMUs, chosen from simulations) with a fitted rise >= 1.2x. IMUs are
printed most evidence first.
"""

REPORT_EPILOG = """\
examples:
  companion fleet report --db fleet.sqlite
  companion fleet report --db fleet.sqlite --html report.html --json report.json

--json OUT writes {"imus": [...]}, one entry per IMU, most evidence first, with vehicle, sysid, imu,
message, flights, flagged, evidence, axis and param (the worst test), trend (its fitted last/first
ratio), t, dispersion, first_flight/last_flight (unix s).
"""


def register(sub) -> None:
    r = sub.add_parser("report", help="trend test per IMU, ranking, HTML and JSON",
                       description=REPORT_DESCRIPTION, epilog=REPORT_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("--db", required=True, metavar="FILE", help="SQLite database written by fleet analyze")
    r.add_argument("--html", metavar="OUT", help="write the self-contained HTML report")
    r.add_argument("--json", metavar="OUT", help="write the ranking as JSON ({\"imus\": [...]})")
    r.add_argument("--top", type=int, default=20, metavar="K", help="IMUs printed (default 20; 0: all)")
    r.add_argument("--max-plots", type=int, default=100, metavar="K",
                   help="plots of unflagged IMUs in the HTML (flagged ones always; default 100)")
    r.set_defaults(func=run_report)


def run_report(args) -> int:
    from companion.cli.output import check_output_path
    from companion.fleet.fleet_ranking import fleet_trends, identity_notes, ranking_lines
    from companion.fleet.store import FleetStore

    if args.top < 0 or args.max_plots < 0:
        raise CompanionError(f"--{'top' if args.top < 0 else 'max-plots'} must be >= 0")
    # checked before the trend tests over a large database, not after
    for path, opt in ((args.html, "--html"), (args.json, "--json")):
        if path:
            check_output_path(path, opt)
    with FleetStore(args.db, create=False) as store:
        entries = fleet_trends(store)
        if not entries:
            return _report_nothing(args, store)
        for line in ranking_lines(entries, args.top):
            print(line)
        for who, note, flagged in identity_notes(entries):  # trends over logs that may not be one vehicle's
            print(f"note: {who}{note}" + (" (a flagged IMU among them)" if flagged else ""))
        _write_reports(args, store, entries)
    flagged = sum(e["flagged"] for e in entries)
    if flagged:  # a script or CI job gates on it (README "Exit status")
        print(f"companion fleet report: {flagged} flagged IMU(s) (exit status {EXIT_FAULTS})", file=sys.stderr)
        return EXIT_FAULTS
    return 0


def _write_reports(args, store, entries) -> None:
    from companion.cli.output import to_json, write_text
    from companion.fleet.fleet_ranking import report_html, report_json
    from companion.fleet.trends import EVIDENCE_THRESHOLD, MIN_RISE

    from companion.fleet.fleet_evidence import fleet_evidence, fleet_view
    from companion.webview.pages import fleet_section

    if args.json:
        data = dict(report_json(store, entries, EVIDENCE_THRESHOLD, MIN_RISE), evidence=fleet_evidence(entries))
        write_text(args.json, to_json(data) + "\n", "JSON")
        print(f"wrote {args.json}")
    if args.html:  # the fixed page, then its interactive part (collapsed) before the end
        page = report_html(store, entries, EVIDENCE_THRESHOLD, MIN_RISE, args.max_plots)
        page = page.replace("</body></html>", fleet_section(fleet_view(entries, args.max_plots)) + "</body></html>")
        write_text(args.html, page, "HTML")
        print(f"wrote {args.html}")


def _report_nothing(args, store) -> int:
    """No IMU to rank (every log failed, or none analysed): the files are still written, saying why (a
    nightly job's report page must not silently keep yesterday's), then one error line."""
    from companion.fleet.fleet_ranking import failure_reasons, nothing_to_rank

    for n, reason in failure_reasons(store.failures()):
        print(f"{n} log(s) failed: {reason}")
    _write_reports(args, store, [])
    raise NoUsableData(f"{args.db}: no IMU to rank: {nothing_to_rank(store.counts())}")
