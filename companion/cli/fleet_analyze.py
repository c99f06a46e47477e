"""``companion fleet analyze``: every log into the SQLite database (:mod:`companion.fleet.orchestrate`)."""

from __future__ import annotations

import argparse
import sys

from companion.errors import EXIT_FAULTS, EXIT_INTERRUPTED, EXIT_NO_DATA, EXIT_TERMINATED, EXIT_TIME_LIMIT

ANALYZE_DESCRIPTION = """\
Analyse every log named by LOGS (files, folders searched recursively, glob patterns) with the code of
`companion analyze` (the same segment choice, fit and 95 % intervals; gyro axes by default) in parallel
on Dask: a local cluster of --workers processes on this machine (default: one per CPU core), or the
workers of an existing scheduler (--scheduler tcp://HOST:8786; they need companion installed and the
log paths readable). Results go to the SQLite database --db, one transaction per log, written by this
process only. A log whose content (BLAKE2b hash) is already in the database is skipped, so an
interrupted run resumes where it stopped; a log that fails is recorded with a one-line reason
(--retry-failed analyses those again). Progress on stderr: logs done, failed, rate, ETA.
"""

ANALYZE_EPILOG = """\
examples:
  companion fleet analyze logs/ --db fleet.sqlite
  companion fleet analyze 'logs/**/*.tlog' more/flight7.tlog --db fleet.sqlite --workers 8
  companion fleet analyze /shared/logs --db fleet.sqlite --scheduler tcp://10.0.0.5:8786
  companion fleet analyze logs/ --db fleet.sqlite --vehicle dir     one folder per vehicle
  companion fleet analyze logs/ --db fleet.sqlite --workers 0       in this process, no Dask

Vehicle id: the autopilot's board id when the log has one (AUTOPILOT_VERSION uid in a tlog, the boot
banner of a DataFlash log), else sys<MAVLink sysid>; --vehicle dir names vehicles by the log's folder
instead (CSV logs carry no id); a folder holding the logs of several boards is ranked per board, as
folder/<board id>. Run again with other --axes: the stored logs are analysed for the new axes too.
SIGTERM stops like Ctrl-C (exit 143); what is recorded stays.
"""


def register(sub) -> None:
    a = sub.add_parser("analyze", help="analyse logs in parallel into the database (resumable)",
                       description=ANALYZE_DESCRIPTION, epilog=ANALYZE_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    a.add_argument("logs", nargs="+", metavar="LOGS", help="log files, folders or glob patterns")
    a.add_argument("--db", required=True, metavar="FILE", help="SQLite database (created when missing)")
    g = a.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local Dask worker processes (default: CPU cores); 0: analyse in this process")
    g.add_argument("--scheduler", metavar="ADDR", help="an existing Dask scheduler, e.g. tcp://HOST:8786")
    a.add_argument("--vehicle", choices=("auto", "dir"), default="auto",
                   help="vehicle id: auto (board id, else sys<sysid>) or dir (the log's folder name)")
    a.add_argument("--axes", default="gx,gy,gz", help="axes to analyse (default gx,gy,gz)")
    a.add_argument("--batch", type=int, default=None, metavar="K",
                   help="logs per Dask task (default: 1 for up to 100 logs per worker, then more, at most 20 "
                        "-- fewer tasks for the scheduler and fewer database transactions; see docs/fleet.md)")
    a.add_argument("--retry-failed", action="store_true", help="analyse logs recorded as failed again")
    a.add_argument("--time-limit", type=float, default=None, metavar="S",
                   help="stop submitting after S seconds (what is recorded stays; run again to resume)")
    a.add_argument("--quiet", action="store_true", help="no progress line")
    a.set_defaults(func=run_analyze)


def run_analyze(args) -> int:
    from companion.cli.output import check_output_path
    from companion.fleet.orchestrate import AnalyzeOptions, analyze_fleet
    from companion.fleet.dask_runner import describe

    opts = AnalyzeOptions(args.logs, args.db, args.axes, args.workers, args.scheduler, args.vehicle, args.batch,
                          args.retry_failed, args.time_limit, args.quiet)
    opts.check()
    check_output_path(args.db, "--db")
    outcome = analyze_fleet(opts, say=lambda line: print(line, file=sys.stderr))
    code = outcome.exit_code()
    if outcome.stats is not None:
        for line in outcome.failure_lines():
            print(line, file=sys.stderr)
        print(describe(outcome.stats))
        if code in (EXIT_INTERRUPTED, EXIT_TERMINATED, EXIT_TIME_LIMIT):
            return code
    print(f"{args.db}: {outcome.counts['ok']} log(s) analysed, {outcome.counts['failed']} failed")
    if code == EXIT_FAULTS:
        print(f"companion fleet analyze: a gyro dead, stuck or saturated in {args.db} (fleet report ranks it; "
              f"exit status {code})", file=sys.stderr)
    elif code == EXIT_NO_DATA:
        print(f"companion fleet analyze: no log analysed in {args.db} (exit status {code})", file=sys.stderr)
    return code
