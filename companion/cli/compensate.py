"""``companion compensate``: ARIMA(1,1,1) gyro random-error compensation with STF, SR-UKF and SR-RSUKF
(Shi et al.), and the Allan deviation of the raw and of each compensated series."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from companion.cli.output import to_json, write_text
from companion.cli.progress import Progress
from companion.errors import CompanionError
from companion.samples import AXES, GYRO_AXES

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
    from companion.compensation.pipeline import METHODS  # scipy: loaded only when this command runs

    names = [s.strip().lower() for s in spec.split(",") if s.strip()]
    if not names or names == ["all"]:
        return METHODS
    bad = [n for n in names if n not in METHODS]
    if bad:
        raise CompanionError(f"unknown --method {bad[0]!r}; expected {', '.join(METHODS)} or all")
    return tuple(dict.fromkeys(names))


def _has_axis(stream, axis: str) -> bool:
    """Whether the stream carries data for ``axis`` (a batch-sampler burst of one sensor has NaN for the other)."""
    return bool(np.any(np.isfinite(stream.axis(axis))))


def select_series(res, axis: str, stream_index: int, max_samples):
    """(t, z, rate_hz, label) of the longest still, gap-free piece of the chosen IMU stream."""
    streams = res.imu_streams()
    if not streams:
        raise CompanionError(f"{res.source}: no IMU stream")
    if not 0 <= stream_index < len(streams):
        labels = "; ".join(f"{i}: {s.key.label()}" for i, s in enumerate(streams))
        raise CompanionError(f"--stream {stream_index} out of range; IMU streams: {labels}")
    s = streams[stream_index]
    kind = "gyro" if axis in GYRO_AXES else "accel"
    if not _has_axis(s, axis):
        other = "accel" if kind == "gyro" else "gyro"
        usable = [f"{i}: {o.key.label()}" for i, o in enumerate(streams) if _has_axis(o, axis)]
        where = (f"{kind} streams: {'; '.join(usable)} (choose one with --stream I)" if usable
                 else f"this source has no {kind} stream")
        raise CompanionError(f"{s.key.label()} (--stream {stream_index}) has no {kind} data ({other} only); {where}")
    from companion.sources.still import longest_still_range

    a, b = longest_still_range(res, s, warn=lambda m: print(f"warning: {m}", file=sys.stderr))
    if max_samples is not None:
        if max_samples < 1:
            raise CompanionError("--max-samples must be at least 1")
        b = min(b, a + max_samples)
    rate = float(s.rate_hz)
    if not rate > 0:
        raise CompanionError(f"{s.key.label()}: no usable sample rate")
    from companion.compensation.arima import MIN_FIT_SAMPLES

    if b - a < MIN_FIT_SAMPLES:
        longer = [f"{i}: {o.key.label()} ({o.samples} samples)" for i, o in enumerate(streams)
                  if i != stream_index and o.samples >= MIN_FIT_SAMPLES and _has_axis(o, axis)]
        hint = f"; streams with more data: {'; '.join(longer)}" if longer else ""
        raise CompanionError(f"{s.key.label()} {axis}: {b - a} samples ({(b - a) / rate:.1f} s at {rate:g} Hz) are too "
                             f"few for the ARIMA(1,1,1) fit (need at least {MIN_FIT_SAMPLES}){hint}")
    z = np.asarray(s.axis(axis)[a:b], dtype=float)
    if np.all(z == z[0]):
        scale, unit = display_unit(axis)
        raise CompanionError(f"{s.key.label()} {axis}: all {b - a} samples are {z[0] * scale:g} {unit} "
                             f"(stuck, absent or not logged): nothing to compensate")
    return s.t[a:b], z, rate, s.key.label()


#: The table stops at T/10: beyond it the overlapping Allan estimate rests on fewer than ten clusters.
MAX_TAU_FRACTION = 0.1

#: A method "helped" when it brought the ADEV at tau0 below this fraction of the raw ADEV.
HELPED_RATIO = 0.9


def display_unit(axis: str) -> tuple[float, str]:
    """(factor, unit) from SI to the table's and plot's unit: deg/s for gyro axes, m/s^2 for accelerometers."""
    return (180.0 / np.pi, "deg/s") if axis in GYRO_AXES else (1.0, "m/s^2")


def max_tau(n: int, rate_hz: float) -> float:
    """The longest cluster time shown (table and plot) for ``n`` samples at ``rate_hz``: T/10."""
    return MAX_TAU_FRACTION * n / rate_hz + 1e-12


def table_taus(result) -> list[int]:
    """Indices of the taus shown: tau0, about 1 s and about 100 s, none beyond T/10 of the record."""
    tau = result.raw_tau
    n = len(next(iter(result.methods.values())).x)
    ok = np.flatnonzero(tau <= max_tau(n, result.rate_hz))
    if ok.size == 0:
        return [0]
    return sorted({int(ok[np.argmin(np.abs(np.log(tau[ok]) - np.log(v)))]) for v in (tau[0], 1.0, 100.0)})


def format_table(result, axis: str, label: str) -> str:
    tau = result.raw_tau
    scale, unit = display_unit(axis)
    p = result.params
    picks = table_taus(result)
    lines = [f"{label} {axis}: {len(next(iter(result.methods.values())).x)} samples at {result.rate_hz:g} Hz; "
             f"ARIMA(1,1,1) fit ({p.split}): phi={p.phi:.4f} theta={p.theta:.4f} "
             f"delta1={p.delta1 * p.scale * scale:.3g} {unit} sqrt(R)={np.sqrt(p.R) * p.scale * scale:.3g} {unit}"]
    head = f"{'method':<20}" + "".join(f"{'ADEV ratio @' + format(tau[i], '.3g') + ' s':>20}" for i in picks)
    lines.append(head + f"{'samples/s':>12}{'factor ok':>11}")
    lines.append(f"{'raw ADEV (' + unit + ')':<20}" + "".join(f"{result.raw_adev[i] * scale:>20.4g}" for i in picks))
    for m in result.methods.values():
        ratio = m.adev / result.raw_adev
        lines.append(f"{m.label:<20}" + "".join(f"{ratio[i]:>20.3f}" for i in picks)
                     + f"{m.samples_per_s:>12.0f}{'yes' if m.factor_valid else 'NO':>11}")
    return "\n".join(lines)


def nothing_helped(result) -> str | None:
    """A warning when no method brought the ADEV at tau0 below ``HELPED_RATIO`` x raw, else None."""
    ratios = {m.label: float(m.adev[0] / result.raw_adev[0]) for m in result.methods.values()}
    if not ratios or min(ratios.values()) < HELPED_RATIO:
        return None
    best = min(ratios, key=ratios.get)
    return (f"no method brought the ADEV at tau0 ({result.raw_tau[0]:.3g} s) below {HELPED_RATIO:g}x raw (best: "
            f"{best} {ratios[best]:.3f}x): little white noise found to remove (motion, or noise the model "
            f"does not describe)")


def run(args) -> int:
    from companion.cli.output import check_output_path, check_plot_path
    from companion.sources import load

    for opt, path in (("--json", args.json), ("--out", args.out)):
        if path:
            check_output_path(path, opt)
    if args.plot:
        check_plot_path(args.plot)
    axis = args.axis.strip().lower()
    if axis not in AXES:
        raise CompanionError(f"unknown --axis {args.axis!r}; expected one of {', '.join(AXES)}")
    methods = parse_methods(args.method)
    from companion.cli.source_options import warn_ignored_options

    warn_ignored_options(args, [args.source], "compensate")
    res = load(args.source, args.config, duration=args.duration)
    t, z, rate, label = select_series(res, axis, args.stream, args.max_samples)
    progress = Progress("compensate", enabled=not args.quiet and z.shape[0] > 50_000)
    from companion.compensation.pipeline import compensate

    try:
        result = compensate(z, rate, methods=methods, progress=progress, split=args.split)
    finally:
        progress.close()
    print(format_table(result, axis, label))
    warning = nothing_helped(result)
    if warning:
        print(f"companion: warning: {warning}", file=sys.stderr)
    bad = [m.name for m in result.methods.values() if not m.factor_valid]
    if args.json:
        report = result.to_json(axis)
        report["stream"] = label
        write_text(args.json, to_json(report) + "\n", "JSON")
        print(f"wrote {args.json}")  # every file written is named, as analyze, gap and simulate do
    if args.out:
        cols = [t, z] + [m.x for m in result.methods.values()]
        header = ",".join(["time_s", f"{axis}_raw"] + [f"{axis}_{name}" for name in result.methods])
        try:
            np.savetxt(args.out, np.column_stack(cols), delimiter=",", header=header, comments="", fmt="%.9g")
        except OSError as exc:
            raise CompanionError(f"{args.out}: cannot write CSV ({exc.strerror or exc})") from None
        print(f"wrote {args.out}")
    if args.plot:
        from companion.plots.compensation_plot import plot_compensation

        scale, unit = display_unit(axis)
        plot_compensation(result, t, z, args.plot, title=f"{label} {axis}", unit_scale=scale, unit=unit,
                          max_tau=max_tau(z.shape[0], rate))
        print(f"wrote {args.plot}")
    if bad:
        print(f"companion: warning: covariance factor lost validity in {', '.join(bad)}", file=sys.stderr)
        return 1
    return 0
