"""``companion inspect SOURCE``: what IMU streams a log (.tlog, .bin, .ulg), CSV file or live link holds."""

from __future__ import annotations

import argparse

import sys

from companion.errors import EXIT_FAULTS, NoUsableData

DESCRIPTION = """\
List the IMU streams of a source: per stream the MAVLink message, instance, sysid, compid, number of
samples, detected rate, duration, gaps, and whether it is an IMU at all (a SCALED_IMU2/3 with all accel
and gyro zero only carries a compass); plus the frame totals (valid frames, bad bytes, bad frames).
Sample times come from the messages' own timestamps; nothing is resampled or dropped silently
(duplicates, backward steps and reboots are counted, see docs/ingestion.md). Where the log carries them, the
autopilot's own IMU health follows, one line per IMU (error and clip counts, health flags, vibration; DataFlash
IMU/VIBE/ERR, ULog vehicle_imu_status/sensors_status_imu, tlog SYS_STATUS/VIBRATION; docs/health.md).

SOURCE is a .tlog file (armed state from the vehicle autopilot's HEARTBEATs), an ArduPilot DataFlash .bin
log (every IMU, batch-sampler bursts ISB_GYRO/ISB_ACCEL, parameters and armed state), a PX4 .ulg
(sensor_combined, sensor_gyro, sensor_gyro_fifo, vehicle_imu), a CSV file (header time_s,gx,gy,gz,ax,ay,az; rad/s, m/s^2) -- each optionally gzip-compressed (.gz) -- or a
pymavlink connection string (udpin:HOST:PORT, udpout:, udp:, tcp:, tcpin:, a serial device with --baud)
listened to for --duration seconds."""

EPILOG = """\
examples:
  companion inspect flight.tlog
  companion inspect flight.tlog --json streams.json
  companion inspect imu.csv.gz
  companion inspect 00000042.BIN                    # ArduPilot DataFlash: IMU[0..2], ISB_GYRO, INS_GYRO_FILTER, armed
  companion inspect log_3_2024-5-1.ulg              # PX4 ULog
  companion inspect udpin:0.0.0.0:14550 --duration 10
  companion inspect /dev/ttyACM0 --baud 921600 --duration 5
  companion inspect flight.tlog --config my.yaml     # per-stream gyro_scale/accel_scale (streams: section)

exit status: 0 when at least one IMU stream was found, 4 when a gyro is dead, 5 when no stream is an
IMU (the table is still printed), 2 on bad input (README "Exit status")."""

def register(subparsers) -> None:
    p = subparsers.add_parser("inspect", help="list the IMU streams of a log (.tlog, .bin, .ulg, .csv) or live link",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", metavar="SOURCE", help=".tlog, .bin, .ulg, .csv (each optionally .gz), or a connection string")
    p.add_argument("--json", metavar="OUT", help="also write {streams: [...], frames, bad_bytes, bad_frames} to OUT (and autopilot: "
                                            "the autopilot's own IMU health, where the log has it)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="seconds to listen on a live connection (required for links)")
    p.add_argument("--baud", type=int, default=None, help="serial baud rate (default 115200)")
    p.add_argument("--config", metavar="YAML", help="configuration file (its streams: section sets scales)")
    p.add_argument("--time-unit", choices=("s", "ms", "us"), default=None, dest="time_unit",
                   help="unit of a CSV's time column (default s; a column whose median step is 1 or more, or coarser than "
                        "the sample rate, is refused with the unit to pass)")
    p.set_defaults(func=run)


def run(args) -> int:
    from companion.cli.output import check_output_path
    from companion.cli.source_options import warn_ignored_options
    from companion.sources import load
    from companion.sources.listing import render, write_summary

    if args.json:
        check_output_path(args.json, "--json")
    warn_ignored_options(args, [args.source], "inspect")
    res = load(args.source, config=args.config, duration=args.duration, baud=args.baud, require_imu=False,
               time_unit=getattr(args, "time_unit", None))
    print(render(res), flush=True)
    if args.json:
        write_summary(args.json, res)
    if not res.imu_streams():
        raise NoUsableData(f"{res.source}: no IMU data" + (" (compass-only streams only)" if res.streams else ""))
    from companion.analysis.source import dead_gyros

    dead = dead_gyros(res.imu_streams())  # named in the notes above; the exit status lets a script gate on it
    if dead:
        print(f"companion inspect: gyro faults found: {len(dead)} dead gyro stream(s) (exit status {EXIT_FAULTS})",
              file=sys.stderr)
        return EXIT_FAULTS
    return 0
