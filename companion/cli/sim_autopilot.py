"""``companion sim-autopilot``: a simulated ArduPilot vehicle (1-3 IMUs, flights, handling, faults) on a MAVLink link
(SITL loopback for `companion run`); the vehicle itself is :mod:`companion.sim.vehicle`."""

from __future__ import annotations

import argparse
import os
import signal
import sys

from companion.cli.vehicle_options import FAULT_HELP, add_fault_options, add_vehicle_options, build_simulator
from companion.errors import CompanionError

DESCRIPTION = """\
Play an ArduPilot vehicle on a MAVLink link for loopback tests of `companion run`: HEARTBEAT once per
simulated second (armed bit while a flight is armed) and the IMUs of companion.sim.vehicle in ArduPilot
units: IMU0 as RAW_IMU, IMU1 as SCALED_IMU2, IMU2 as SCALED_IMU3 (--imus 1..3), gyro int16 mrad/s and
accel int16 mG, rounded to the nearest LSB (the 1 mrad/s rounding adds white noise of variance LSB^2/12
per sample, i.e. N_q = 1e-3/sqrt(12 rate) rad/s/sqrt(Hz): choose a model noise well above it or add it
to your truth). It honours MAV_CMD_SET_MESSAGE_INTERVAL (COMMAND_ACK; the rate of all IMUs changes) and
REQUEST_DATA_STREAM, and prints what comes back (STATUSTEXT as it arrives, the last NAMED_VALUE_FLOAT
values at the end).

Time is simulated: --speedup X sends X simulated seconds per wall second, message timestamps in simulated
time since boot (the first sample at 1 s). Every time option (--arm-at, --handle-at, --fault-at, ...) is
in seconds since the simulation start. --flow-control (a receiver on this machine, Linux): simulated time
also waits for the receiver: no more IMU messages are sent while more than a quarter of a socket receive
buffer waits unread at the receiving UDP port (and every --flow-port), as the kernel's /proc/net/udp shows;
with a large --speedup the link then runs as fast as the receiver reads, with no loss from overrunning it.

The vehicle: all IMUs see the same body rotation and vibration, each through its own scale-factor error
(--scale-spread) and misalignment (--misalign-deg), with its own bias and its own model noise. A flight
(--arm-at S --disarm-at S): armed on the ground, take-off, manoeuvres with body rates up to about
--max-rate, vibration, landing, disarm. Handling (--handle-at S ...): the disarmed vehicle picked up and
turned by hand for --handle-s seconds and put down in another attitude. --warmup-deg-s: a cold-start bias
drift (exponential, --warmup-tau-s).

""" + FAULT_HELP + """\
A noise degradation is also available (--degrade-at S: term --degrade-term of axis --degrade-axis multiplied
by --degrade-factor by adding an independent component of the same kind scaled by sqrt(F^2 - 1)).
"""

EPILOG = """\
examples:
  companion sim-autopilot --model gyro.yaml --connect udpout:127.0.0.1:14551
  companion sim-autopilot --model gyro.yaml --connect udpout:127.0.0.1:14551 --speedup 30 --duration 900 \\
      --degrade-at 400 --degrade-factor 2 --degrade-axis gx --record replies.jsonl
  two IMUs, a flight from 300 to 900 s, IMU1's gyro X frozen in flight at 600 s:
  companion sim-autopilot --model gyro.yaml --connect udpout:127.0.0.1:14551 --speedup 10 --imus 2 \\
      --arm-at 300 --disarm-at 900 --fault stuck --fault-at 600 --fault-imu 1 --fault-axis gx
  a +1 deg/s bias jump on IMU0 gyro Z while disarmed, handled by hand at 200 s, warm-up drift:
  companion sim-autopilot --model gyro.yaml --connect udpout:127.0.0.1:14551 --handle-at 200 \\
      --warmup-deg-s 0.1 --fault bias --fault-at 400 --fault-size 0.01745 --fault-axis gz

model file (SI units, see companion simulate):
  rate_hz: 100
  axes:
    gx: [{effect: white_noise, N: 3.0e-3}]
    gy: [{effect: white_noise, N: 3.0e-3}, {effect: bias_instability, B: 5.0e-5}]
"""

def register(subparsers) -> None:
    p = subparsers.add_parser("sim-autopilot", help="simulated ArduPilot vehicle with 1-3 IMUs, flights and faults (SITL loopback)",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", metavar="MODEL.yaml", help="noise model (companion.sim.model format; optional with --preset)")
    p.add_argument("--connect", required=True, metavar="CONN", help="where to send, e.g. udpout:127.0.0.1:14551")
    p.add_argument("--rate", type=float, metavar="HZ", help="IMU message rate before any request (default: the model's rate_hz)")
    p.add_argument("--speedup", type=float, default=1.0, metavar="X", help="simulated seconds per wall second (default 1)")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S simulated seconds (default: until Ctrl-C)")
    p.add_argument("--flow-control", action="store_true", help="loopback (Linux): send only while the receiver's UDP "
                   "queue is short (at most --speedup X); simulated time waits for a slow receiver")
    p.add_argument("--flow-port", type=int, action="append", default=[], metavar="PORT",
                   help="with --flow-control: also wait on this local UDP port's queue (a relay's next hop; repeatable)")
    p.add_argument("--wall-limit", type=float, metavar="S", help="stop after S wall-clock seconds in any case")
    p.add_argument("--sysid", type=int, default=1, help="system id of the simulated vehicle (default 1)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the simulator (default 0)")
    p.add_argument("--wait-request", action="store_true", help="idle (HEARTBEAT once a wall second) until asked for IMU data "
                   "(SET_MESSAGE_INTERVAL / REQUEST_DATA_STREAM); simulated time starts then")
    p.add_argument("--refuse-interval", action="store_true", help="answer SET_MESSAGE_INTERVAL with DENIED (tests the fallback)")
    p.add_argument("--record", metavar="FILE", help="write every received NAMED_VALUE_FLOAT/STATUSTEXT as JSON lines")
    p.add_argument("--quiet", action="store_true", help="print only STATUSTEXT and the final values")
    p.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing with this 32-byte key, like an "
                   "ArduPilot with signing set up: signs what it sends, ignores unsigned or wrongly signed frames")
    add_vehicle_options(p)
    add_fault_options(p, degrade=True)
    p.set_defaults(func=run)


def _flow_ports(args) -> list[int]:
    """The local UDP ports whose queues pace the simulation: --connect udpout:HOST:PORT's and every --flow-port."""
    ports = list(args.flow_port)
    kind, _, rest = args.connect.partition(":")
    if kind in ("udpout", "udp") and rest.rpartition(":")[2].isdigit():
        ports.append(int(rest.rpartition(":")[2]))
    if not ports:
        raise CompanionError("--flow-control needs --connect udpout:HOST:PORT or --flow-port PORT")
    return ports


def run(args) -> int:
    from companion.mavlink.autopilot_sim import SimAutopilot, SimOptions, describe
    from companion.sim.model import load_model
    from companion.sources.connection import open_connection

    if not args.speedup > 0:
        raise CompanionError("--speedup must be > 0")
    for name in ("duration", "wall_limit", "arm_s"):
        v = getattr(args, name)
        if v is not None and not v > 0:
            raise CompanionError(f"--{name.replace('_', '-')} must be > 0")
    if not 1 <= args.sysid <= 255:
        raise CompanionError(f"--sysid must be 1-255 (the MAVLink system id it sends as), got {args.sysid}")
    bad_ports = [p for p in args.flow_port if not 1 <= p <= 65535]
    if bad_ports:
        raise CompanionError(f"--flow-port {bad_ports[0]}: a UDP port is 1-65535")
    if args.record:
        from companion.cli.output import check_output_path

        check_output_path(args.record, "--record")
    if args.model is None and args.preset is None:
        raise CompanionError("give --model MODEL.yaml or --preset NAME")
    model = load_model(args.model) if args.model is not None else None
    if args.rate is not None and not args.rate > 0:
        raise CompanionError("--rate must be > 0")
    sim = build_simulator(args, model, args.rate)
    opts = SimOptions(speedup=args.speedup, duration=args.duration, wall_limit=args.wall_limit,
                      wait_request=args.wait_request, refuse_interval=args.refuse_interval, quiet=args.quiet,
                      flow_ports=tuple(_flow_ports(args)) if args.flow_control else None)
    os.environ.setdefault("MAVLINK20", "1")  # speak MAVLink 2 like ArduPilot (pymavlink picks the dialect from it)
    conn = open_connection(args.connect, source_system=args.sysid, source_component=1)
    if args.signing_key:  # signing, as on an autopilot after SETUP_SIGNING
        from companion.mavlink.signing import load_signing_key, setup_signing

        setup_signing(conn, load_signing_key(args.signing_key))
    if not args.quiet:
        print(describe(sim), flush=True)
    try:
        record = open(args.record, "w") if args.record else None
    except OSError as exc:
        conn.close()
        raise CompanionError(f"--record {args.record}: cannot write ({exc.strerror or exc})") from None
    stop = {"flag": False}
    old = {s: signal.signal(s, lambda *a: stop.__setitem__("flag", True)) for s in (signal.SIGINT, signal.SIGTERM)}
    autopilot = SimAutopilot(sim, conn, opts, lambda line: print(line, flush=True), record)
    try:
        autopilot.run(lambda: stop["flag"])
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if record is not None:
            record.close()
        conn.close()
    for line in autopilot.summary_lines():
        print(line)
    sys.stdout.flush()
    return 0
