"""``companion fleet simulate``: a synthetic fleet in which chosen IMUs degrade (:mod:`companion.fleet.synthetic_fleet`)."""

from __future__ import annotations

import argparse
import sys

from companion.errors import CompanionError

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



def register(sub) -> None:
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


def run_simulate(args) -> int:
    from companion.fleet.synthetic_fleet import (check_fleet_options, check_fleet_size, degrading_imus, fleet_bytes,
                                                 simulate_fleet)

    check_fleet_options(args.vehicles, args.flights, args.imus, args.degrading, args.rise, args.duration, args.rate,
                        args.seed, args.message, args.format)
    check_fleet_size(args.out_dir, fleet_bytes(args.vehicles, args.flights, args.imus, args.duration, args.rate,
                                               args.message, args.format))
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
    degrading = ", ".join(degrading_imus(truth)) or "none"
    print(f"wrote {len(truth['logs'])} logs to {args.out_dir} ({args.vehicles} vehicles x {args.flights} flights, "
          f"{args.imus} IMUs each); degrading ({args.param} x{args.rise:g}): {degrading}")
    return 0
