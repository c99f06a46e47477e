"""``companion sim-autopilot``: a simulated ArduPilot vehicle (1-3 IMUs, flights, handling, faults) on a MAVLink link
(SITL loopback for `companion run`); the vehicle itself is :mod:`companion.sim.vehicle`."""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time

import numpy as np

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
The older noise degradation (--degrade-at S: term --degrade-term of axis --degrade-axis multiplied by
--degrade-factor by adding an independent component of the same kind scaled by sqrt(F^2 - 1)) still works.
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

MAV_TYPE_QUADROTOR = 2
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_STATE_STANDBY = 3
MAV_STATE_ACTIVE = 4
MAV_CMD_SET_MESSAGE_INTERVAL = 511
RAW_IMU_ID = 27
SCALED_IMU2_ID = 116
SCALED_IMU3_ID = 129
IMU_MSG_IDS = (RAW_IMU_ID, SCALED_IMU2_ID, SCALED_IMU3_ID)  # IMU0, IMU1, IMU2
G0 = 9.80665


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


def _imu_ints(blk, i):
    """IMU i of a block as int16 accel (mG) and gyro (mrad/s) rows, rounded to the nearest LSB."""
    a = np.clip(np.rint(blk.accel[i] / (G0 * 1e-3)), -32768, 32767).astype(int).tolist()
    g = np.clip(np.rint(blk.gyro[i] / 1e-3), -32768, 32767).astype(int).tolist()
    return a, g


def _send_block(conn, blk, sending, hb_times, hb_armed, counts, count_keys) -> None:
    """Send a block's IMU messages and HEARTBEATs as frames built at once, one datagram/write each."""
    from companion.mavlink.imu_frames import block_frames

    mav = conn.mav
    buf, starts, kind = block_frames(blk.t, blk.gyro, blk.accel, blk.temperature, sending, hb_times, hb_armed,
                                     mav.seq, mav.srcSystem, mav.srcComponent)
    write = mav.file.write
    bounds = starts.tolist()
    for j in range(len(bounds) - 1):
        write(buf[bounds[j]:bounds[j + 1]])
    total = len(bounds) - 1
    mav.seq = (mav.seq + total) % 256
    mav.total_packets_sent += total
    mav.total_bytes_sent += len(buf)
    for i, key in enumerate(count_keys[:len(sending)]):
        counts[key] += int(np.count_nonzero(kind == i))
    counts["heartbeat"] += len(hb_times)


def _describe(sim) -> str:
    names = ("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")[:sim.imus]
    parts = [f"{sim.imus} IMU(s) ({', '.join(names)}) at {sim.rate_hz:g} Hz"]
    for f in sim.schedule.flights:
        parts.append(f"flight {f.arm_at:g}-{f.disarm_at:g} s")
    for h in sim.schedule.handlings:
        parts.append(f"handling {h.at:g}-{h.end:g} s")
    if sim.fault is not None:
        parts.append("fault " + sim.fault.describe())
    return "sim-autopilot: " + "; ".join(parts)


def _udp_queue_bytes(ports) -> int | None:
    """Bytes queued unread at the local UDP sockets bound to ``ports`` (the largest over the ports; sockets
    sharing a port are summed), from /proc/net/udp; None where the kernel does not show them."""
    queued = {}
    for name in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            with open(name) as f:
                lines = f.read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            f = line.split()
            if len(f) > 4:
                port = int(f[1].rsplit(":", 1)[1], 16)
                if port in ports:
                    queued[port] = queued.get(port, 0) + int(f[4].split(":")[1], 16)
    return max(queued.values()) if queued else None


def _flow_ports(args) -> list[int]:
    """The local UDP ports whose queues pace the simulation: --connect udpout:HOST:PORT's and every --flow-port."""
    ports = list(args.flow_port)
    kind, _, rest = args.connect.partition(":")
    if kind in ("udpout", "udp") and rest.rpartition(":")[2].isdigit():
        ports.append(int(rest.rpartition(":")[2]))
    if not ports:
        raise CompanionError("--flow-control needs --connect udpout:HOST:PORT or --flow-port PORT")
    return ports


def _flow_limit() -> int:
    """Queued bytes above which sending waits: a quarter of the default socket receive buffer (kernel
    accounting per datagram includes its buffer overhead, so this is some tens of datagrams)."""
    try:
        with open("/proc/sys/net/core/rmem_default") as f:
            return max(int(f.read()) // 4, 16384)
    except (OSError, ValueError):
        return 49152


def run(args) -> int:
    from companion.sim.model import load_model
    from companion.sources.connection import open_connection

    if not args.speedup > 0:
        raise CompanionError("--speedup must be > 0")
    for name in ("duration", "wall_limit", "arm_s"):
        v = getattr(args, name)
        if v is not None and not v > 0:
            raise CompanionError(f"--{name.replace('_', '-')} must be > 0")
    if args.model is None and args.preset is None:
        raise CompanionError("give --model MODEL.yaml or --preset NAME")
    model = load_model(args.model) if args.model is not None else None
    if args.rate is not None and not args.rate > 0:
        raise CompanionError("--rate must be > 0")
    sim = build_simulator(args, model, args.rate)
    flow_ports = _flow_ports(args) if args.flow_control else None
    flow_limit = _flow_limit()
    os.environ.setdefault("MAVLINK20", "1")  # speak MAVLink 2 like ArduPilot (pymavlink picks the dialect from it)
    conn = open_connection(args.connect, source_system=args.sysid, source_component=1)
    if args.signing_key:  # signing, as on an autopilot after SETUP_SIGNING
        from companion.mavlink.signing import load_signing_key, setup_signing

        setup_signing(conn, load_signing_key(args.signing_key))
    out = sys.stdout
    if not args.quiet:
        print(_describe(sim), file=out, flush=True)
    record = open(args.record, "w") if args.record else None
    stop = {"flag": False}
    old = {s: signal.signal(s, lambda *a: stop.__setitem__("flag", True)) for s in (signal.SIGINT, signal.SIGTERM)}
    values: dict[str, float] = {}
    counts = {"raw_imu": 0, "scaled_imu2": 0, "scaled_imu3": 0, "heartbeat": 0, "named_value_float": 0,
              "statustext": 0, "commands": 0}
    sending = {mid: not args.wait_request for mid in IMU_MSG_IDS[:sim.imus]}
    wall_start = time.monotonic()
    wall0 = None if args.wait_request else wall_start  # simulated time runs from wall0 (the first request)
    next_idle_hb = wall_start
    next_hb = 1.0
    t_flow = 1.0  # --flow-control: simulated time sent so far
    mav = conn.mav
    # temperature in cdegC: the simulated IMU's (--preset) or a constant 42 C
    senders = (lambda ti, a, g, c: mav.raw_imu_send(int(round(ti * 1e6)), *a, *g, 0, 0, 0, 0, c),
               lambda ti, a, g, c: mav.scaled_imu2_send(int(round(ti * 1e3)), *a, *g, 0, 0, 0, c),
               lambda ti, a, g, c: mav.scaled_imu3_send(int(round(ti * 1e3)), *a, *g, 0, 0, 0, c))
    count_keys = ("raw_imu", "scaled_imu2", "scaled_imu3")
    # whole blocks packed with numpy (the same bytes as pymavlink's *_send); a signed or MAVLink 1 link
    # keeps pymavlink's per-message path
    dialect = sys.modules.get(type(mav).__module__)
    fast = getattr(dialect, "WIRE_PROTOCOL_VERSION", "") == "2.0" and not mav.signing.sign_outgoing

    def heartbeat(armed: bool) -> None:
        base_mode = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        mav.heartbeat_send(MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_ARDUPILOTMEGA, base_mode, 0,
                           MAV_STATE_ACTIVE if armed else MAV_STATE_STANDBY)
        counts["heartbeat"] += 1

    try:
        while not stop["flag"]:
            now = time.monotonic()
            if wall0 is None:  # --wait-request: idle, HEARTBEAT once a wall second, simulated time stands still
                t_sim = 1.0
                if now >= next_idle_hb:
                    heartbeat(False)
                    next_idle_hb += 1.0
            else:
                t_sim = 1.0 + (now - wall0) * args.speedup
                if flow_ports is not None:
                    # at most a burst that fits well in the receiver's buffer, and only when its queue is short
                    burst_s = 24.0 / (sim.rate_hz * max(1, sum(sending.values())))
                    queued = _udp_queue_bytes(flow_ports)
                    if queued is None:  # not observable (not Linux, not bound yet): --speedup alone paces
                        t_flow = max(t_flow, t_sim)
                    elif queued <= flow_limit:
                        t_flow = min(t_sim, t_flow + burst_s)
                    t_sim = t_flow
                if args.duration is not None:
                    t_sim = min(t_sim, 1.0 + args.duration)
                blk = sim.take_until(t_sim)
                hb_times = []
                while next_hb <= t_sim:
                    hb_times.append(next_hb)
                    next_hb += 1.0
                if fast:
                    _send_block(conn, blk, [sending[mid] for mid in IMU_MSG_IDS[:sim.imus]], hb_times,
                                [bool(sim.armed_at(th)) for th in hb_times], counts, count_keys)
                else:
                    t = blk.t.tolist()
                    ints = [_imu_ints(blk, i) for i in range(sim.imus)]
                    temps = [[4200] * blk.n if blk.temperature is None else
                             np.clip(np.rint(blk.temperature[i] * 100.0), -32768, 32767).astype(int).tolist()
                             for i in range(sim.imus)]
                    k = 0
                    for th in hb_times + [math.inf]:
                        while k < len(t) and t[k] < th:
                            for i, mid in enumerate(IMU_MSG_IDS[:sim.imus]):
                                if sending[mid]:
                                    senders[i](t[k], ints[i][0][k], ints[i][1][k], temps[i][k])
                                    counts[count_keys[i]] += 1
                            k += 1
                        if th != math.inf:
                            heartbeat(bool(sim.armed_at(th)))
            while True:
                msg = conn.recv_match(blocking=False)
                if msg is None:
                    break
                _on_reply(msg, args, sim, mav, values, counts, record, out, t_sim, sending)
            if wall0 is None and any(sending.values()):
                wall0 = time.monotonic()  # asked: the simulation starts now
            if args.duration is not None and t_sim >= 1.0 + args.duration:
                break
            if args.wall_limit is not None and now - wall_start >= args.wall_limit:
                break
            time.sleep(0.002 if flow_ports is not None else 0.005)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if record is not None:
            record.close()
        conn.close()
    sent = " + ".join(f"{counts[count_keys[i]]} {count_keys[i].upper()}" for i in range(sim.imus))
    print(f"sim-autopilot: sent {sent} and {counts['heartbeat']} HEARTBEAT "
          f"({sim.rate_hz:g} Hz at the end); received {counts['named_value_float']} NAMED_VALUE_FLOAT, "
          f"{counts['statustext']} STATUSTEXT, {counts['commands']} requests", file=out)
    for name in sorted(values):
        print(f"NAMED_VALUE_FLOAT {name} {values[name]:.6g}", file=out)
    out.flush()
    return 0


def _on_reply(msg, args, sim, mav, values, counts, record, out, t_sim, sending) -> None:
    """Answer a request (``sending``: message id -> on/off, changed in place) or record a report."""
    mtype = msg.get_type()
    if mtype == "NAMED_VALUE_FLOAT":
        counts["named_value_float"] += 1
        values[msg.name] = msg.value
        if record is not None:
            record.write(json.dumps({"type": "NAMED_VALUE_FLOAT", "t_sim": t_sim, "time_boot_ms": msg.time_boot_ms,
                                     "name": msg.name, "value": msg.value}) + "\n")
    elif mtype == "STATUSTEXT":
        counts["statustext"] += 1
        print(f"STATUSTEXT severity={msg.severity} t={t_sim - 1.0:.0f}s: {msg.text}", file=out, flush=True)
        if record is not None:
            record.write(json.dumps({"type": "STATUSTEXT", "t_sim": t_sim, "severity": msg.severity, "text": msg.text}) + "\n")
    elif mtype == "COMMAND_LONG" and msg.command == MAV_CMD_SET_MESSAGE_INTERVAL:
        counts["commands"] += 1
        if args.refuse_interval:
            mav.command_ack_send(MAV_CMD_SET_MESSAGE_INTERVAL, 2)  # MAV_RESULT_DENIED
            return
        mid = int(msg.param1)
        if mid in sending:  # one of our IMU messages; all IMUs share one rate (the last one asked for)
            sim.interval_set = True
            interval = msg.param2
            if interval > 0:
                sim.set_rate(1e6 / interval)
            sending[mid] = interval >= 0
        mav.command_ack_send(MAV_CMD_SET_MESSAGE_INTERVAL, 0)  # MAV_RESULT_ACCEPTED
        if not args.quiet:
            print(f"request: SET_MESSAGE_INTERVAL id {int(msg.param1)} {msg.param2:.0f} us", file=out, flush=True)
    elif mtype == "REQUEST_DATA_STREAM":
        counts["commands"] += 1
        if (msg.req_stream_id in (0, 1) and msg.start_stop and msg.req_message_rate > 0
                and not sim.interval_set):  # MAV_DATA_STREAM_ALL or RAW_SENSORS
            sim.set_rate(min(50.0, float(msg.req_message_rate)))
            for mid in sending:
                sending[mid] = True
        if not args.quiet:
            print(f"request: REQUEST_DATA_STREAM {msg.req_stream_id} at {msg.req_message_rate} Hz", file=out, flush=True)
