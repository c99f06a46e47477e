"""``companion gap``: where a noise model and a measurement disagree, what effect is missing, the fix."""

from __future__ import annotations

import argparse
import math

from companion.cli.output import to_json, write_text
from companion.errors import CompanionError
from companion.samples import AXES

DESCRIPTION = """\
Compare a noise model (YAML, as written by 'companion analyze'/'simulate' or by hand from a datasheet)
with measured data on one axis, and fix the model:

  1. measured Allan deviation with its 95 % band;
  2. the model's Allan deviation, analytic and confirmed by simulating the model;
  3. the tau ranges where the measurement leaves the model's band (table);
  4. every effect the model lacks (quantization, white_noise, bias_instability, random_walk, ramp,
     gauss_markov, sinusoid) added, each model term recalibrated, and each effect with a recalibrated
     term: all fitted to the same data and ranked by one score (deviance removed minus the penalty of the
     documented test level, scaled for the correlated long-tau Allan points); the best is taken when its
     corrected likelihood ratio passes that level, and the runner-up is printed beside it (so a ramp and
     a 5x larger random walk are weighed against each other, not tested one after the other); a named
     sinusoid is checked against the periodogram; a random walk that won over a long Gauss-Markov comes
     with that Gauss-Markov as the alternative the record is too short to rule out;
  5. repeated until no significant gap remains; gap before/after (G = 1 on average for a right model,
     noise floor 2) against the analytic curves and against fresh simulations.

If the model already fits within the noise, it says so and adds nothing. See docs/gap.md."""

EPILOG = """\
examples:
  companion gap flight.bin --datasheet MPU-6000 --imu 0         datasheet model vs the log's still segments
  companion gap flight.ulg --datasheet ICM-42688 --axis gz --plot gap.png
  companion gap flight.tlog --model imu_model.yaml --axis gx
  companion gap adis.csv.gz --model datasheet.yaml --axis gy --json gap.json --out-model fixed.yaml
  companion gap raw.csv --model m.yaml --axis gz --lsb 1e-3     rate rounded to 1 mrad/s (int16 RAW_IMU)

MEASURED is anything 'companion analyze' reads (.bin, .ulg, .tlog, .csv, .csv.gz); the still segments are
selected as analyze selects them (armed state, motion; --start/--end/--all) and pooled. Besides the seven
terms the candidates include the autopilot's low-pass filter with the logger's decimation (cut-off from
INS_GYRO_FILTER / INS_MPU6K_FILTER / IMU_GYRO_CUTOFF or --cutoff, else fitted) and, when the log has a temperature channel,
a temperature-driven rate checked against that channel. With --datasheet the first line says which
datasheet term the measurement contradicts and by how much.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser("gap", help="find where a noise model and a measurement disagree, name the missing "
                              "effect, fix the model", description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("measured", metavar="MEASURED", help="log with IMU data: .bin, .ulg, .tlog, .csv (.gz)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--model", metavar="MODEL.yaml", help="noise model YAML (SI units)")
    src.add_argument("--datasheet", metavar="NAME", help="start from a gyro's datasheet figures (" +
                     ", ".join(_datasheet_names()) + ")")
    p.add_argument("--axis", choices=AXES, help="axis to compare (default: every gyro axis of the model)")
    sel = p.add_mutually_exclusive_group()
    sel.add_argument("--imu", type=int, metavar="I", help="IMU instance to use (default: the IMU stream with the "
                     "most still samples)")
    sel.add_argument("--stream", metavar="LABEL", help="IMU stream by its label or message name, e.g. IMU[1], "
                     "sensor_combined, RAW_IMU")
    p.add_argument("--json", metavar="OUT", help="write the result as JSON ('-' for stdout)")
    p.add_argument("--out-model", metavar="NEW.yaml",
                   help="write the sensor's updated model at the data's rate_hz (other axes' terms unchanged; the "
                   "log's rate rounding and filter are not written: docs/gap.md)")
    p.add_argument("--plot", metavar="PNG", help="write the gap figure (one per axis: NAME_gx.png ... when several)")
    p.add_argument("--lsb", type=float, metavar="RAD_S",
                   help="output step of the data in SI (default: the format's, e.g. 1e-3 for RAW_IMU gyro, or "
                        "detected from the values)")
    p.add_argument("--cutoff", type=float, metavar="HZ", help="low-pass cut-off of the logged data (default: the "
                   "log's INS_GYRO_FILTER / IMU_GYRO_CUTOFF, else fitted)")
    p.add_argument("--start", type=float, metavar="S", help="ignore data before this time (s)")
    p.add_argument("--end", type=float, metavar="S", help="ignore data after this time (s)")
    p.add_argument("--all", dest="use_all", action="store_true", help="use the whole record, not only still "
                   "segments")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulations (default 0)")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (streams: scale overrides)")
    p.add_argument("--time-unit", choices=("s", "ms", "us"), default=None, dest="time_unit",
                   help="unit of a CSV's time column (default s; a column whose median step is 1 or more, or coarser than "
                        "the sample rate, is refused with the unit to pass)")
    p.set_defaults(func=run)


def _datasheet_names() -> list[str]:
    try:
        from companion.datasheets import names

        return names()
    except Exception:  # the help text must not fail on a broken install
        return []


def _axis_path(path, axis, several):
    if not several or path in (None, "-"):
        return path
    from pathlib import Path

    q = Path(path)
    return str(q.with_name(f"{q.stem}_{axis}{q.suffix}"))


def _check_options(args) -> None:
    """Everything that can be checked before the model and the log are read."""
    from companion.cli.output import check_output_path, check_plot_path
    from companion.cli.source_options import check_time_window, warn_ignored_options

    for opt, path in (("--json", None if args.json == "-" else args.json), ("--out-model", args.out_model)):
        if path:
            check_output_path(path, opt)
    if args.plot:
        check_plot_path(args.plot)
    warn_ignored_options(args, [args.measured], "gap")
    check_time_window(args)
    for opt in ("lsb", "cutoff"):
        v = getattr(args, opt)
        if v is not None and not (v > 0 and math.isfinite(v)):
            raise CompanionError(f"--{opt} must be a positive number, got {v}")


def _plot(run, args, several) -> None:
    from companion.plots.gap_plot import plot_gap

    path = _axis_path(args.plot, run.axis, several)
    try:
        plot_gap(run.result, path)
    except OSError as exc:
        raise CompanionError(f"cannot write {args.plot}: {exc.strerror or exc}") from None
    print(f"wrote {path}")  # every file written is named, as analyze and compensate do


def run(args) -> int:
    from companion.gap.from_log import GapLogOptions, prepare, run_axes, write_updated_model

    _check_options(args)
    lg = prepare(GapLogOptions.from_args(args))
    several = len(lg.axes) > 1
    runs = []
    for r in run_axes(lg):
        if args.json != "-":
            print(r.text + ("\n" if several else ""))
        runs.append(r)
        if args.plot:
            _plot(r, args, several)
    if args.json:
        s = to_json(runs[0].doc if not several else {"axes": [r.doc for r in runs]}, indent=2)
        if args.json == "-":
            print(s)
        else:
            write_text(args.json, s + "\n", "JSON")
            print(f"wrote {args.json}")
    if args.out_model:
        left = write_updated_model(lg, runs, args.out_model)
        print(f"wrote {args.out_model}")
        if left:
            print(f"  (the sensor's terms at the data's {lg.rate_hz:.6g} Hz; the log's own, which gap derives from it "
                  f"on every run, not written: {'; '.join(left)})")
    return 0
