"""``companion simulate``: synthesise IMU data from a noise-model YAML and write a tlog or a CSV."""

from __future__ import annotations

import argparse
import math

from companion.errors import CompanionError
from companion.sim.synth import imu_arrays

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

--vehicle: a whole vehicle instead of one IMU's noise (companion.sim.vehicle): 1-3 IMUs (--imus; IMU0 as
RAW_IMU, IMU1 as SCALED_IMU2, IMU2 as SCALED_IMU3, ArduPilot units) on one rigid body with per-IMU
scale-factor, misalignment and bias differences, a flight (--arm-at/--disarm-at: HEARTBEAT armed,
manoeuvres, vibration), handling by hand (--handle-at), a warm-up drift and one gyro fault (--fault),
written to a .tlog only. The options are those of `companion sim-autopilot`; times in s since the start.
"""

EPILOG = """\
examples:
  companion simulate companion/examples/sample_model.yaml --duration 1200 --out tlogs/sample.tlog --seed 1
  companion simulate model.yaml --duration 7200 --out sim.csv.gz --seed 3
  companion simulate model.yaml --duration 600 --out hr.tlog --message HIGHRES_IMU
  two IMUs, a flight, IMU1's gyro X frozen in flight; then replay it through the health monitor:
  companion simulate model.yaml --duration 2400 --out stuck.tlog --vehicle --imus 2 --arm-at 1200 \\
      --disarm-at 2000 --fault stuck --fault-at 1500 --fault-imu 1
  companion run --source stuck.tlog --baseline-s 300
"""

#: IMU messages a noise-only tlog can carry
MESSAGES = ("RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3", "HIGHRES_IMU")


def register(subparsers) -> None:
    p = subparsers.add_parser("simulate", help="synthesise IMU noise from a model YAML into a .tlog or .csv",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", nargs="?", help="noise model YAML (with --vehicle --preset: optional, the preset's model)")
    p.add_argument("--duration", type=float, required=True, metavar="S", help="seconds to synthesise")
    p.add_argument("--out", required=True, metavar="FILE", help="output .tlog, .csv or .csv.gz")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--message", default="RAW_IMU", choices=MESSAGES, help="IMU message of a tlog (default RAW_IMU)")
    p.add_argument("--sysid", type=int, default=1, help="MAVLink system id of a tlog (default 1)")
    p.add_argument("--vehicle", action="store_true", help="simulate a vehicle with 1-3 IMUs, flights, handling and a fault (below)")
    from companion.cli.vehicle_options import add_fault_options, add_vehicle_options

    add_vehicle_options(p)
    add_fault_options(p)
    p.set_defaults(func=run)


#: the --vehicle options and their values when not given: any other value needs --vehicle
VEHICLE_ONLY = {"imus": None, "preset": None, "arm_at": None, "disarm_at": None, "arm_s": None, "handle_at": None, "warmup_deg_s": 0.0,
                "fault": None, "fault_at": None, "fault_size": None}


def run_vehicle(args, model) -> int:
    """``--vehicle``: companion.sim.vehicle into a tlog (RAW_IMU / SCALED_IMU2 / SCALED_IMU3 + HEARTBEAT)."""
    from companion.cli.vehicle_options import build_simulator
    from companion.mavlink.vehicle_tlog import write_tlog
    from companion.sim.vehicle import IMU_MESSAGES

    if not args.out.lower().endswith(".tlog"):
        raise CompanionError(f"--out {args.out}: --vehicle writes a .tlog (one IMU message type per IMU)")
    if args.message != "RAW_IMU":
        raise CompanionError("--message does not apply to --vehicle (IMU0 RAW_IMU, IMU1 SCALED_IMU2, IMU2 SCALED_IMU3)")
    sim = build_simulator(args, model)
    try:
        counts = write_tlog(args.out, sim, args.duration, sysid=args.sysid)
    except OSError as exc:
        raise CompanionError(f"cannot write {args.out}: {exc.strerror or exc}") from None
    what = [f"{counts['imu_messages'] // sim.imus} {IMU_MESSAGES[i]}" for i in range(sim.imus)]
    extra = [f"fault {sim.fault.describe()}"] if sim.fault is not None else []
    extra += [f"flight {f.arm_at:g}-{f.disarm_at:g} s" for f in sim.schedule.flights]
    print(f"wrote {args.out}: {' + '.join(what)} and {counts['heartbeats']} HEARTBEAT messages, "
          f"{args.duration:g} s at {sim.rate_hz:g} Hz" + "".join(f"; {e}" for e in extra))
    return 0


#: most samples per IMU written in one run (about 1.2 GB of arrays per IMU)
MAX_SAMPLES = 50_000_000


def _model(args):
    """The noise model: MODEL.yaml, else the --preset's."""
    from companion.sim.model import load_model

    if args.model is None and not (args.vehicle and args.preset):
        raise CompanionError("give a noise model MODEL.yaml (or --vehicle --preset NAME)")
    if args.model is not None:
        return load_model(args.model)
    from companion.sim.preset import load_preset

    return load_preset(args.preset)["model"]


def _check_noise_run(args, model, n: int) -> None:
    """One error line for a noise-only run that cannot be written as asked (checked before the work)."""
    used = [k for k, v in VEHICLE_ONLY.items() if getattr(args, k) != v]
    if used:
        raise CompanionError(f"--{used[0].replace('_', '-')} needs --vehicle")
    if n < 2:
        raise CompanionError(f"--duration {args.duration} s at {model.rate_hz} Hz gives fewer than 2 samples")
    if n > MAX_SAMPLES:
        raise CompanionError(f"{n} samples is too many (limit 5e7); shorten --duration")
    from companion.sim.synth import check_model_rate

    try:
        check_model_rate(model)  # a sinusoid above Nyquist, an impossible f0: refused before the work
    except ValueError as exc:
        raise CompanionError(f"{args.model}: {exc}") from None
    low = args.out.lower()
    if not (low.endswith(".tlog") or low.endswith(".csv") or low.endswith(".csv.gz")):
        raise CompanionError(f"--out {args.out}: expected a .tlog, .csv or .csv.gz file name")
    from companion.cli.output import check_output_path

    check_output_path(args.out, "--out")


def run(args) -> int:
    if not 1 <= args.sysid <= 255:
        raise CompanionError(f"--sysid must be 1-255 (the MAVLink system id of the tlog), got {args.sysid}")
    if args.seed < 0:
        raise CompanionError(f"--seed must be >= 0, got {args.seed}")
    model = _model(args)
    if not (args.duration > 0 and math.isfinite(args.duration)):
        raise CompanionError("--duration must be a positive number of seconds")
    n = int(round(args.duration * model.rate_hz))
    if args.vehicle:
        if n > MAX_SAMPLES:
            raise CompanionError(f"{n} samples per IMU is too many (limit 5e7); shorten --duration")
        return run_vehicle(args, model)
    _check_noise_run(args, model, n)
    out = args.out
    try:
        t, gyro, accel = imu_arrays(model, args.duration, args.seed)
    except ValueError as exc:
        raise CompanionError(f"{args.model}: {exc}") from None
    try:
        if out.lower().endswith(".tlog"):
            from companion.mavlink.tlog_writer import write_imu_tlog

            count = write_imu_tlog(out, t, gyro, accel, message=args.message, sysid=args.sysid)
            print(f"wrote {out}: {count} {args.message} messages, {args.duration:g} s at {model.rate_hz:g} Hz")
        else:
            from companion.sources.csvfile import write_csv

            write_csv(out, t, gyro, accel)
            print(f"wrote {out}: {n} samples, {args.duration:g} s at {model.rate_hz:g} Hz")
    except OSError as exc:
        raise CompanionError(f"cannot write {out}: {exc.strerror or exc}") from None
    return 0
