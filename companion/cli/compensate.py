"""``companion compensate``: ARIMA(1,1,1) gyro random-error compensation with STF, SR-UKF and SR-RSUKF
(Shi et al.), and the Allan deviation of the raw and of each compensated series."""

from __future__ import annotations

import argparse
import sys

from companion.cli.output import to_json, write_text
from companion.cli.progress import Progress
from companion.errors import EXIT_NUMERICS, CompanionError
from companion.samples import AXES
from companion.units import rate_display

DESCRIPTION = """\
Compensate the random error of one gyro axis with the three methods of Shi et al. ("Compensation of MEMS
gyroscope random error based on square-root risk-sensitive UKF"):
  stf      model L (linear ARIMA(1,1,1)) + strong tracking Kalman filter (fading factor)
  srukf    model NL (ARIMA parameters as states) + square-root UKF
  srrsukf  model NL + square-root risk-sensitive UKF (diagonal risk-sensitive matrix)
The ARIMA(1,1,1) + white-noise model is first fitted to the data by least squares (no hand tuning);
each filter then runs sample by sample. The compensated series is the filtered estimate x_k: the
gyro output with the white measurement noise removed. The table compares the overlapping Allan
deviation of each compensated series with that of the raw series (ratio < 1: lower noise) at tau0,
about 1 s and about 100 s, never beyond a tenth of the record, with the raw ADEV in deg/s (m/s^2 for
an accelerometer axis), and the speed; a warning says when no method got below 0.9x raw at tau0.
Meant for data at rest; on a moving vehicle the filters also smooth real motion.
The longest still, gap-free piece of the chosen IMU stream is used (disarmed where the log says so,
motion judged from the accelerometers); without one, the longest gap-free segment, with a warning.
Method and measurements: docs/compensation.md.
"""

EPILOG = """\
examples:
  companion compensate imu.csv.gz --axis gy --plot comp.png
  companion compensate flight.tlog --axis gz --method srukf --json comp.json --out comp.csv
  companion compensate imu.csv.gz --axis gx --max-samples 100000     first 1000 s at 100 Hz

--out writes time_s, raw and one column per method (same unit as the input, rad/s for gyros).
--json writes {"axis", "raw": {"tau", "adev"}, "methods": {name: {"tau", "adev", "adev_ratio",
"samples_per_s", "factor_valid", ...}}, "arima": fitted parameters}.
Speed: STF about 10^5-10^6 samples/s, the UKFs about 10^4 samples/s (pure numpy, one core).
"""


def register(subparsers) -> None:
    p = subparsers.add_parser("compensate", help="ARIMA random-error compensation (STF, SR-UKF, SR-RSUKF) and ADEV",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", help=".tlog, DataFlash .bin, PX4 .ulg, .csv (each optionally .gz), or a "
                   "connection string (with --duration)")
    p.add_argument("--axis", required=True, help=f"axis to compensate: {', '.join(AXES)}")
    p.add_argument("--method", default="all", help="stf, srukf, srrsukf, all, or a comma list (default all)")
    p.add_argument("--json", metavar="OUT", help="write ADEVs and fitted parameters as JSON (SI units)")
    p.add_argument("--plot", metavar="PNG", help="raw and compensated series and their Allan deviations")
    p.add_argument("--out", metavar="CSV", help="write the compensated series as CSV")
    p.add_argument("--max-samples", type=int, default=None, metavar="N",
                   help="use only the first N samples of that piece")
    p.add_argument("--stream", type=int, default=0, metavar="I", help="index of the IMU stream (default 0, the first)")
    p.add_argument("--split", default="auto", choices=("auto", "free", "canonical"),
                   help="how the ARIMA fit shares white noise between error and measurement noise (default auto)")
    p.add_argument("--duration", type=float, default=None, help="seconds to listen on a live link")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (streams: scale overrides)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def parse_methods(spec: str) -> tuple:
    from companion.compensation.compare_methods import METHODS  # scipy: loaded only when this command runs

    names = [s.strip().lower() for s in spec.split(",") if s.strip()]
    if not names or names == ["all"]:
        return METHODS
    bad = [n for n in names if n not in METHODS]
    if bad:
        raise CompanionError(f"unknown --method {bad[0]!r}; expected {', '.join(METHODS)} or all")
    return tuple(dict.fromkeys(names))


def run(args) -> int:
    from companion.cli.output import check_output_path, check_plot_path
    from companion.cli.source_options import warn_ignored_options
    from companion.sources import load

    for opt, path in (("--json", args.json), ("--out", args.out)):
        if path:
            check_output_path(path, opt)
    if args.out and not args.out.lower().endswith((".csv", ".csv.gz")):
        # CSV text under a log's name (c.tlog) would be refused, or misread, by every tool that opens it
        raise CompanionError(f"--out {args.out}: writes CSV text; give a .csv or .csv.gz file name")
    if args.max_samples is not None and args.max_samples < 1:
        raise CompanionError(f"--max-samples must be >= 1, got {args.max_samples}")
    if args.stream < 0:
        raise CompanionError(f"--stream must be >= 0 (an index into the IMU streams), got {args.stream}")
    if args.plot:
        check_plot_path(args.plot)
    axis = args.axis.strip().lower()
    if axis not in AXES:
        raise CompanionError(f"unknown --axis {args.axis!r}; expected one of {', '.join(AXES)}")
    methods = parse_methods(args.method)
    warn_ignored_options(args, [args.source], "compensate")
    res = load(args.source, args.config, duration=args.duration)
    from companion.compensation.arima import MIN_FIT_SAMPLES
    from companion.compensation.compare_methods import compensate
    from companion.compensation.comparison_table import format_table, json_report, max_tau, nothing_helped, write_series_csv
    from companion.sources.series import select_series

    series = select_series(res, axis, args.stream, args.max_samples, MIN_FIT_SAMPLES, "the ARIMA(1,1,1) fit",
                           warn=lambda m: print(f"warning: {m}", file=sys.stderr))
    progress = Progress("compensate", enabled=not args.quiet and series.z.shape[0] > 50_000)
    try:
        result = compensate(series.z, series.rate_hz, methods=methods, progress=progress, split=args.split)
    finally:
        progress.close()
    print(format_table(result, axis, series.label))
    warning = nothing_helped(result)
    if warning:
        print(f"companion: warning: {warning}", file=sys.stderr)
    if args.json:
        write_text(args.json, to_json(json_report(result, axis, series.label)) + "\n", "JSON")
        print(f"wrote {args.json}")  # every file written is named, as analyze, gap and simulate do
    if args.out:
        write_series_csv(args.out, series.t, series.z, result, axis)
        print(f"wrote {args.out}")
    if args.plot:
        from companion.plots.compensation_plot import plot_compensation

        scale, unit = rate_display(axis)
        plot_compensation(result, series.t, series.z, args.plot, title=f"{series.label} {axis}", unit_scale=scale,
                          unit=unit, max_tau=max_tau(series.z.shape[0], series.rate_hz))
        print(f"wrote {args.plot}")
    bad = [m.name for m in result.methods.values() if not m.factor_valid]
    if bad:
        print(f"companion: warning: covariance factor lost validity in {', '.join(bad)} (exit status "
              f"{EXIT_NUMERICS})", file=sys.stderr)
        return EXIT_NUMERICS
    return 0
