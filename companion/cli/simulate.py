"""``companion simulate``: synthesise IMU data from a noise-model YAML and write a tlog or a CSV."""

from __future__ import annotations

import argparse
import gzip
import math

import numpy as np

from companion.errors import CompanionError
from companion.samples import ACCEL_AXES, GYRO_AXES

DESCRIPTION = """\
Synthesise every noise term of MODEL.yaml (white noise, angle quantization, flicker bias instability by
spectral shaping, rate random walk, ramp, exact Gauss-Markov, sinusoid; see docs/analysis.md) for the
axes it lists, at its rate_hz, and write a telemetry log (--out x.tlog: HEARTBEAT once a second and one
IMU message per sample with proper timestamps; RAW_IMU/SCALED_IMU round to int16 mrad/s and mG like
ArduPilot, HIGHRES_IMU keeps float32 SI) or a CSV (--out x.csv[.gz]: time_s,gx,gy,gz,ax,ay,az in rad/s
and m/s^2). Axes the model does not list are written as 0 (accel: az = -9.80665 m/s^2 when the model
has no accel axis at all, a vehicle at rest).

Model YAML (SI units):
  rate_hz: 100.0
  axes:
    gx:
      - {effect: white_noise, N: 1.0e-3}          # rad/s/sqrt(Hz)
      - {effect: bias_instability, B: 2.0e-5}     # rad/s
      - {effect: gauss_markov, sigma: 1.0e-4, tau_c: 20.0}
"""

EPILOG = """\
examples:
  companion simulate tlogs/sample_model.yaml --duration 1200 --out tlogs/sample.tlog --seed 1
  companion simulate model.yaml --duration 7200 --out sim.csv.gz --seed 3
  companion simulate model.yaml --duration 600 --out hr.tlog --message HIGHRES_IMU
"""

MESSAGES = ("RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3", "HIGHRES_IMU")


def register(subparsers) -> None:
    p = subparsers.add_parser("simulate", help="synthesise IMU noise from a model YAML into a .tlog or .csv",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", help="noise model YAML")
    p.add_argument("--duration", type=float, required=True, metavar="S", help="seconds to synthesise")
    p.add_argument("--out", required=True, metavar="FILE", help="output .tlog, .csv or .csv.gz")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--message", default="RAW_IMU", choices=MESSAGES, help="IMU message of a tlog (default RAW_IMU)")
    p.add_argument("--sysid", type=int, default=1, help="MAVLink system id of a tlog (default 1)")
    p.set_defaults(func=run)


def synthesize(model, duration_s: float, seed: int):
    """(t, gyro (n,3), accel (n,3)) SI arrays for a model."""
    from companion.sim.synth import simulate_model

    data = simulate_model(model, duration_s, seed)
    n = int(round(duration_s * model.rate_hz))
    t = np.arange(n) / model.rate_hz
    gyro = np.column_stack([data.get(a, np.zeros(n)) for a in GYRO_AXES])
    accel = np.column_stack([data.get(a, np.zeros(n)) for a in ACCEL_AXES])
    if not any(a in model.axes for a in ACCEL_AXES):
        accel[:, 2] = -9.80665
    return t, gyro, accel


def write_csv(path: str, t, gyro, accel) -> None:
    opener = gzip.open if path.lower().endswith(".gz") else open
    arr = np.column_stack([t, gyro, accel])
    with opener(path, "wt") as f:
        f.write("time_s,gx,gy,gz,ax,ay,az\n")
        np.savetxt(f, arr, fmt=["%.6f"] + ["%.9e"] * 6, delimiter=",")


def run(args) -> int:
    from companion.sim.model import load_model

    model = load_model(args.model)
    if not (args.duration > 0 and math.isfinite(args.duration)):
        raise CompanionError("--duration must be a positive number of seconds")
    n = int(round(args.duration * model.rate_hz))
    if n < 2:
        raise CompanionError(f"--duration {args.duration} s at {model.rate_hz} Hz gives fewer than 2 samples")
    if n > 50_000_000:
        raise CompanionError(f"{n} samples is too many (limit 5e7); shorten --duration")
    from companion.sim.synth import check_model_rate

    try:
        check_model_rate(model)  # i14: a sinusoid above Nyquist, an impossible f0: refused before the work
    except ValueError as exc:
        raise CompanionError(f"{args.model}: {exc}") from None
    out = args.out
    low = out.lower()
    if not (low.endswith(".tlog") or low.endswith(".csv") or low.endswith(".csv.gz")):
        raise CompanionError(f"--out {out}: expected a .tlog, .csv or .csv.gz file name")
    from companion.cli.output import check_output_path

    check_output_path(out, "--out")
    try:
        t, gyro, accel = synthesize(model, args.duration, args.seed)
    except ValueError as exc:
        raise CompanionError(f"{args.model}: {exc}") from None
    try:
        if low.endswith(".tlog"):
            from companion.mavlink.tlog_writer import write_imu_tlog

            count = write_imu_tlog(out, t, gyro, accel, message=args.message, sysid=args.sysid)
            print(f"wrote {out}: {count} {args.message} messages, {args.duration:g} s at {model.rate_hz:g} Hz")
        else:
            write_csv(out, t, gyro, accel)
            print(f"wrote {out}: {n} samples, {args.duration:g} s at {model.rate_hz:g} Hz")
    except OSError as exc:
        raise CompanionError(f"cannot write {out}: {exc.strerror or exc}") from None
    return 0
