"""``companion run``: the live loop on the companion computer (or a .tlog replayed through the same pipeline)."""

from __future__ import annotations

import argparse
import signal
import sys

from companion.cli.run_web import WebRun, add_arguments
from companion.errors import CompanionError

DESCRIPTION = """\
Watch the gyros of a vehicle for hours: per IMU and axis, online Allan-variance noise coefficients
(N angle random walk, B bias instability, K rate random walk) learned while the vehicle is still
(disarmed and not moving), sent back on the link as NAMED_VALUE_FLOAT (IMU0GX_N ... in datasheet
units) with a health flag IMU0G_HLTH (0 healthy, 1 degrading or faulty, 2 learning, 3 stale), a fault
code IMU0G_FLT and a STATUSTEXT on every change, e.g. "IMU0 gyro X degrading: N 2.1x baseline".

Every block of samples is also checked for the ways a gyro fails: stuck (frozen), noise jump, bias
jump or drift, spikes, saturation, rate drop, and (with two or three IMUs, also in flight) an IMU
that disagrees with the others, e.g. "IMU0 gyro X stuck" (CRITICAL), "IMU1 gyro X disagrees with
IMU0/IMU2". The run summary lists the active faults.

The baseline (what healthy looks like) is learned from the first --baseline-s seconds of still data or
loaded from a report of `companion analyze` (--baseline FILE). It is kept, with the estimator state,
in the --state file (saved atomically every minute and on Ctrl-C / SIGTERM), so it survives restarts.

A log file (.tlog, ArduPilot DataFlash .bin, PX4 .ulg, .csv; each optionally .gz) is replayed through the
very same pipeline as fast as possible (message time only: the estimates do not depend on the replay
speed; a log's armed state becomes heartbeats) and a summary is printed. See docs/run.md.
"""

EPILOG = """\
examples:
  companion run --source udpin:0.0.0.0:14550                   listen for a GCS/router forward
  companion run --source /dev/ttyAMA0 --baud 921600 --state /var/lib/companion/state.json
  companion run --source tcp:127.0.0.1:5760 --baseline healthy_analyze.json
  companion run --source flight.tlog --baseline-s 300          replay a log, print the summary
  companion run --source udpin:127.0.0.1:14551 --duration 60 --out-tlog session.tlog
  companion run --source udpin:0.0.0.0:14550 --gcs udpout:192.168.1.10:14551   reports also to a GCS
  companion run --source udpin:0.0.0.0:14550 --web 0.0.0.0:8080     a live page for a browser on the network
  companion run --source flight.tlog --report alarms.html             every alarm with its evidence (docs/reports.md)

watch it in MAVProxy:   graph NAMED_VALUE_FLOAT[IMU0GX_N].value
            in Mission Planner: Ctrl-F > Tuning > MAV_IMU0GX_N
"""

#: Printed on stderr (also with --quiet) once a live link is open and SIGINT/SIGTERM are handled:
#: supervisors and tests wait for it instead of a fixed time.
READY_LINE = "companion run: listening on"



def register(subparsers) -> None:
    p = subparsers.add_parser("run", help="live gyro health on the companion computer (NAMED_VALUE_FLOAT reports)",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--source", required=True, metavar="CONN",
                   help="udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, tcpin:, a serial device, or a log to replay "
                        "(.tlog, DataFlash .bin, PX4 .ulg, .csv; each optionally .gz)")
    p.add_argument("--baud", type=int, default=None, help="serial baud rate (default 115200)")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (sections run:, estimator:, streams:)")
    p.add_argument("--time-unit", choices=("s", "ms", "us"), default=None, dest="time_unit",
                   help="unit of a CSV's time column (default s; a column whose median step is 1 or more, or coarser than "
                        "the sample rate, is refused with the unit to pass)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--baseline-s", type=float, metavar="S", help="learn the baseline from the first S s of still data (default 600)")
    g.add_argument("--baseline", metavar="FILE", help="baseline from a `companion analyze` JSON/YAML report or a saved baseline")
    p.add_argument("--baseline-force", action="store_true",
                   help="use --baseline even when it was measured on another stream (message, rate, sensor LSB, "
                        "units); without it a mismatch is an error")
    st = p.add_mutually_exclusive_group()  # both given: which one was meant cannot be guessed
    st.add_argument("--state", metavar="FILE", help="state file (default: run.state_file, else "
                    "$XDG_STATE_HOME/companion/run_state.json on a live link, none for a replay)")
    st.add_argument("--no-state", action="store_true", help="do not read or write a state file")
    p.add_argument("--relearn", action="store_true", help="ignore the baseline kept in the state file and learn a new one")
    p.add_argument("--sysid", type=int, help="system id of the vehicle (default: the first one sending IMU data)")
    p.add_argument("--rate", type=float, metavar="HZ", help="IMU message rate to ask the autopilot for (default 100)")
    p.add_argument("--report-period", type=float, metavar="S", help="seconds of message time between two reports of a value (default 1)")
    p.add_argument("--gcs", action="append", default=[], metavar="CONN",
                   help="also send the reports (NAMED_VALUE_FLOAT, STATUSTEXT) and our HEARTBEAT to this ground-station "
                        "link, e.g. udpout:GCS_IP:14550 (repeatable; same frames and signing as the main link): for "
                        "routers such as MAVProxy that do not forward what their --out peer sends to other outputs")
    p.add_argument("--out-tlog", metavar="FILE", help="record what was received and sent (or, for a replay, the reports) to a tlog")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S wall-clock seconds (default: run until Ctrl-C/SIGTERM)")
    p.add_argument("--quiet", action="store_true", help="only warnings and the final summary")
    add_arguments(p)
    # MAVLink 2 signing (companion/mavlink/signing.py, docs/run.md#signed-links)
    p.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing with this 32-byte key (raw or 64 hex "
                   "digits; the autopilot's key, set with SETUP_SIGNING): sign what we send, accept only "
                   "correctly signed frames, count the rejected ones")
    p.add_argument("--accept-unsigned", action="store_true",
                   help="with --signing-key: also accept unsigned frames (wrongly signed ones are still refused)")
    p.set_defaults(func=run)


def print_summary(pipeline, out=None) -> None:
    from companion.service.run_session import summary_lines

    for line in summary_lines(pipeline):
        print(line, file=out or sys.stdout)


def run(args) -> int:
    # signal handling first (a SIGTERM during start-up still saves and exits 0), then the imports
    stop = {"flag": False}

    def on_signal(signum, frame):
        stop["flag"] = True

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _run(args, stop)
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def _run(args, stop) -> int:
    from companion.service import run_session
    from companion.service.run_options import RunHooks, build_options

    def log(line):
        if not args.quiet:
            print(f"companion run: {line}", file=sys.stderr, flush=True)

    def warn(line):
        print(f"companion run: warning: {line}", file=sys.stderr, flush=True)

    def ready(source):  # printed even with --quiet: the socket/port is open and signals are handled
        print(f"{READY_LINE} {source}", file=sys.stderr, flush=True)

    opts = build_options(args, warn, lambda state, run_keys: _check_outputs(args, run_keys, state))
    web = WebRun(args)  # --report checked, --web bound and serving, before the work
    hooks = RunHooks(log=log, warn=warn, stop=lambda: stop["flag"], ready=ready,
                     echo=None if args.quiet else print, started=web.started)
    try:
        result = run_session.run(opts, hooks)
        print_summary(result.pipeline)
        if result.link is not None:  # link health (loss, reordering, late, rejected frames) per source
            for line in result.link.stats.summary_lines():
                print(line)
        web.finish(result.pipeline, opts.source, lambda: stop["flag"], opts.is_replay)
    finally:
        web.close()
    from companion.service.outcome import run_status

    code, reason = run_status(result.pipeline.summary())
    if code:  # the exit status says it (README "Exit status"); the line says why
        print(f"companion run: {reason} (exit status {code})", file=sys.stderr)
    return code


def _check_outputs(args, extra, state_path) -> None:
    """--out-tlog and a state file named by the user (--state, run.state_file) follow the CLI's one rule
    (companion.cli.output.check_output_path: existing directory, writable, refused otherwise); only the
    default state location ($XDG_STATE_HOME/companion) is created when missing."""
    from companion.cli.output import check_output_path

    if args.out_tlog:
        check_output_path(args.out_tlog, "--out-tlog")
    if state_path is None:
        return
    if args.state or extra.get("state_file"):
        check_output_path(state_path, "--state" if args.state else "run.state_file")
    else:
        try:
            state_path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CompanionError(f"default state file {state_path}: cannot create its directory "
                                 f"({exc.strerror or exc}); give --state FILE or --no-state") from None
        check_output_path(state_path, "state file")
