"""``companion`` command line: one console script with subcommands.

Each subcommand lives in its own module ``companion.cli.<name>`` that defines
``register(subparsers)`` (adds its parser and sets ``func``) and does its work in that function.
User errors raise :class:`companion.errors.CompanionError`: one line on stderr and a non-zero exit.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from companion import __version__
from companion.errors import CompanionError, Terminated

#: Subcommand modules in the order ``--help`` lists them.
COMMANDS = (
    "inspect",
    "analyze",
    "simulate",
    "gap",
    "compensate",
    "run",
    "sim_autopilot",
    "fleet",
    "example",
)

EPILOG = """\
typical use:
  companion inspect flight.tlog                 what IMU streams a log holds
  companion analyze flight.tlog --plot adev.png  Allan deviation, fitted noise terms, datasheet units
  companion run --source udpin:0.0.0.0:14550     live gyro health on the companion computer

Sources are pymavlink connection strings (udpin:HOST:PORT, udpout:, tcp:, tcpin:, a serial device
with --baud), .tlog files, ArduPilot DataFlash .bin logs, PX4 .ulg logs, or CSV files
(time_s,gx,gy,gz,ax,ay,az; gyro rad/s, accel m/s^2); each file optionally gzip-compressed (.gz).
"""


class Parser(argparse.ArgumentParser):
    """An argument parser that takes options by their full names only: argparse's prefix matching would read
    ``run --report r.html`` as ``--report-period r.html``, and a script abbreviating an option would change its
    meaning silently when a longer option is added. Subcommand parsers are made of this class too
    (``add_subparsers`` uses its parser's class)."""

    def __init__(self, *args, **kwargs):
        kwargs["allow_abbrev"] = False
        super().__init__(*args, **kwargs)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="companion",
        description="Gyro health from MAVLink IMU data: Allan-variance noise coefficients, online and offline.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"companion {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"companion.cli.{name}")
        except ModuleNotFoundError as exc:  # a subcommand not present in this build
            if exc.name != f"companion.cli.{name}":
                raise
            continue
        module.register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        rc = args.func(args)
    except CompanionError as exc:
        print(f"companion: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt as exc:
        if isinstance(exc, Terminated):
            print("companion: terminated (SIGTERM)", file=sys.stderr)
            return exc.exit_code
        print("companion: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0
    return int(rc or 0)
