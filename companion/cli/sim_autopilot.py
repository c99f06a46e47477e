"""``companion sim-autopilot``: a simulated, disarmed vehicle on a MAVLink link (SITL loopback for `companion run`)."""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time

import numpy as np

from companion.errors import CompanionError

DESCRIPTION = """\
Play a disarmed vehicle: HEARTBEAT once per simulated second and RAW_IMU from the noise simulator
(companion.sim) in ArduPilot units (gyro int16 mrad/s, accel int16 mG, rounded to the nearest LSB, so
the 1 mrad/s rounding adds white noise of variance LSB^2/12 per sample, i.e. N_q = 1e-3/sqrt(12 rate)
rad/s/sqrt(Hz) -- choose a model noise well above it or add it to your truth). It honours
MAV_CMD_SET_MESSAGE_INTERVAL (answers COMMAND_ACK and changes the RAW_IMU rate) and REQUEST_DATA_STREAM,
and prints what comes back (STATUSTEXT as it arrives, the last NAMED_VALUE_FLOAT values at the end).

Time is simulated: --speedup X sends X simulated seconds per wall second with message timestamps in
simulated time. Optional: a degradation (--degrade-at S: from then on the term --degrade-term of axis
--degrade-axis is multiplied by --degrade-factor, by adding an independent component of the same kind
scaled by sqrt(F^2 - 1)), and an armed, moving period (--arm-at S --arm-s D) to check that flight and
handling neither corrupt the estimates nor raise flags.
"""

EPILOG = """\
examples:
  companion sim-autopilot --model gyro.yaml --connect udpout:127.0.0.1:14551
  companion sim-autopilot --model gyro.yaml --connect udpout:127.0.0.1:14551 --speedup 30 --duration 900 \\
      --degrade-at 400 --degrade-factor 2 --degrade-axis gx --record replies.jsonl

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
G0 = 9.80665
DEGRADE_EFFECT = {"N": "white_noise", "B": "bias_instability", "K": "random_walk"}


def register(subparsers) -> None:
    p = subparsers.add_parser("sim-autopilot", help="simulated disarmed vehicle sending RAW_IMU (SITL loopback)",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", required=True, metavar="MODEL.yaml", help="noise model (companion.sim.model format)")
    p.add_argument("--connect", required=True, metavar="CONN", help="where to send, e.g. udpout:127.0.0.1:14551")
    p.add_argument("--rate", type=float, metavar="HZ", help="RAW_IMU rate before any request (default: the model's rate_hz)")
    p.add_argument("--speedup", type=float, default=1.0, metavar="X", help="simulated seconds per wall second (default 1)")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S simulated seconds (default: until Ctrl-C)")
    p.add_argument("--wall-limit", type=float, metavar="S", help="stop after S wall-clock seconds in any case")
    p.add_argument("--sysid", type=int, default=1, help="system id of the simulated vehicle (default 1)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the simulator (default 0)")
    p.add_argument("--degrade-at", type=float, metavar="S", help="simulated time at which the gyro degrades")
    p.add_argument("--degrade-factor", type=float, default=2.0, metavar="F", help="factor on the degraded term (default 2)")
    p.add_argument("--degrade-axis", default="gx", choices=("gx", "gy", "gz"), help="degraded axis (default gx)")
    p.add_argument("--degrade-term", default="N", choices=("N", "B", "K"), help="degraded term (default N)")
    p.add_argument("--arm-at", type=float, metavar="S", help="arm and move (flight) at simulated time S")
    p.add_argument("--arm-s", type=float, default=60.0, metavar="D", help="armed, moving period in seconds (default 60)")
    p.add_argument("--wait-request", action="store_true", help="send no RAW_IMU until asked (SET_MESSAGE_INTERVAL / REQUEST_DATA_STREAM)")
    p.add_argument("--refuse-interval", action="store_true", help="answer SET_MESSAGE_INTERVAL with DENIED (tests the fallback)")
    p.add_argument("--record", metavar="FILE", help="write every received NAMED_VALUE_FLOAT/STATUSTEXT as JSON lines")
    p.add_argument("--quiet", action="store_true", help="print only STATUSTEXT and the final values")
    p.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing with this 32-byte key, like an "
                   "ArduPilot with signing set up: signs what it sends, ignores unsigned or wrongly signed frames")
    p.set_defaults(func=run)


class ImuSimulator:
    """Blocks of SI gyro/accel samples from the model, continuing across blocks; rate may change."""

    BLOCK_S = 600.0

    def __init__(self, model, rate_hz: float, seed: int, degrade=None, arm=None):
        from companion.sim.synth import synthesize_axis

        self.synth = synthesize_axis
        self.model = model
        self.rate_hz = float(rate_hz)
        self.rng = np.random.default_rng(seed)
        self.degrade = degrade  # (t0, axis, extra term)
        self.arm = arm  # (t0, t1)
        self.t_next = 1.0  # s since boot of the next sample
        self.interval_set = False  # a SET_MESSAGE_INTERVAL wins over REQUEST_DATA_STREAM (as in ArduPilot)
        self.last = {}
        self._t = np.zeros(0)
        self._g = np.zeros((0, 3))
        self._a = np.zeros((0, 3))
        self._i = 0

    def set_rate(self, rate_hz: float) -> None:
        if rate_hz > 0 and abs(rate_hz - self.rate_hz) > 1e-9:
            self.rate_hz = float(rate_hz)
            self._t, self._i = np.zeros(0), 0  # regenerate from t_next at the new rate

    def _block(self) -> None:
        n = max(1, int(round(self.BLOCK_S * self.rate_hz)))
        t = self.t_next + np.arange(n) / self.rate_hz
        g = np.zeros((n, 3))
        a = np.zeros((n, 3))
        for j, ax in enumerate(("gx", "gy", "gz", "ax", "ay", "az")):
            terms = self.model.axes.get(ax) or []
            y = np.zeros(n)
            for i, term in enumerate(terms):  # term by term: random walk and ramp continue across blocks
                c = self.synth([term], self.rate_hz, n, self.rng)
                if term["effect"] in ("random_walk", "ramp"):
                    c += self.last.get((ax, i), 0.0) + (term.get("R", 0.0) / self.rate_hz if (ax, i) in self.last else 0.0)
                    self.last[(ax, i)] = float(c[-1])
                y += c
            if self.degrade is not None and ax == self.degrade[1] and t[-1] >= self.degrade[0]:
                extra = self.synth([self.degrade[2]], self.rate_hz, n, self.rng)
                if self.degrade[2]["effect"] == "random_walk":  # starts from 0 at the degradation, continues
                    i0 = int(np.searchsorted(t, self.degrade[0]))
                    extra += self.last.get("extra", 0.0) - (extra[i0] if t[0] < self.degrade[0] else extra[0])
                    self.last["extra"] = float(extra[-1])
                y = y + np.where(t >= self.degrade[0], extra, 0.0)
            if j < 3:
                g[:, j] = y
            else:
                a[:, j - 3] = y
        if not self.model.axes.get("ax") and not self.model.axes.get("ay") and not self.model.axes.get("az"):
            a += self.rng.normal(0.0, 0.02, (n, 3))  # a plausible accelerometer at rest
        a[:, 2] -= G0  # gravity, body z down (ArduPilot's FRD: -1 g on z at rest)
        if self.arm is not None:
            m = (t >= self.arm[0]) & (t < self.arm[1])
            if m.any():  # flight: turning and vibrating
                g[m] += 0.5 * np.sin(2 * np.pi * 0.3 * t[m])[:, None]
                a[m] += self.rng.normal(0.0, 2.0, (int(m.sum()), 3))
        self._t, self._g, self._a, self._i = t, g, a, 0

    def take_until(self, t_end: float):
        """Samples with t <= t_end: (t, gyro, accel) arrays."""
        ts, gs, as_ = [], [], []
        while self.t_next <= t_end:
            if self._i >= self._t.size:
                self._block()
            j = int(np.searchsorted(self._t, t_end, side="right"))
            ts.append(self._t[self._i:j])
            gs.append(self._g[self._i:j])
            as_.append(self._a[self._i:j])
            self._i = j
            self.t_next = self._t[j] if j < self._t.size else self._t[-1] + 1.0 / self.rate_hz
        if not ts:
            return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
        return np.concatenate(ts), np.concatenate(gs), np.concatenate(as_)


def _int16(x):
    return int(max(-32768, min(32767, round(x))))


def run(args) -> int:
    from companion.sim.model import load_model
    from companion.sources.connection import open_connection

    if not args.speedup > 0:
        raise CompanionError("--speedup must be > 0")
    for name in ("duration", "wall_limit", "arm_s"):
        v = getattr(args, name)
        if v is not None and not v > 0:
            raise CompanionError(f"--{name.replace('_', '-')} must be > 0")
    if not args.degrade_factor >= 1.0:
        raise CompanionError("--degrade-factor must be >= 1 (a degradation makes a term larger)")
    model = load_model(args.model)
    gyro_terms = model.axes.get(args.degrade_axis) or []
    degrade = None
    if args.degrade_at is not None:
        effect = DEGRADE_EFFECT[args.degrade_term]
        base = [t for t in gyro_terms if t["effect"] == effect]
        if not base:
            raise CompanionError(f"--degrade-term {args.degrade_term}: the model has no {effect} on {args.degrade_axis}")
        extra = {"effect": effect, args.degrade_term: base[0][args.degrade_term] * math.sqrt(args.degrade_factor**2 - 1.0)}
        degrade = (args.degrade_at + 1.0, args.degrade_axis, extra)  # time since boot starts at 1 s
    arm = None if args.arm_at is None else (args.arm_at + 1.0, args.arm_at + 1.0 + args.arm_s)
    rate = float(args.rate or model.rate_hz)
    if not rate > 0:
        raise CompanionError("--rate must be > 0")
    sim = ImuSimulator(model, rate, args.seed, degrade, arm)
    os.environ.setdefault("MAVLINK20", "1")  # speak MAVLink 2 like ArduPilot (pymavlink picks the dialect from it)
    conn = open_connection(args.connect, source_system=args.sysid, source_component=1)
    if args.signing_key:  # i14: signing, as on an autopilot after SETUP_SIGNING
        from companion.mavlink.signing import load_signing_key, setup_signing

        setup_signing(conn, load_signing_key(args.signing_key))
    out = sys.stdout
    record = open(args.record, "w") if args.record else None
    stop = {"flag": False}
    old = {s: signal.signal(s, lambda *a: stop.__setitem__("flag", True)) for s in (signal.SIGINT, signal.SIGTERM)}
    values: dict[str, float] = {}
    counts = {"raw_imu": 0, "heartbeat": 0, "named_value_float": 0, "statustext": 0, "commands": 0}
    sending = not args.wait_request
    wall0 = time.monotonic()
    next_hb = 1.0
    mav = conn.mav
    try:
        while not stop["flag"]:
            wall = time.monotonic() - wall0
            t_sim = 1.0 + wall * args.speedup
            if args.duration is not None:
                t_sim = min(t_sim, 1.0 + args.duration)
            armed = arm is not None and arm[0] <= t_sim < arm[1]
            t, g, a = sim.take_until(t_sim)
            hb_times = []
            while next_hb <= t_sim:
                hb_times.append(next_hb)
                next_hb += 1.0
            k = 0
            for th in hb_times + [math.inf]:
                while k < t.size and t[k] < th:
                    if sending:
                        mav.raw_imu_send(int(round(t[k] * 1e6)),
                                         _int16(a[k, 0] / (G0 * 1e-3)), _int16(a[k, 1] / (G0 * 1e-3)), _int16(a[k, 2] / (G0 * 1e-3)),
                                         _int16(g[k, 0] / 1e-3), _int16(g[k, 1] / 1e-3), _int16(g[k, 2] / 1e-3),
                                         0, 0, 0, 0, 4200)
                        counts["raw_imu"] += 1
                    k += 1
                if th != math.inf:
                    base_mode = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
                    mav.heartbeat_send(MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_ARDUPILOTMEGA, base_mode, 0,
                                       MAV_STATE_ACTIVE if armed else MAV_STATE_STANDBY)
                    counts["heartbeat"] += 1
            while True:
                msg = conn.recv_match(blocking=False)
                if msg is None:
                    break
                sending = _on_reply(msg, args, sim, mav, values, counts, record, out, t_sim, sending)
            if args.duration is not None and t_sim >= 1.0 + args.duration:
                break
            if args.wall_limit is not None and wall >= args.wall_limit:
                break
            time.sleep(0.005)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if record is not None:
            record.close()
        conn.close()
    print(f"sim-autopilot: sent {counts['raw_imu']} RAW_IMU and {counts['heartbeat']} HEARTBEAT "
          f"({sim.rate_hz:g} Hz at the end); received {counts['named_value_float']} NAMED_VALUE_FLOAT, "
          f"{counts['statustext']} STATUSTEXT, {counts['commands']} requests", file=out)
    for name in sorted(values):
        print(f"NAMED_VALUE_FLOAT {name} {values[name]:.6g}", file=out)
    out.flush()
    return 0


def _on_reply(msg, args, sim, mav, values, counts, record, out, t_sim, sending) -> bool:
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
            return sending
        if int(msg.param1) == RAW_IMU_ID:
            sim.interval_set = True
            interval = msg.param2
            if interval > 0:
                sim.set_rate(1e6 / interval)
                sending = True
            elif interval == 0:
                sending = True
            else:
                sending = False
        mav.command_ack_send(MAV_CMD_SET_MESSAGE_INTERVAL, 0)  # MAV_RESULT_ACCEPTED
        if not args.quiet:
            print(f"request: SET_MESSAGE_INTERVAL id {int(msg.param1)} {msg.param2:.0f} us", file=out, flush=True)
    elif mtype == "REQUEST_DATA_STREAM":
        counts["commands"] += 1
        if (msg.req_stream_id in (0, 1) and msg.start_stop and msg.req_message_rate > 0
                and not sim.interval_set):  # MAV_DATA_STREAM_ALL or RAW_SENSORS
            sim.set_rate(min(50.0, float(msg.req_message_rate)))
            sending = True
        if not args.quiet:
            print(f"request: REQUEST_DATA_STREAM {msg.req_stream_id} at {msg.req_message_rate} Hz", file=out, flush=True)
    return sending
