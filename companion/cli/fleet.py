"""``companion fleet``: analyse a fleet's logs on Dask into SQLite, report gyro trends, simulate a fleet."""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import sys

from companion.errors import CompanionError, Terminated

DESCRIPTION = """\
A fleet's thousands of logs: every IMU's noise coefficients per flight, kept in a SQLite database, and
the IMUs whose N, B or K rise across flights named. Three steps:

  companion fleet simulate demo/ --vehicles 20 --flights 30       a synthetic fleet (3 IMUs degrade)
  companion fleet analyze demo/ --db fleet.sqlite --workers 2     analyse every log (Dask), resumable
  companion fleet report --db fleet.sqlite --html report.html     ranking, trends, plots

Method and database schema: docs/fleet.md.
"""

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

SIM_DESCRIPTION = """\
Write a synthetic fleet: OUT_DIR/vehicle_NNN/flight_FFF.tlog for every vehicle and flight (a day apart),
each a still recording of --duration s at --rate Hz of --imus IMUs (ArduPilot's RAW_IMU, SCALED_IMU2,
SCALED_IMU3, int16 mrad/s; or HIGHRES_IMU), with the board id (AUTOPILOT_VERSION) and the INS_GYR_ID
parameters. Every IMU axis has its own N, B and K; --degrading IMUs chosen at random have --param
multiplied by --rise from the first to the last flight. The truth goes to OUT_DIR/fleet_truth.json.
"""

SIM_EPILOG = """\
examples:
  companion fleet simulate demo/ --vehicles 20 --flights 30
  companion fleet simulate small/ --vehicles 4 --flights 8 --duration 60 --rate 50 --seed 3
  companion fleet simulate b/ --vehicles 10 --flights 20 --param B --rise 2 --message HIGHRES_IMU
  companion fleet simulate df/ --vehicles 5 --flights 10 --format bin    # ArduPilot DataFlash logs
"""


def register(subparsers) -> None:
    p = subparsers.add_parser("fleet", help="many logs on Dask into SQLite, gyro trends across flights, HTML report",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="fleet_command", metavar="STEP")
    p.set_defaults(func=lambda args: _help(p))

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

    s = sub.add_parser("simulate", help="a synthetic fleet in which chosen IMUs degrade",
                       description=SIM_DESCRIPTION, epilog=SIM_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("out_dir", metavar="OUT_DIR", help="folder for the logs (vehicle_NNN/flight_FFF.tlog or .bin) and "
                   "fleet_truth.json; created when missing, existing files of the same names are overwritten")
    s.add_argument("--vehicles", type=int, required=True, metavar="V", help="number of vehicles (>= 1)")
    s.add_argument("--flights", type=int, required=True, metavar="F",
                   help="flights per vehicle (>= 1), one log each, a day apart")
    s.add_argument("--imus", type=int, default=3, help="IMUs per vehicle (default 3)")
    s.add_argument("--degrading", type=int, default=3, help="IMUs that degrade (default 3)")
    s.add_argument("--rise", type=float, default=1.5, help="last/first flight ratio of the degrading parameter (1.5)")
    s.add_argument("--param", choices=("N", "B", "K"), default="N", help="parameter that rises (default N)")
    s.add_argument("--duration", type=float, default=600.0, metavar="S", help="seconds per flight (default 600)")
    s.add_argument("--rate", type=float, default=100.0, metavar="HZ", help="sample rate (default 100)")
    s.add_argument("--message", choices=("ardupilot", "HIGHRES_IMU"), default="ardupilot",
                   help="ardupilot: RAW_IMU/SCALED_IMU2/SCALED_IMU3 int16 (default); HIGHRES_IMU: float "
                        "(tlogs only)")
    s.add_argument("--format", choices=("tlog", "bin"), default="tlog",
                   help="tlog: telemetry logs (default); bin: ArduPilot DataFlash logs (IMU messages, float "
                        "rad/s, board id in the boot banner, start time in a GPS record)")
    s.add_argument("--seed", type=int, default=0, help="random seed: the same seed and options write the same "
                   "fleet (default 0)")
    s.set_defaults(func=run_simulate)


def _help(p) -> int:
    p.print_help()
    return 2


class _Term:
    """SIGTERM (a batch system's time limit, ``kill``, systemd) stops the run like Ctrl-C -- what is recorded
    stays, the next run resumes -- and exits 143 (:class:`companion.errors.Terminated`). While the local
    cluster starts or closes the signal is held and acted on right after: raised in the middle of
    distributed's start-up it left a half-made cluster, whose clean-up at exit printed tracebacks."""

    def __init__(self):
        self.hold = 0
        self.pending = False
        try:
            self.old = signal.signal(signal.SIGTERM, self._handler)
        except ValueError:  # not the main thread
            self.old = None

    def _handler(self, signum, frame):
        if self.hold:
            self.pending = True
            return
        raise Terminated

    @contextlib.contextmanager
    def held(self):
        self.hold += 1
        try:
            yield
        except Exception:
            if self.pending:  # the start failed because the signal killed the workers too
                raise Terminated from None
            raise
        finally:
            self.hold -= 1
        if self.pending and not self.hold:
            raise Terminated

    def restore(self) -> None:
        if self.old is not None:
            signal.signal(signal.SIGTERM, self.old)


def run_analyze(args) -> int:
    from companion.cli.output import check_output_path
    from companion.fleet.discover import discover
    from companion.fleet.runner import (FleetProgress, close_client, hash_on_cluster, open_client, plan, run_dask,
                                        run_serial)
    from companion.fleet.store import FleetStore
    from companion.samples import AXES

    axes = tuple(a.strip() for a in args.axes.split(",") if a.strip())
    if not axes or any(a not in AXES for a in axes):
        raise CompanionError(f"bad --axes {args.axes!r}: expected a comma list of {', '.join(AXES)}")
    if args.batch is not None and args.batch < 1:
        raise CompanionError("--batch must be >= 1")
    if args.workers is not None and args.workers < 0:
        raise CompanionError("--workers must be >= 0")
    if args.time_limit is not None and not (args.time_limit > 0 and math.isfinite(args.time_limit)):
        raise CompanionError("--time-limit must be a positive number of seconds")
    check_output_path(args.db, "--db")
    logs = discover(args.logs)
    client = cluster = None
    term = _Term()
    try:
        with FleetStore(args.db) as store:
            hasher = None
            if args.scheduler:  # a cluster: hash the files on the workers, next to the storage
                with term.held():
                    client, cluster = open_client(None, args.scheduler)
                hasher = hash_on_cluster(client)
            work, skipped, unreadable, duplicates = plan(store, logs, retry_failed=args.retry_failed, hasher=hasher,
                                                         axes=axes)
            for path, reason in unreadable[:10]:
                print(f"warning: {path}: {reason}; skipped", file=sys.stderr)
            more = sum(w.axes is not None for w in work)
            print(f"{len(logs)} log(s): {len(work)} to analyse"
                  + (f" ({more} of them stored before without some of the axes {','.join(axes)})" if more else "")
                  + f", {skipped} already in {args.db}"
                  + (f", {duplicates} duplicate(s) (the same content as another log given)" if duplicates else "")
                  + (f", {len(unreadable)} unreadable" if unreadable else ""), file=sys.stderr)
            progress = FleetProgress(len(work), skipped + duplicates, enabled=not args.quiet)
            stats = None
            if work and args.workers == 0 and not args.scheduler:
                stats = run_serial(store, work, progress, axes, args.vehicle, args.time_limit)
            elif work:
                if client is None:
                    with term.held():
                        client, cluster = open_client(args.workers or os.cpu_count() or 1, None)
                stats = run_dask(store, work, progress, client, axes, args.vehicle, args.time_limit,
                                 batch=args.batch)
            rc = _finish(args, store, stats, progress, skipped, duplicates)
    finally:
        try:
            if client is not None:
                with term.held():
                    close_client(client, cluster)
        finally:
            term.restore()
    return rc


def _finish(args, store, stats, progress, skipped, duplicates=0) -> int:
    from companion.fleet.runner import describe

    if stats is not None:
        progress.close()
        stats.skipped, stats.duplicates = skipped, duplicates
        for path, reason in stats.failures[:10]:
            print(f"failed: {path}: {reason}", file=sys.stderr)
        if len(stats.failures) > 10:
            print(f"... and {len(stats.failures) - 10} more failed (fleet report --html lists them)",
                  file=sys.stderr)
        print(describe(stats))
        if stats.stopped == "interrupted":
            return 130
        if stats.stopped == "terminated":
            return Terminated.exit_code
        if stats.stopped == "deadline":
            return 3
    c = store.counts()
    print(f"{args.db}: {c['ok']} log(s) analysed, {c['failed']} failed")
    return 0


def run_report(args) -> int:
    from companion.cli.output import check_output_path, to_json, write_text
    from companion.fleet.report import fleet_trends, identity_notes, report_html, report_json
    from companion.fleet.trend import EVIDENCE_THRESHOLD, MIN_RISE

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
        flagged = sum(e["flagged"] for e in entries)
        print(f"{len(entries)} IMUs, {flagged} flagged (evidence >= {EVIDENCE_THRESHOLD:g}, rise >= {MIN_RISE:g}x)")
        # board ids in full (a 96-bit MCU id is 24 hex digits, with its board name and a folder more)
        wv = max([18] + [len(e["vehicle"]) for e in entries])
        print(f"{'#':>4} {'vehicle':<{wv}} {'sys':>3} {'IMU':<16} {'flights':>7} {'flag':>4} {'evidence':>8} "
              f"{'worst':<6} {'trend':>6}")
        top = entries if args.top == 0 else entries[:args.top]
        for i, e in enumerate(top, 1):
            worst = f"{e['axis']} {e['param']}" if e["axis"] else "-"
            trend = f"{e['trend']:.2f}x" if e["trend"] is not None else "-"
            print(f"{i:>4} {e['vehicle']:<{wv}} {e['sysid']:>3} {str(e['imu']) + ' ' + e['message']:<16} "
                  f"{e['flights']:>7} {'YES' if e['flagged'] else 'no':>4} {e['evidence']:>8.1f} {worst:<6} {trend:>6}"
                  + (f"  ({e['note']})" if e["note"] and not e["axis"] else ""))
        if len(top) < len(entries):
            print(f"... {len(entries) - len(top)} more (--top 0 for all)")
        for who, note, flagged in identity_notes(entries):  # trends over logs that may not be one vehicle's
            print(f"note: {who}{note}" + (" (a flagged IMU among them)" if flagged else ""))
        if args.json:
            write_text(args.json, to_json(report_json(store, entries, EVIDENCE_THRESHOLD, MIN_RISE)) + "\n", "JSON")
            print(f"wrote {args.json}")
        if args.html:
            write_text(args.html, report_html(store, entries, EVIDENCE_THRESHOLD, MIN_RISE, args.max_plots), "HTML")
            print(f"wrote {args.html}")
    return 0


def _report_nothing(args, store) -> int:
    """No IMU to rank (every log failed, or none analysed): the files are still written, saying why (a
    nightly job's report page must not silently keep yesterday's), then one error line."""
    from companion.cli.output import to_json, write_text
    from companion.fleet.report import failure_reasons, report_html, report_json
    from companion.fleet.trend import EVIDENCE_THRESHOLD, MIN_RISE

    c = store.counts()
    for n, reason in failure_reasons(store.failures()):
        print(f"{n} log(s) failed: {reason}")
    written = []
    if args.json:
        write_text(args.json, to_json(report_json(store, [], EVIDENCE_THRESHOLD, MIN_RISE)) + "\n", "JSON")
        written.append(args.json)
    if args.html:
        write_text(args.html, report_html(store, [], EVIDENCE_THRESHOLD, MIN_RISE, args.max_plots), "HTML")
        written.append(args.html)
    for path in written:
        print(f"wrote {path}")
    what = f"all {c['failed']} log(s) failed" if c["failed"] and not c["ok"] else \
        f"no analysed IMU data ({c['ok']} logs ok, {c['failed']} failed)"
    raise CompanionError(f"{args.db}: no IMU to rank: {what}")


def run_simulate(args) -> int:
    from companion.fleet.simulate import simulate_fleet

    for name in ("vehicles", "flights", "imus"):
        if getattr(args, name) < 1:
            raise CompanionError(f"--{name} must be >= 1")
    if not (args.duration > 0 and math.isfinite(args.duration)) or not (args.rate > 0 and math.isfinite(args.rate)):
        raise CompanionError("--duration and --rate must be positive")
    if args.duration * args.rate < 64:
        raise CompanionError(f"--duration {args.duration:g} s at {args.rate:g} Hz is fewer than 64 samples per flight")
    if not 0 <= args.degrading <= args.vehicles * args.imus:
        raise CompanionError(f"--degrading must be between 0 and --vehicles x --imus = {args.vehicles * args.imus}")
    if args.seed < 0:
        raise CompanionError("--seed must be >= 0")
    if not (args.rise > 0 and math.isfinite(args.rise)):
        raise CompanionError("--rise must be a positive ratio")
    if args.format == "bin" and args.message != "ardupilot":
        raise CompanionError("--message chooses the MAVLink message of tlogs; DataFlash logs hold IMU messages")
    if args.format == "bin" and args.imus > 3:
        raise CompanionError("--format bin writes at most 3 IMUs (ArduPilot's IMU instances 0-2)")
    tty = sys.stderr.isatty()

    def progress(done, total):
        if tty:
            sys.stderr.write(f"\rsimulate {done}/{total} logs")
            sys.stderr.flush()

    try:
        truth = simulate_fleet(args.out_dir, args.vehicles, args.flights, args.imus, args.degrading, args.rise,
                               args.param, args.duration, args.rate, args.seed, args.message, progress,
                               args.format)
    except ValueError as exc:
        raise CompanionError(str(exc)) from None
    except OSError as exc:
        raise CompanionError(f"{args.out_dir}: cannot write ({exc.strerror or exc})") from None
    if tty:
        sys.stderr.write("\n")
    deg = [f"{v['name']} IMU{i['imu']}" for v in truth["vehicles"] for i in v["imus"] if i["degrading"]]
    print(f"wrote {len(truth['logs'])} logs to {args.out_dir} ({args.vehicles} vehicles x {args.flights} flights, "
          f"{args.imus} IMUs each); degrading ({args.param} x{args.rise:g}): {', '.join(deg) or 'none'}")
    return 0
