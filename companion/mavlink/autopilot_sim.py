"""A simulated ArduPilot vehicle on a live MAVLink link (``companion sim-autopilot``; the vehicle itself is
:mod:`companion.sim.vehicle`): HEARTBEAT once per simulated second, the IMUs as RAW_IMU / SCALED_IMU2 /
SCALED_IMU3 in ArduPilot units, the answers to MAV_CMD_SET_MESSAGE_INTERVAL and REQUEST_DATA_STREAM, and a
record of what comes back.

Time is simulated: ``speedup`` simulated seconds per wall second, the first sample at 1 s. With flow
control (a receiver on this machine, Linux) simulated time also waits for the receiver: no IMU messages
are sent while its UDP receive queue (/proc/net/udp) holds more than a quarter of a socket buffer.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

MAV_TYPE_QUADROTOR = 2
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_STATE_STANDBY = 3
MAV_STATE_ACTIVE = 4
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_RESULT_ACCEPTED = 0
MAV_RESULT_DENIED = 2
RAW_IMU_ID = 27
SCALED_IMU2_ID = 116
SCALED_IMU3_ID = 129
IMU_MSG_IDS = (RAW_IMU_ID, SCALED_IMU2_ID, SCALED_IMU3_ID)  # IMU0, IMU1, IMU2
COUNT_KEYS = ("raw_imu", "scaled_imu2", "scaled_imu3")  # the sent counters of IMU0, IMU1, IMU2
G0 = 9.80665  # standard gravity, m/s^2 per g (accel in mG)
TEMP_CDEG = 4200  # IMU temperature sent when the simulator has none: 42 degC in cdegC
MAX_STREAM_HZ = 50.0  # the highest rate REQUEST_DATA_STREAM sets, as ArduPilot's stream rates
FLOW_BURST_MESSAGES = 24.0  # IMU messages sent at once under flow control: well within a receive buffer
IDLE_SLEEP_S = 0.005  # wall seconds between two passes of the send loop
FLOW_SLEEP_S = 0.002  # the same under flow control (smaller bursts, more often)
FLOW_BACKOFF_MAX_S = 0.03  # the longest wait while the receiver's queue stays full: reading /proc/net/udp
# costs about 0.13 ms, so polling a slow (loaded) receiver every 2 ms spent CPU in proportion to wall time


@dataclass(frozen=True)
class SimOptions:
    """How the simulated autopilot runs (the command line's options)."""

    speedup: float = 1.0  # simulated seconds per wall second
    duration: float | None = None  # simulated seconds, None: until stopped
    wall_limit: float | None = None  # wall seconds in any case
    wait_request: bool = False  # idle until asked for IMU data
    refuse_interval: bool = False  # answer SET_MESSAGE_INTERVAL with DENIED
    quiet: bool = False  # only STATUSTEXT and the final values
    flow_ports: tuple[int, ...] | None = None  # local UDP ports whose queues pace the simulation


def udp_queue_bytes(ports) -> int | None:
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


def flow_limit() -> int:
    """Queued bytes above which sending waits: a quarter of the default socket receive buffer (kernel
    accounting per datagram includes its buffer overhead, so this is some tens of datagrams)."""
    try:
        with open("/proc/sys/net/core/rmem_default") as f:
            return max(int(f.read()) // 4, 16384)
    except (OSError, ValueError):
        return 49152


def describe(sim) -> str:
    """One line: the IMUs, flights, handlings and fault of the simulated vehicle."""
    names = ("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")[:sim.imus]
    parts = [f"{sim.imus} IMU(s) ({', '.join(names)}) at {sim.rate_hz:g} Hz"]
    for f in sim.schedule.flights:
        parts.append(f"flight {f.arm_at:g}-{f.disarm_at:g} s")
    for h in sim.schedule.handlings:
        parts.append(f"handling {h.at:g}-{h.end:g} s")
    if sim.fault is not None:
        parts.append("fault " + sim.fault.describe())
    return "sim-autopilot: " + "; ".join(parts)


def _imu_ints(blk, i):
    """IMU i of a block as int16 accel (mG) and gyro (mrad/s) rows, rounded to the nearest LSB."""
    a = np.clip(np.rint(blk.accel[i] / (G0 * 1e-3)), -32768, 32767).astype(int).tolist()
    g = np.clip(np.rint(blk.gyro[i] / 1e-3), -32768, 32767).astype(int).tolist()
    return a, g


class SimAutopilot:
    """The simulator ``sim`` on the open connection ``conn``; ``say(line)`` prints what happens."""

    def __init__(self, sim, conn, opts: SimOptions, say: Callable[[str], None], record=None):
        self.sim, self.conn, self.opts, self.say, self.record = sim, conn, opts, say, record
        self.mav = conn.mav
        self.values: dict[str, float] = {}
        self.counts = {"raw_imu": 0, "scaled_imu2": 0, "scaled_imu3": 0, "heartbeat": 0, "named_value_float": 0,
                       "statustext": 0, "commands": 0}
        self.sending = {mid: not opts.wait_request for mid in IMU_MSG_IDS[:sim.imus]}
        self.flow_limit = flow_limit()
        self.next_hb = 1.0
        self.t_flow = 1.0  # flow control: simulated time sent so far
        self.flow_sleep = FLOW_SLEEP_S  # flow control: wall seconds to the next pass (longer while the queue is full)
        # whole blocks packed with numpy (the same bytes as pymavlink's *_send); a signed or MAVLink 1 link
        # keeps pymavlink's per-message path
        dialect = sys.modules.get(type(self.mav).__module__)
        self.fast = getattr(dialect, "WIRE_PROTOCOL_VERSION", "") == "2.0" and not self.mav.signing.sign_outgoing

    # ------------------------------------------------------------------ the loop
    def run(self, stop: Callable[[], bool]) -> None:
        """Send and answer until ``stop()``, the simulated duration or the wall limit."""
        opts = self.opts
        wall_start = time.monotonic()
        wall0 = None if opts.wait_request else wall_start  # simulated time runs from wall0 (the first request)
        next_idle_hb = wall_start
        while not stop():
            now = time.monotonic()
            if wall0 is None:  # waiting for a request: HEARTBEAT once a wall second, simulated time stands still
                t_sim = 1.0
                if now >= next_idle_hb:
                    self.heartbeat(False)
                    next_idle_hb += 1.0
            else:
                t_sim = self.sim_time(now, wall0)
                self.send_until(t_sim)
            self.answer(t_sim)
            if wall0 is None and any(self.sending.values()):
                wall0 = time.monotonic()  # asked: the simulation starts now
            if opts.duration is not None and t_sim >= 1.0 + opts.duration:
                break
            if opts.wall_limit is not None and now - wall_start >= opts.wall_limit:
                break
            time.sleep(self.flow_sleep if opts.flow_ports is not None else IDLE_SLEEP_S)

    def sim_time(self, now: float, wall0: float) -> float:
        """The simulated time to send up to: by the wall clock, held back by flow control, capped."""
        opts = self.opts
        t_sim = 1.0 + (now - wall0) * opts.speedup
        if opts.flow_ports is not None:
            # at most a burst that fits well in the receiver's buffer, and only when its queue is short
            burst_s = FLOW_BURST_MESSAGES / (self.sim.rate_hz * max(1, sum(self.sending.values())))
            queued = udp_queue_bytes(opts.flow_ports)
            if queued is None:  # not observable (not Linux, not bound yet): the speedup alone paces
                self.t_flow = max(self.t_flow, t_sim)
            elif queued <= self.flow_limit:
                self.t_flow = min(t_sim, self.t_flow + burst_s)
                self.flow_sleep = FLOW_SLEEP_S
            else:  # the receiver is behind: wait longer each pass, up to FLOW_BACKOFF_MAX_S
                self.flow_sleep = min(2.0 * self.flow_sleep, FLOW_BACKOFF_MAX_S)
            t_sim = self.t_flow
        if opts.duration is not None:
            t_sim = min(t_sim, 1.0 + opts.duration)
        return t_sim

    def answer(self, t_sim: float) -> None:
        """Every message waiting on the link: requests answered, reports recorded."""
        while True:
            msg = self.conn.recv_match(blocking=False)
            if msg is None:
                return
            self.on_reply(msg, t_sim)

    # ------------------------------------------------------------------ sending
    def heartbeat(self, armed: bool) -> None:
        base_mode = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        self.mav.heartbeat_send(MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_ARDUPILOTMEGA, base_mode, 0,
                                MAV_STATE_ACTIVE if armed else MAV_STATE_STANDBY)
        self.counts["heartbeat"] += 1

    def send_until(self, t_sim: float) -> None:
        """The IMU samples and HEARTBEATs of the simulator up to ``t_sim``, in time order."""
        sim = self.sim
        blk = sim.take_until(t_sim)
        hb_times = []
        while self.next_hb <= t_sim:
            hb_times.append(self.next_hb)
            self.next_hb += 1.0
        if self.fast:
            self._send_block(blk, [self.sending[mid] for mid in IMU_MSG_IDS[:sim.imus]], hb_times,
                             [bool(sim.armed_at(th)) for th in hb_times])
        else:
            self._send_messages(blk, hb_times)

    def _send_block(self, blk, sending, hb_times, hb_armed) -> None:
        """A block's IMU messages and HEARTBEATs as frames built at once, one datagram/write each."""
        from companion.mavlink.imu_frames import block_frames

        mav = self.mav
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
        for i, key in enumerate(COUNT_KEYS[:len(sending)]):
            self.counts[key] += int(np.count_nonzero(kind == i))
        self.counts["heartbeat"] += len(hb_times)

    def _send_messages(self, blk, hb_times) -> None:
        """pymavlink's per-message path (signed or MAVLink 1 links): samples and HEARTBEATs in time order."""
        sim, mav = self.sim, self.mav
        senders = (lambda ti, a, g, c: mav.raw_imu_send(int(round(ti * 1e6)), *a, *g, 0, 0, 0, 0, c),
                   lambda ti, a, g, c: mav.scaled_imu2_send(int(round(ti * 1e3)), *a, *g, 0, 0, 0, c),
                   lambda ti, a, g, c: mav.scaled_imu3_send(int(round(ti * 1e3)), *a, *g, 0, 0, 0, c))
        t = blk.t.tolist()
        ints = [_imu_ints(blk, i) for i in range(sim.imus)]
        # temperature in cdegC: the simulated IMU's (a preset) or a constant
        temps = [[TEMP_CDEG] * blk.n if blk.temperature is None else
                 np.clip(np.rint(blk.temperature[i] * 100.0), -32768, 32767).astype(int).tolist()
                 for i in range(sim.imus)]
        k = 0
        for th in hb_times + [math.inf]:
            while k < len(t) and t[k] < th:
                for i, mid in enumerate(IMU_MSG_IDS[:sim.imus]):
                    if self.sending[mid]:
                        senders[i](t[k], ints[i][0][k], ints[i][1][k], temps[i][k])
                        self.counts[COUNT_KEYS[i]] += 1
                k += 1
            if th != math.inf:
                self.heartbeat(bool(sim.armed_at(th)))

    # ------------------------------------------------------------------ what comes back
    def on_reply(self, msg, t_sim: float) -> None:
        """Answer a request or record a report."""
        mtype = msg.get_type()
        if mtype == "NAMED_VALUE_FLOAT":
            self.counts["named_value_float"] += 1
            self.values[msg.name] = msg.value
            self._record({"type": "NAMED_VALUE_FLOAT", "t_sim": t_sim, "time_boot_ms": msg.time_boot_ms,
                          "name": msg.name, "value": msg.value})
        elif mtype == "STATUSTEXT":
            self.counts["statustext"] += 1
            self.say(f"STATUSTEXT severity={msg.severity} t={t_sim - 1.0:.0f}s: {msg.text}")
            self._record({"type": "STATUSTEXT", "t_sim": t_sim, "severity": msg.severity, "text": msg.text})
        elif mtype == "COMMAND_LONG" and msg.command == MAV_CMD_SET_MESSAGE_INTERVAL:
            self.on_set_interval(msg)
        elif mtype == "REQUEST_DATA_STREAM":
            self.counts["commands"] += 1
            if (msg.req_stream_id in (0, 1) and msg.start_stop and msg.req_message_rate > 0
                    and not self.sim.interval_set):  # MAV_DATA_STREAM_ALL or RAW_SENSORS
                self.sim.set_rate(min(MAX_STREAM_HZ, float(msg.req_message_rate)))
                for mid in self.sending:
                    self.sending[mid] = True
            if not self.opts.quiet:
                self.say(f"request: REQUEST_DATA_STREAM {msg.req_stream_id} at {msg.req_message_rate} Hz")

    def on_set_interval(self, msg) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL: all IMUs share one rate (the last one asked for)."""
        self.counts["commands"] += 1
        if self.opts.refuse_interval:
            self.mav.command_ack_send(MAV_CMD_SET_MESSAGE_INTERVAL, MAV_RESULT_DENIED)
            return
        mid = int(msg.param1)
        if mid in self.sending:  # one of our IMU messages
            self.sim.interval_set = True
            interval = msg.param2
            if interval > 0:
                self.sim.set_rate(1e6 / interval)
            self.sending[mid] = interval >= 0
        self.mav.command_ack_send(MAV_CMD_SET_MESSAGE_INTERVAL, MAV_RESULT_ACCEPTED)
        if not self.opts.quiet:
            self.say(f"request: SET_MESSAGE_INTERVAL id {int(msg.param1)} {msg.param2:.0f} us")

    def _record(self, entry: dict) -> None:
        if self.record is not None:
            self.record.write(json.dumps(entry) + "\n")

    def summary_lines(self) -> list[str]:
        """What was sent and received, then the last value of every NAMED_VALUE_FLOAT."""
        c = self.counts
        sent = " + ".join(f"{c[COUNT_KEYS[i]]} {COUNT_KEYS[i].upper()}" for i in range(self.sim.imus))
        lines = [f"sim-autopilot: sent {sent} and {c['heartbeat']} HEARTBEAT ({self.sim.rate_hz:g} Hz at the end); "
                 f"received {c['named_value_float']} NAMED_VALUE_FLOAT, {c['statustext']} STATUSTEXT, "
                 f"{c['commands']} requests"]
        return lines + [f"NAMED_VALUE_FLOAT {name} {self.values[name]:.6g}" for name in sorted(self.values)]
