"""``companion analyze``: overlapping Allan deviation with 95 % intervals and the fitted noise terms, per IMU
stream and axis, as a table in datasheet units, a JSON report (SI), a plot and a Kalibr imu.yaml."""

from __future__ import annotations

import argparse
import math
import sys

from companion.cli.analyze_report import add_argument as add_report_argument
from companion.cli.output import to_json, write_text
from companion.cli.progress import Progress
from companion.errors import EXIT_FAULTS, EXIT_NO_DATA, EXIT_USAGE, CompanionError
from companion.samples import AXES

DESCRIPTION = """\
Post-flight noise analysis. For every IMU stream of SOURCE (a .tlog, an ArduPilot DataFlash .bin, a PX4
.ulg, a CSV time_s,gx,gy,gz,ax,ay,az in rad/s and m/s^2 -- each optionally .gz -- or a connection string
listened to for --duration s) and every axis: the overlapping
Allan deviation with 95 % confidence intervals (EDF from the fitted noise model), and an automatic
weighted fit of the IEEE 952 terms (white noise N, bias instability B, rate random walk K; quantization Q,
ramp R and a Gauss-Markov term only when the data demand them), each with a 95 % interval.
Only the still parts are analysed: the log's armed state (DataFlash EV/ARM, ULog vehicle_status, the
vehicle autopilot's HEARTBEATs in a tlog) and a
motion detector over the accelerometers and gyros of every IMU pick the still segments, and the Allan
variance is pooled over them (no cluster crosses a gap); the report says what was used and what was left
out. Each stream also gets ground (armed, not moving) and flight figures: each IMU's own noise from the
vehicle's redundant IMUs (docs/inflight.md), so a log armed throughout is analysed, not refused. --start/--end restrict the time, --all skips the selection. A low-pass filter of the logged data
(INS_GYRO_FILTER, older INS_MPU6K_FILTER, IMU_GYRO_CUTOFF, or a roll-off the data show; the data set a
log's cut-off aside when it lies outside their 99 % interval, or for a first-order roll-off, the shape of a
short Gauss-Markov process, which the note then names) is modelled in the white-noise term, so N
comes from every cluster time and the filter never becomes bias instability or a Gauss-Markov term; where
no cluster time carries white noise above the filter's corner, N is a bound and the table says why. A stream slower than 10 Hz or shorter than 60 s gets a warning and no Kalibr
file (unless --force). Gyro in deg/sqrt(h), deg/h, deg/h^1.5;
accel in m/s/sqrt(h), mg, m/s/h^1.5. For int16 messages the contribution of the 1-LSB rounding to N is
reported (and whether the data are dithered at all). Method: docs/analysis.md.
"""

EPILOG = """\
examples:
  companion analyze tlogs/sample.tlog --plot adev.png
  companion analyze flight.tlog --json report.json --kalibr imu.yaml
  companion analyze imu.csv.gz --taus log:10 --axes gx,gy,gz
  companion analyze imu.csv --taus 0.1,1,10,100          cluster times in seconds
  companion analyze flight.tlog --online --json r.json    offline and online estimates side by side
  companion analyze 00000042.BIN --plot adev.png          every IMU of an ArduPilot log, still parts only
  companion analyze before.bin after.bin --plot cmp.png   two logs overlaid in one figure
  companion analyze log.ulg --start 10 --end 95           a time window chosen by hand (still selection inside)
  companion analyze bench.csv --all                       no still selection
  companion analyze flight.tlog --report analyze.html     interactive page, run's detectors over the log

--taus: octave (1, 2, 4 ... samples), decade (1, 2, 4, 10, 20, 40 ...), all, log:N (N per decade), or a
comma list of seconds. The fit always uses octave-spaced points with their full covariance; --taus
chooses what the table/JSON/plot show.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser("analyze", help="Allan deviation, fitted noise terms with 95 %% intervals, plot, JSON",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", nargs="+",
                   help=".tlog, DataFlash .bin, PX4 .ulg, .csv (each optionally .gz), or a connection string "
                        "(with --duration); several files are analysed one after the other (one plot overlays them)")
    p.add_argument("--json", metavar="OUT", help="write the report as JSON (SI units)")
    p.add_argument("--plot", metavar="PNG", help="write the Allan deviation plot (one file per stream if several)")
    p.add_argument("--kalibr", metavar="YAML", help="write a Kalibr imu.yaml (noise densities and random walks)")
    p.add_argument("--taus", default="octave", help="octave|decade|all|log:N|comma list of seconds (default octave)")
    p.add_argument("--axes", default=",".join(AXES), help="axes to analyse (default gx,gy,gz,ax,ay,az)")
    p.add_argument("--duration", type=float, default=None, help="seconds to listen on a live link")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (streams: scale overrides)")
    p.add_argument("--time-unit", choices=("s", "ms", "us"), default=None, dest="time_unit",
                   help="unit of a CSV's time column (default s; a column whose median step is 1 or more, or coarser than "
                        "the sample rate, is refused with the unit to pass)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--start", type=float, default=None, metavar="S",
                   help="analyse only from this time (seconds, the log's own clock as inspect shows it)")
    p.add_argument("--end", type=float, default=None, metavar="S", help="analyse only up to this time")
    p.add_argument("--all", action="store_true", dest="use_all",
                   help="no still-segment selection: every contiguous segment between --start and --end")
    p.add_argument("--min-still", type=float, default=10.0, metavar="S",
                   help="shortest still stretch used (default 10 s)")
    p.add_argument("--force", action="store_true",
                   help="write the Kalibr file even for a stream slower than 10 Hz or shorter than 60 s")
    p.add_argument("--online", action="store_true",
                   help="also run the online estimator (octave bank, model chosen from the data, docs/online.md) "
                        "over each axis, the same report as `companion run`: JSON key 'online' per axis (terms with "
                        "'bound': true for 95 %% upper bounds), table row 'online' ('< x' = bound)")
    add_report_argument(p)
    p.set_defaults(func=run)


def analyze_source(spec, args, axes, progress_enabled=True) -> tuple[list[dict], dict]:
    """:func:`companion.analysis.source.analyze_source` with the options of ``args`` (a progress bar on a
    terminal for inputs over 2 million values; --taus beyond the record as warnings on stderr)."""
    from companion.analysis.source import analyze_source as analyze

    def progress(steps, values):
        return Progress("analyze", steps, enabled=progress_enabled and values > 2_000_000)

    return analyze(spec, axes, args.taus, config=getattr(args, "config", None), duration=getattr(args, "duration", None),
                   start=getattr(args, "start", None), end=getattr(args, "end", None),
                   use_all=getattr(args, "use_all", False), min_still=getattr(args, "min_still", 10.0),
                   online=getattr(args, "online", False), progress=progress,
                   time_unit=getattr(args, "time_unit", None),
                   warn=lambda text: print(f"companion analyze: warning: {text}", file=sys.stderr))


def run(args) -> int:
    from companion.analysis.kalibr import kalibr_blockers, kalibr_yaml
    from companion.analysis.report_table import format_table
    from companion.cli.output import check_output_path, check_plot_path
    from companion.cli.source_options import check_time_window, warn_ignored_options

    for opt, path in (("--json", args.json), ("--kalibr", args.kalibr), ("--report", args.report)):  # outputs checked before the work
        if path:
            check_output_path(path, opt)
    if args.plot:
        check_plot_path(args.plot)
    axes = [a.strip() for a in args.axes.split(",") if a.strip()]
    bad = [a for a in axes if a not in AXES]
    if bad or not axes:
        raise CompanionError(f"bad --axes {args.axes!r}: expected a comma list of {', '.join(AXES)}")
    # a negative (or NaN) shortest stretch would quietly mean "every still stretch"; say what is accepted
    if not (math.isfinite(args.min_still) and args.min_still >= 0):
        raise CompanionError(f"--min-still must be a number of seconds >= 0, got {args.min_still:g}")
    sources = args.source if isinstance(args.source, (list, tuple)) else [args.source]
    check_time_window(args)
    warn_ignored_options(args, sources, "analyze")
    report = {"source": str(sources[0]) if len(sources) == 1 else ", ".join(map(str, sources)),
              "sources": [], "streams": []}
    failed, codes, dead, frozen = [], [], [], []
    for spec in sources:
        try:
            entries, summary = analyze_source(spec, args, axes, progress_enabled=not args.quiet)
        except CompanionError as exc:
            if len(sources) == 1:
                raise
            failed.append(str(exc))  # the other logs are still analysed; the exit status says it
            codes.append(exc.exit_code)
            continue
        dead += summary.pop("dead_gyros", [])  # for the exit status; the notes say it in the report
        frozen += summary.pop("frozen_gyros", [])
        report["sources"].append(summary)
        report["streams"].extend(entries)
    if not report["streams"]:
        from companion.analysis.source import nothing_analysed

        raise CompanionError("; ".join(failed) if failed else nothing_analysed(report["sources"]),
                             _all_failed_code(codes))
    report["failed_sources"] = failed
    for summary in report["sources"]:
        print(f"{summary['source']}: {summary['selection']['description']}")
        for n in summary["notes"]:
            print(f"note: {n}")
        for line in (summary.get("autopilot") or {}).get("lines", []):
            print(f"autopilot: {line}")
    report["warnings"] = [f"{st['message']}[{st['instance']}]: {w}" for st in report["streams"] for w in st["warnings"]]
    print(format_table(report))
    if args.report:  # run's fault detectors over each log: the flagged IMUs' evidence (cli.analyze_report)
        from companion.cli import analyze_report

        report["evidence"], report["evidence_note"] = analyze_report.evidence(sources, args)
        analyze_report.write(args.report, report)
    if args.json:
        write_text(args.json, to_json(report) + "\n", "JSON")
        print(f"wrote {args.json}")
    if args.plot:
        from companion.plots.adev_plot import plot_report

        still = {**report, "streams": [st for st in report["streams"] if st["axes"]]}  # ground/flight only: none
        for path in plot_report(still, args.plot) if still["streams"] else []:
            print(f"wrote {path}")
        if not still["streams"]:
            print(f"{args.plot} not written: no still data to plot (the ground and flight figures are in the table)")
    if args.kalibr:
        blockers = kalibr_blockers(report)
        if blockers and not args.force:
            raise CompanionError(f"{args.kalibr} not written: {'; '.join(blockers)} (--force writes it anyway)")
        write_text(args.kalibr, kalibr_yaml(report), "Kalibr YAML")
        print(f"wrote {args.kalibr}")
    if failed:  # a gyro fault found in any source outranks the sources that could not be read
        raise CompanionError(f"{len(failed)} of {len(sources)} sources not analysed: {'; '.join(failed)}",
                             EXIT_FAULTS if dead or frozen or EXIT_FAULTS in codes else EXIT_USAGE)
    if dead or frozen:  # said above as a warning; the exit status lets a script gate on it (README "Exit status")
        print(f"companion analyze: gyro faults found: {_found(dead, frozen)}", file=sys.stderr)
        return EXIT_FAULTS
    return 0


def _found(dead: list, frozen: list) -> str:
    """What the exit status says, e.g. ``1 dead gyro stream(s) (exit status 4)``."""
    return ", ".join(([f"{len(dead)} dead gyro stream(s)"] if dead else [])
                     + ([f"{len(frozen)} gyro axis/axes frozen while moving"] if frozen else [])) + \
        f" (exit status {EXIT_FAULTS})"


def _all_failed_code(codes) -> int:
    """Every source failed: a dead gyro among them is a fault found; none with usable data, no usable data;
    else the usage/input error."""
    if EXIT_FAULTS in codes:
        return EXIT_FAULTS
    if codes and all(c == EXIT_NO_DATA for c in codes):
        return EXIT_NO_DATA
    return EXIT_USAGE
