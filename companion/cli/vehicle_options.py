"""Command-line options of the simulated vehicle (companion.sim.vehicle), shared by `companion sim-autopilot`
and `companion simulate --vehicle`: IMU count, flight, handling, warm-up, IMU spread and one gyro fault.
Every option is checked in :func:`build_simulator`, before anything is opened, with one error line."""

from __future__ import annotations

import math

from companion.errors import CompanionError

#: the effect a --degrade-term grows
DEGRADE_EFFECT = {"N": "white_noise", "B": "bias_instability", "K": "random_walk"}
#: --fault kinds (companion.sim.vehicle.Fault)
FAULT_KINDS = ("stuck", "noise", "bias", "spikes", "drift", "saturate", "flight_noise")
#: s: the shortest flight, room for take-off, a manoeuvre and landing
MIN_FLIGHT_S = 4.0
#: the --help text of the fault sizes, one line per kind
FAULT_HELP = """\
A fault (--fault KIND --fault-at S) on IMU --fault-imu, gyro axis --fault-axis; --fault-size X is, per KIND:
  stuck     std of a dither added to the frozen value, rad/s (default 0: output frozen at its last value)
  noise     factor on the white-noise std (default 6; the model needs a white_noise term on that axis)
  bias      step added to the output, rad/s (default 0.01745 = 1 deg/s; negative allowed)
  spikes    fraction of samples hit by a +-amplitude outlier (default 0.005 = 0.5 %;
            --spike-amplitude, default 0.3 rad/s)
  drift     ramp added from the fault time on, rad/s per s (default 1e-4)
  saturate  clip level: the output is limited to +-X rad/s (default 0.5)
  flight_noise  factor on the own noise; with --preset also on the IMU's vibration pick-up (default 2)
"""


def add_vehicle_options(p) -> None:
    """--imus, flight, handling, warm-up and IMU-spread options (times in s since the simulation start)."""
    g = p.add_argument_group("vehicle (times in s since the simulation start)")
    g.add_argument("--imus", type=int, default=None, metavar="N", help="number of IMUs, 1-3: RAW_IMU, +SCALED_IMU2, +SCALED_IMU3 (default 1, or the preset's)")
    from companion.sim import preset_names

    g.add_argument("--preset", metavar="NAME|FILE", help="realistic autopilot data (companion.sim.realism): "
                   f"{', '.join(preset_names())} or a preset "
                   "YAML: gyro low-pass at the sensor rate and decimation, vibration per IMU and flight phase, IMU timing skew, "
                   "temperature-driven bias, sensor LSB; its noise model is used when no model is given")
    g.add_argument("--arm-at", type=float, metavar="S", help="arm (and fly) at S")
    g.add_argument("--disarm-at", type=float, metavar="S", help="land and disarm at S (default: --arm-at + 60)")
    g.add_argument("--arm-s", type=float, metavar="D", help="older form of --disarm-at: armed for D seconds")
    g.add_argument("--max-rate", type=float, default=1.5, metavar="RAD_S", help="about the peak body rate of the manoeuvres (default 1.5 rad/s)")
    g.add_argument("--handle-at", type=float, action="append", metavar="S", help="picked up and turned by hand at S while disarmed (repeatable)")
    g.add_argument("--handle-s", type=float, default=20.0, metavar="D", help="duration of each handling (default 20 s)")
    g.add_argument("--warmup-deg-s", type=float, default=0.0, metavar="X", help="cold-start bias drift of up to X deg/s per gyro axis (default 0)")
    g.add_argument("--warmup-tau-s", type=float, default=200.0, metavar="S", help="time constant of the warm-up drift (default 200 s)")
    g.add_argument("--scale-spread", type=float, default=0.005, metavar="F", help="per-IMU scale-factor error, uniform in +-F (default 0.005 = 0.5 %%)")
    g.add_argument("--misalign-deg", type=float, default=0.3, metavar="D", help="per-IMU misalignment, up to D degrees (default 0.3)")


def add_fault_options(p, degrade: bool = False) -> None:
    """--fault KIND and its options; with ``degrade`` also the older --degrade-* noise growth."""
    g = p.add_argument_group("fault (one gyro axis of one IMU; see above for --fault-size per kind)")
    g.add_argument("--fault", choices=FAULT_KINDS, metavar="KIND", help="stuck, noise, bias, spikes, drift, saturate or flight_noise")
    g.add_argument("--fault-at", type=float, metavar="S", help="time of the fault (required with --fault)")
    g.add_argument("--fault-size", type=float, metavar="X", help="size in the kind's SI unit (rad/s, factor, fraction, rad/s per s)")
    g.add_argument("--fault-imu", type=int, default=0, metavar="I", help="faulty IMU, 0 .. --imus - 1 (default 0)")
    g.add_argument("--fault-axis", default="gx", choices=("gx", "gy", "gz"), help="faulty gyro axis (default gx)")
    g.add_argument("--spike-amplitude", type=float, default=0.3, metavar="RAD_S", help="outlier size of --fault spikes (default 0.3 rad/s)")
    if not degrade:
        return
    g = p.add_argument_group("degradation (a noise term grows; IMU0)")
    g.add_argument("--degrade-at", type=float, metavar="S", help="simulated time at which the gyro degrades")
    g.add_argument("--degrade-factor", type=float, default=2.0, metavar="F", help="factor on the degraded term (default 2)")
    g.add_argument("--degrade-axis", default="gx", choices=("gx", "gy", "gz"), help="degraded axis (default gx)")
    g.add_argument("--degrade-term", default="N", choices=("N", "B", "K"), help="degraded term (default N)")


def _preset_model(args, model, rate_hz):
    """(model, rate_hz, realism) with a --preset's: its realism, and its model and logged rate where none
    was given; --imus from the preset unless given."""
    preset = getattr(args, "preset", None)
    if preset is None:
        return model, rate_hz, None
    from companion.sim.preset import load_preset

    P = load_preset(preset)
    if model is None:  # the preset's model at the preset's logged rate
        model = P["model"]
        if rate_hz is None and "rate_hz" in P["vehicle"]:
            rate_hz = float(P["vehicle"]["rate_hz"])
    if args.imus is None:
        args.imus = int(P["vehicle"].get("imus", 1))
    return model, rate_hz, P["realism"]


def _schedule(args, V):
    """The flight (--arm-at, --disarm-at or --arm-s, --max-rate) and the handlings (--handle-at)."""
    flights = []
    if args.arm_at is None:
        for name in ("disarm_at", "arm_s"):
            if getattr(args, name) is not None:
                raise CompanionError(f"--{name.replace('_', '-')} needs --arm-at")
    else:
        if args.disarm_at is not None and args.arm_s is not None:
            raise CompanionError("give --disarm-at or --arm-s, not both")
        disarm = args.disarm_at if args.disarm_at is not None else args.arm_at + (60.0 if args.arm_s is None else args.arm_s)
        if not disarm >= args.arm_at + MIN_FLIGHT_S:
            raise CompanionError(f"--disarm-at ({disarm:g} s) must be at least 4 s after --arm-at ({args.arm_at:g} s)")
        flights.append(_checked(lambda: V.Flight(args.arm_at, disarm, max_rate=args.max_rate), "--arm-at/--max-rate"))
    handlings = [_checked(lambda: V.Handling(h, args.handle_s), "--handle-at/--handle-s") for h in (args.handle_at or [])]
    return _checked(lambda: V.Schedule(tuple(flights), tuple(handlings)), "--handle-at")


def _fault(args, V):
    """The --fault, or None; its options without it are refused."""
    if args.fault is None:
        for name in ("fault_at", "fault_size"):
            if getattr(args, name) is not None:
                raise CompanionError(f"--{name.replace('_', '-')} needs --fault KIND")
        return None
    if args.fault_at is None:
        raise CompanionError("--fault needs --fault-at S (seconds since the simulation start)")
    if not 0 <= args.fault_imu < args.imus:
        raise CompanionError(f"--fault-imu {args.fault_imu}: the vehicle has {args.imus} IMU(s) (0..{args.imus - 1}); raise --imus")
    if not args.fault_at >= 0:
        raise CompanionError(f"--fault-at must be >= 0, got {args.fault_at:g}")
    if not args.spike_amplitude > 0:
        raise CompanionError(f"--spike-amplitude must be > 0 rad/s, got {args.spike_amplitude:g}")
    return _checked(lambda: V.Fault(args.fault, args.fault_at, args.fault_size, args.fault_imu, args.fault_axis,
                                    args.spike_amplitude), "--fault-size")


def _degradation(args, model, V):
    """The --degrade-* noise growth, or None: the term grows to ``factor`` x its value by adding an independent
    term of the same effect, sqrt(factor^2 - 1) x the value (variances add)."""
    if getattr(args, "degrade_at", None) is None:
        return None
    if not args.degrade_factor >= 1.0:
        raise CompanionError("--degrade-factor must be >= 1 (a degradation makes a term larger)")
    effect = DEGRADE_EFFECT[args.degrade_term]
    base = [t for t in (model.axes.get(args.degrade_axis) or []) if t["effect"] == effect]
    if not base:
        raise CompanionError(f"--degrade-term {args.degrade_term}: the model has no {effect} on {args.degrade_axis}")
    extra = {"effect": effect, args.degrade_term: base[0][args.degrade_term] * math.sqrt(args.degrade_factor**2 - 1.0)}
    return _checked(lambda: V.Degradation(args.degrade_at, args.degrade_axis, extra), "--degrade-at")


def _warmup(args, V):
    if args.warmup_deg_s < 0:
        raise CompanionError(f"--warmup-deg-s must be >= 0, got {args.warmup_deg_s:g}")
    if not args.warmup_deg_s:
        return None
    return _checked(lambda: V.WarmUp(math.radians(args.warmup_deg_s), args.warmup_tau_s), "--warmup-deg-s/--warmup-tau-s")


def build_simulator(args, model, rate_hz: float | None = None):
    """The :class:`companion.sim.vehicle.VehicleSimulator` the options describe (every check up front)."""
    from companion.sim import vehicle as V

    model, rate_hz, realism = _preset_model(args, model, rate_hz)
    if model is None:
        raise CompanionError("give a noise model (MODEL.yaml) or --preset")
    if args.imus is None:
        args.imus = 1
    if not 1 <= args.imus <= 3:
        raise CompanionError(f"--imus must be 1, 2 or 3, got {args.imus}")
    if args.seed < 0:
        raise CompanionError(f"--seed must be >= 0, got {args.seed}")
    schedule = _schedule(args, V)
    fault = _fault(args, V)
    degrade = _degradation(args, model, V)
    warmup = _warmup(args, V)
    spread = _checked(lambda: V.ImuSpread(scale=args.scale_spread, misalignment_deg=args.misalign_deg),
                      "--scale-spread/--misalign-deg")
    rate = float(rate_hz or model.rate_hz)
    if not rate > 0:
        raise CompanionError("--rate must be > 0")
    return _checked(lambda: V.VehicleSimulator(model, imus=args.imus, seed=args.seed, rate_hz=rate, schedule=schedule,
                                               fault=fault, warmup=warmup, spread=spread, degrade=degrade,
                                               realism=realism), "--fault/--preset")


def _checked(make, option):
    try:
        return make()
    except CompanionError as exc:
        raise CompanionError(f"{option}: {exc}") from None
