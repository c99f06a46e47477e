"""A vehicle with 1-3 IMUs: body motion (flights, handling), per-IMU errors, warm-up drift and faults (numpy only).

Physically, every IMU is a MEMS chip bolted to the same rigid body: all of them see the same body rotation
rate and specific force (including the frame's vibration), each through its own small scale-factor error
and mounting misalignment, plus its own constant bias, its own cold-start warm-up bias drift and its own
noise drawn from the noise model (:mod:`companion.sim.synth`). One sensor fault can be injected on one
IMU's gyro axis.

Stable API
----------
::

    from companion.sim.vehicle import (VehicleSimulator, Fault, Flight, Handling, Schedule, WarmUp,
                                       ImuSpread, Degradation, write_tlog)

    sim = VehicleSimulator(model, imus=2, seed=1,
                           schedule=Schedule(flights=[Flight(arm_at=600, disarm_at=1500)],
                                             handlings=[Handling(at=300, duration=20)]),
                           fault=Fault("stuck", at=1200, imu=1, axis="gx"),
                           warmup=WarmUp(amplitude=math.radians(0.1), tau_s=200))
    blk = sim.take_until(t_end)      # the samples with t <= t_end not taken yet (continues block by block)
    blk = sim.run(duration_s)        # or: everything up to t_start + duration_s
    for blk in sim.blocks(duration_s, block_s=600): ...   # or: the same in blocks (constant memory)
    blk.t                            # (n,) time since boot, s (the message timestamp)
    blk.gyro[i], blk.accel[i]        # (n, 3) IMU i in SI: rad/s, m/s^2 (body FRD; -9.81 on z when level)
    t, g, a = blk.imu(i)             # the same as a tuple
    blk.armed                        # (n,) bool, the HEARTBEAT armed bit the autopilot would send
    blk.rate_true, blk.accel_true    # (n, 3) the body's true rate and specific force (vibration included)
    sim.armed_at(t)                  # armed flag at times since boot (for HEARTBEATs)
    sim.set_rate(hz)                 # a SET_MESSAGE_INTERVAL: the next samples come at the new rate
    write_tlog("x.tlog", sim, 3600)  # RAW_IMU / SCALED_IMU2 / SCALED_IMU3 + HEARTBEAT (ArduPilot units)
    Schedule.random(36_000, seed=3)  # random non-overlapping flights and handlings (soak runs, benchmarks)
    sim.gyro_matrix[i], sim.gyro_bias[i], sim.warmup_amplitude[i]   # IMU i's drawn errors (truth for tests)

Time: samples are stamped in seconds since the autopilot booted; the first sample is at ``t_start``
(1.0 s). Every schedule and fault time (``Flight.arm_at``, ``Handling.at``, ``Fault.at`` ...) is in
seconds since the simulation start, i.e. ``t - t_start``.

Components (the order in which an IMU's gyro output is built, rad/s):

1. body rate ``w`` (vibration included while armed) -> ``C_i w``, with ``C_i = (I + diag(s_i)) R(m_i)``: a
   scale-factor error ``s_i`` per axis (uniform in +-``ImuSpread.scale``) and a misalignment rotation
   ``R(m_i)`` by an angle uniform in [0, ``ImuSpread.misalignment_deg``] about a random axis. The
   accelerometer uses the same mounting rotation and its own scale errors.
2. a constant bias per axis (normal, std ``ImuSpread.gyro_bias``) and the warm-up drift
   ``a_ij exp(-t / tau_s)`` (``|a_ij|`` uniform in [A/2, A], random sign: the bias moves by up to A while
   the chip warms after a cold start).
3. the noise model's terms for that axis, independent per IMU; random walk and Gauss-Markov continue
   exactly from the last sample taken (also across rate changes), ramp and sinusoid are functions of time;
   bias_instability (flicker) is synthesised per internal block of ``BLOCK_S`` = 600 s.
4. an optional :class:`Degradation` (an extra independent term of the same kind from a time on).
5. the :class:`Fault`, if any, on its IMU and axis (SI semantics in the :class:`Fault` docstring).

The body (:mod:`companion.sim.motion`): at rest the vehicle sits still at a small tilt; a :class:`Flight`
is armed, takes off, manoeuvres with body rates up to about ``max_rate`` and vibration, lands and
disarms; a :class:`Handling` is the disarmed vehicle picked up, turned by hand and put down in another
attitude. Flight, Handling and Schedule are re-exported here.

Everything is deterministic for a seed: the motion, each IMU's errors and each IMU's noise draw from
their own child of ``SeedSequence(seed)``, so IMU 0's noise does not depend on how many IMUs there are.
Errors in any parameter raise :class:`companion.errors.CompanionError` with one line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from companion.sim.motion import (BodyMotion, Flight, Handling, Schedule, _err, _finite, body_rates,
                                   rotation_nb, specific_force_at_rest)
from companion.allan.terms import validate_term
from companion.sim.synth import flicker, quantization
from companion.sim.realism import Realism, SensorStage

GYRO_AXES = ("gx", "gy", "gz")
ACCEL_AXES = ("ax", "ay", "az")
MAX_IMUS = 3
#: MAVLink message of each IMU index in a tlog or on the link (ArduPilot's convention)
IMU_MESSAGES = ("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")

FAULT_KINDS = ("stuck", "noise", "bias", "spikes", "drift", "saturate")
#: what ``Fault.size`` means for each kind (SI)
FAULT_SIZE_UNITS = {
    "stuck": "std in rad/s of a dither added to the frozen value (0: exactly frozen)",
    "noise": "factor on the axis' white-noise std (e.g. 6: six times noisier)",
    "bias": "step in rad/s added to the output (signed)",
    "spikes": "fraction of samples (0-1] hit by a +-amplitude outlier",
    "drift": "ramp in rad/s per s added from the fault on (signed)",
    "saturate": "clip level in rad/s: the output is limited to +-size",
}
FAULT_DEFAULT_SIZE = {"stuck": 0.0, "noise": 6.0, "bias": math.radians(1.0), "spikes": 0.005,
                      "drift": 1e-4, "saturate": 0.5}
DEFAULT_ACCEL_NOISE = 0.02  # m/s^2 per-sample std when the model has no accelerometer terms


# ----------------------------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class Fault:
    """One gyro fault on IMU ``imu``, axis ``axis`` (gx, gy, gz), from ``at`` s after the simulation start.

    ``size`` (None: the kind's default, :data:`FAULT_DEFAULT_SIZE`), in SI, for each ``kind``:

    - ``stuck``: the output freezes at its value of the last sample before ``at``; ``size`` is the std
      (rad/s) of a white dither added to the frozen value (0: bit-identical samples).
    - ``noise``: the axis' white-noise term (``white_noise`` in the model) has its std multiplied by
      ``size`` (>= 0); the other terms are unchanged.
    - ``bias``: ``size`` rad/s is added to every sample (a step).
    - ``spikes``: each sample is hit independently with probability ``size`` (0 < size <= 1) by an
      outlier of ``+amplitude`` or ``-amplitude`` rad/s (random sign) added to it.
    - ``drift``: ``size * (s - at)`` rad/s is added (a ramp of ``size`` rad/s per s; s = time since start).
    - ``saturate``: the output is clipped to ``[-size, +size]`` rad/s (``size`` > 0).

    The fault acts on the SI output before any int16 rounding of a MAVLink writer.
    """

    kind: str
    at: float
    size: float | None = None
    imu: int = 0
    axis: str = "gx"
    amplitude: float = 0.3  # rad/s, spikes only

    def __post_init__(self):
        if self.kind not in FAULT_KINDS:
            raise _err(f"fault kind {self.kind!r} unknown; expected one of {', '.join(FAULT_KINDS)}")
        object.__setattr__(self, "at", _finite("fault time (at)", self.at, lo=0.0))
        size = FAULT_DEFAULT_SIZE[self.kind] if self.size is None else self.size
        name = f"size of a {self.kind} fault ({FAULT_SIZE_UNITS[self.kind]})"
        if self.kind in ("stuck", "noise"):
            size = _finite(name, size, lo=0.0)
        elif self.kind == "spikes":
            size = _finite(name, size, lo=0.0, hi=1.0, lo_open=True)
        elif self.kind == "saturate":
            size = _finite(name, size, lo=0.0, lo_open=True)
        else:
            size = _finite(name, size)
        object.__setattr__(self, "size", size)
        if isinstance(self.imu, bool) or not isinstance(self.imu, (int, np.integer)) or not 0 <= self.imu < MAX_IMUS:
            raise _err(f"fault IMU must be 0, 1 or 2, got {self.imu!r}")
        if self.axis not in GYRO_AXES:
            raise _err(f"fault axis {self.axis!r} unknown; expected gx, gy or gz")
        object.__setattr__(self, "amplitude", _finite("spike amplitude (rad/s)", self.amplitude, lo=0.0, lo_open=True))

    def describe(self) -> str:
        unit = {"stuck": " rad/s dither", "noise": "x white noise", "bias": " rad/s", "spikes": " of samples",
                "drift": " rad/s/s", "saturate": " rad/s clip"}[self.kind]
        size = f"{100 * self.size:g} %" if self.kind == "spikes" else f"{self.size:g}{unit}"
        return f"IMU{self.imu} {self.axis} {self.kind} {size} at {self.at:g} s"


@dataclass(frozen=True)
class Degradation:
    """A noise term that grows: from ``at`` on, an independent term ``{"effect": ..., param: value}`` is added
    to IMU ``imu``'s ``axis`` (e.g. white_noise N*sqrt(F^2-1) makes the white noise F times larger).
    A random walk starts from 0 at ``at`` and continues."""

    at: float
    axis: str
    term: Mapping
    imu: int = 0

    def __post_init__(self):
        _finite("degradation time", self.at, lo=0.0)
        if self.axis not in GYRO_AXES + ACCEL_AXES:
            raise _err(f"degradation axis {self.axis!r} unknown")
        if self.term.get("effect") not in ("white_noise", "bias_instability", "random_walk", "gauss_markov"):
            raise _err("degradation term must be white_noise, bias_instability, random_walk or gauss_markov")


@dataclass(frozen=True)
class WarmUp:
    """Cold-start bias drift: each IMU gyro axis' bias moves by up to ``amplitude`` rad/s as
    ``a exp(-t / tau_s)`` (t since boot), |a| uniform in [amplitude/2, amplitude], random sign."""

    amplitude: float = math.radians(0.1)
    tau_s: float = 200.0

    def __post_init__(self):
        _finite("warm-up amplitude (rad/s)", self.amplitude, lo=0.0)
        _finite("warm-up time constant (s)", self.tau_s, lo=0.0, lo_open=True)


@dataclass(frozen=True)
class ImuSpread:
    """How much the IMUs differ: scale-factor error per axis uniform in +-``scale`` (fraction), a
    misalignment angle uniform in [0, ``misalignment_deg``] about a random axis, constant biases of std
    ``gyro_bias`` rad/s and ``accel_bias`` m/s^2 per axis."""

    scale: float = 0.005
    misalignment_deg: float = 0.3
    gyro_bias: float = 2e-3
    accel_bias: float = 0.05

    def __post_init__(self):
        _finite("scale-factor spread", self.scale, lo=0.0, hi=0.2)
        _finite("misalignment (deg)", self.misalignment_deg, lo=0.0, hi=10.0)
        _finite("gyro bias std (rad/s)", self.gyro_bias, lo=0.0)
        _finite("accel bias std (m/s^2)", self.accel_bias, lo=0.0)


@dataclass
class VehicleBlock:
    """Samples of all IMUs at common times (see the module docstring)."""

    t: np.ndarray  # (n,) s since boot
    gyro: np.ndarray  # (imus, n, 3) rad/s
    accel: np.ndarray  # (imus, n, 3) m/s^2
    armed: np.ndarray  # (n,) bool
    rate_true: np.ndarray  # (n, 3) rad/s, body
    accel_true: np.ndarray  # (n, 3) m/s^2, body specific force
    temperature: np.ndarray | None = None  # (imus, n) degC (with Realism), else None
    t_imu: np.ndarray | None = None  # (imus, n) each IMU's own time stamp (Realism stamp="own"), else None

    @property
    def n(self) -> int:
        return int(self.t.shape[0])

    def imu(self, i: int):
        return (self.t if self.t_imu is None else self.t_imu[i]), self.gyro[i], self.accel[i]

    def __getitem__(self, sl) -> "VehicleBlock":
        return VehicleBlock(self.t[sl], self.gyro[:, sl], self.accel[:, sl], self.armed[sl],
                            self.rate_true[sl], self.accel_true[sl],
                            None if self.temperature is None else self.temperature[:, sl],
                            None if self.t_imu is None else self.t_imu[:, sl])

    @staticmethod
    def concat(blocks: list, imus: int) -> "VehicleBlock":
        if not blocks:
            z3 = np.zeros((0, 3))
            return VehicleBlock(np.zeros(0), np.zeros((imus, 0, 3)), np.zeros((imus, 0, 3)), np.zeros(0, bool), z3, z3)
        temp = None if blocks[0].temperature is None else np.concatenate([b.temperature for b in blocks], axis=1)
        t_imu = None if blocks[0].t_imu is None else np.concatenate([b.t_imu for b in blocks], axis=1)
        return VehicleBlock(np.concatenate([b.t for b in blocks]), np.concatenate([b.gyro for b in blocks], axis=1),
                            np.concatenate([b.accel for b in blocks], axis=1),
                            np.concatenate([b.armed for b in blocks]),
                            np.concatenate([b.rate_true for b in blocks]), np.concatenate([b.accel_true for b in blocks]),
                            temp, t_imu)


def _misalignment(rng, max_deg: float) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    ang = math.radians(max_deg) * rng.random()
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K


# ----------------------------------------------------------------------------------------------- the simulator
class VehicleSimulator:
    """Samples of 1-3 IMUs on one vehicle, block by block (see the module docstring)."""

    BLOCK_S = 600.0

    def __init__(self, model, imus: int = 1, seed: int = 0, rate_hz: float | None = None,
                 schedule: Schedule | None = None, fault: Fault | None = None, warmup: WarmUp | None = None,
                 spread: ImuSpread | None = None, degrade: Degradation | None = None, t_start: float = 1.0,
                 rest_tilt_deg: float = 2.0, realism: Realism | None = None):
        self.rate_hz = float(model["rate_hz"] if isinstance(model, Mapping) else model.rate_hz) if rate_hz is None else float(rate_hz)
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise _err(f"rate must be > 0 Hz, got {rate_hz!r}")
        axes = model["axes"] if isinstance(model, Mapping) else model.axes
        unknown = sorted(set(axes) - set(GYRO_AXES + ACCEL_AXES))
        if unknown:
            raise _err(f"model axis {unknown[0]!r} unknown (expected gx, gy, gz, ax, ay, az)")
        self.axes = {a: [dict(t) for t in (axes.get(a) or [])] for a in GYRO_AXES + ACCEL_AXES}
        for a, terms in self.axes.items():
            for t in terms:
                try:
                    validate_term(t)
                except ValueError as exc:
                    raise _err(f"model axis {a}: {exc}") from None
                f0 = t.get("f0") if t["effect"] == "bias_instability" else None
                if f0 is not None and abs(f0 - self.rate_hz / 2.0) > 1e-9 * self.rate_hz:
                    raise _err(f"model axis {a}: bias_instability is synthesised with f0 = rate/2; omit f0 or set it so")
        if isinstance(imus, bool) or not isinstance(imus, (int, np.integer)) or not 1 <= imus <= MAX_IMUS:
            raise _err(f"number of IMUs must be 1, 2 or 3, got {imus!r}")
        self.imus = int(imus)
        self.schedule = schedule or Schedule()
        self.fault = fault
        if fault is not None:
            if fault.imu >= self.imus:
                raise _err(f"fault on IMU{fault.imu} but the vehicle has {self.imus} IMU(s) (IMU0..IMU{self.imus - 1})")
            if fault.kind == "noise" and not any(t["effect"] == "white_noise" for t in self.axes[fault.axis]):
                raise _err(f"noise fault on {fault.axis}: the model has no white_noise term there (the fault scales it)")
        self.degrade = degrade
        if degrade is not None and degrade.imu >= self.imus:
            raise _err(f"degradation on IMU{degrade.imu} but the vehicle has {self.imus} IMU(s)")
        self.warmup = warmup
        self.spread = spread or ImuSpread()
        self.t_start = _finite("t_start", t_start, lo=0.0)
        self.seed = seed
        ss = np.random.SeedSequence(seed)
        c = ss.spawn(6 + 2 * MAX_IMUS)
        rng_motion, self._rng_vib, rng_spread, self._rng_fault, rng_warm = (np.random.default_rng(x) for x in c[:5])
        self._rng_noise = [np.random.default_rng(x) for x in c[5:5 + MAX_IMUS]]
        self._rng_deg = np.random.default_rng(c[5 + MAX_IMUS])
        rng_phase = np.random.default_rng(c[6 + MAX_IMUS])
        self._phases = {(i, ax, k): float(rng_phase.uniform(0, 2 * np.pi))
                        for i in range(MAX_IMUS) for ax in GYRO_AXES + ACCEL_AXES for k in range(len(self.axes[ax]))}
        # per-IMU errors (drawn for MAX_IMUS so IMU i does not depend on the IMU count)
        sp = self.spread
        self.gyro_matrix = np.zeros((MAX_IMUS, 3, 3))
        self.accel_matrix = np.zeros((MAX_IMUS, 3, 3))
        self.gyro_bias = np.zeros((MAX_IMUS, 3))
        self.accel_bias = np.zeros((MAX_IMUS, 3))
        self.misalignment = np.zeros((MAX_IMUS, 3, 3))
        for i in range(MAX_IMUS):
            Rm = _misalignment(rng_spread, sp.misalignment_deg)
            self.misalignment[i] = Rm
            self.gyro_matrix[i] = np.diag(1.0 + rng_spread.uniform(-sp.scale, sp.scale, 3)) @ Rm
            self.accel_matrix[i] = np.diag(1.0 + rng_spread.uniform(-sp.scale, sp.scale, 3)) @ Rm
            self.gyro_bias[i] = rng_spread.normal(0.0, sp.gyro_bias, 3)
            self.accel_bias[i] = rng_spread.normal(0.0, sp.accel_bias, 3)
        amp = rng_warm.uniform(0.5, 1.0, (MAX_IMUS, 3)) * rng_warm.choice([-1.0, 1.0], (MAX_IMUS, 3))
        self.warmup_amplitude = amp * (warmup.amplitude if warmup is not None else 0.0)
        self.motion = BodyMotion(self.schedule, rng_motion, self.rate_hz, rest_tilt_deg)
        # the realistic gyro path: its own random streams (spawned after the others: old draws unchanged)
        self.realism = realism
        self._stage = None
        if realism is not None:
            if not isinstance(realism, Realism):
                raise _err("realism must be a companion.sim.realism.Realism")
            if realism.sensor_rate_hz < self.rate_hz:
                raise _err(f"sensor_rate_hz ({realism.sensor_rate_hz:g}) is below the logged rate ({self.rate_hz:g} Hz)")
            r_ch = ss.spawn(3 + MAX_IMUS)
            rng_r, rng_timing = np.random.default_rng(r_ch[0]), np.random.default_rng(r_ch[1])
            self._rng_gmb = np.random.default_rng(r_ch[2])
            self._rng_sensor = [np.random.default_rng(x) for x in r_ch[3:]]
            self.temp_slope = rng_r.normal(0.0, realism.temp_slope, (MAX_IMUS, 3))  # rad/s per K (truth)
            self._stage = SensorStage(realism, self.imus, self.t_start, rng_timing)
        # stream state
        self.t_next = self.t_start
        self._state: dict = {}  # stateful noise components at the last sample taken
        self._frozen = None  # stuck fault: the frozen value, once the first faulty sample was taken
        self._prev_raw = None  # (imus, 3) pre-fault gyro of the last sample taken
        self._blk: VehicleBlock | None = None
        self._blk_state: dict = {}
        self._blk_raw = None
        self._blk_frozen = None
        self._i = 0
        self.interval_set = False  # used by sim-autopilot: SET_MESSAGE_INTERVAL wins over REQUEST_DATA_STREAM

    # ----------------------------------------------------------------- schedule queries
    def armed_at(self, t) -> np.ndarray | bool:
        """Armed flag at time(s) since boot ``t``."""
        s = np.asarray(t, dtype=float) - self.t_start
        out = np.zeros(s.shape, dtype=bool)
        for f in self.schedule.flights:
            out |= (s >= f.arm_at) & (s < f.disarm_at)
        return bool(out) if out.ndim == 0 else out

    def set_rate(self, rate_hz: float) -> None:
        """Change the sample rate from the next sample not yet taken on (like SET_MESSAGE_INTERVAL)."""
        if rate_hz > 0 and abs(rate_hz - self.rate_hz) > 1e-9:
            self.rate_hz = float(rate_hz)
            self._blk, self._i = None, 0
            if self._stage is not None:  # the sensor clock restarts at the next sample (filter state kept)
                self._stage.k_next = int(math.floor((self.t_next - 0.1) * self._stage.fs))
                self._stage.acc = None

    # ----------------------------------------------------------------- sample production
    def take_until(self, t_end: float) -> VehicleBlock:
        """The samples with ``t <= t_end`` not taken yet (may be empty)."""
        parts = []
        while self.t_next <= t_end + 1e-12:
            if self._blk is None or self._i >= self._blk.n:
                self._make_block()
            j = int(np.searchsorted(self._blk.t, t_end + 1e-12, side="right"))
            if j > self._i:
                parts.append(self._blk[self._i:j])
                self._commit(j)
            self._i = j
            self.t_next = self._blk.t[j] if j < self._blk.n else self._blk.t[-1] + 1.0 / self.rate_hz
        return VehicleBlock.concat(parts, self.imus)

    def run(self, duration_s: float) -> VehicleBlock:
        """Everything from the current position up to ``t_start + duration_s`` (one block)."""
        return self.take_until(self.t_start + float(duration_s) - 0.5 / self.rate_hz)

    def blocks(self, duration_s: float, block_s: float = 600.0):
        """Iterate over blocks of at most ``block_s`` seconds up to ``t_start + duration_s``."""
        t_stop = self.t_start + float(duration_s) - 0.5 / self.rate_hz
        while self.t_next <= t_stop:
            yield self.take_until(min(self.t_next + block_s - 0.5 / self.rate_hz, t_stop))

    def _commit(self, j: int) -> None:
        """Samples up to index j (exclusive) of the current block were taken: remember their end state."""
        for k, arr in self._blk_state.items():
            self._state[k] = float(arr[j - 1])
        self._prev_raw = self._blk_raw[:, j - 1].copy()
        if self._blk_frozen is not None and j > self._blk_frozen[0]:
            self._frozen = self._blk_frozen[1]

    def temperature_at(self, t) -> np.ndarray:
        """(imus, n) IMU temperatures (degC) at times since boot ``t`` (with Realism; else the ambient 25 C)."""
        t = np.asarray(t, dtype=float)
        r = self.realism
        if r is None:
            return np.full((self.imus, t.shape[0]), 25.0)
        return np.array([r.ambient_c + r.temp_offset_c[i] + r.rise_c[i] * (1.0 - np.exp(-t / r.temp_tau_s[i]))
                         for i in range(self.imus)])

    def _make_block(self) -> None:
        if self.realism is not None:
            return self._make_block_real()
        n = max(1, int(round(self.BLOCK_S * self.rate_hz)))
        t = self.t_next + np.arange(n) / self.rate_hz
        s = t - self.t_start
        w, f = self.motion.sample(s, self._rng_vib)  # the body, vibration included (all IMUs see the same)
        armed = np.asarray(self.armed_at(t), dtype=bool)
        gyro = np.empty((self.imus, n, 3))
        accel = np.empty((self.imus, n, 3))
        self._blk_state = {}
        white_parts = {}
        for i in range(self.imus):
            gyro[i] = w @ self.gyro_matrix[i].T + self.gyro_bias[i]
            gyro[i] += self.warmup_amplitude[i] * np.exp(-t / (self.warmup.tau_s if self.warmup else 1.0))[:, None]
            accel[i] = f @ self.accel_matrix[i].T + self.accel_bias[i]
            rng = self._rng_noise[i]
            for j, ax in enumerate(GYRO_AXES + ACCEL_AXES):
                white, other = self._noise(i, ax, s, rng)
                if j < 3:
                    gyro[i, :, j] += white + other
                    white_parts[(i, ax)] = white
                else:
                    accel[i, :, j - 3] += white + other
            if not any(self.axes[a] for a in ACCEL_AXES):
                accel[i] += rng.normal(0.0, DEFAULT_ACCEL_NOISE, (n, 3))
        if self.degrade is not None:
            self._apply_degradation(gyro, accel, s)
        self._blk_raw = gyro.copy()
        self._blk_frozen = None
        if self.fault is not None:
            self._apply_fault(gyro, s, white_parts)
        self._blk = VehicleBlock(t, gyro, accel, armed, w, f)
        self._i = 0

    def _make_block_real(self) -> None:
        """One block through the realistic path (:mod:`companion.sim.realism`): the slow part at the logged
        rate, white noise and vibration at the sensor rate, filter, per-IMU decimation."""
        r = self.realism
        n = max(1, int(round(self.BLOCK_S * self.rate_hz)))
        t = self.t_next + np.arange(n) / self.rate_hz
        s = t - self.t_start
        w, f, env = self.motion.sample_parts(s, self._rng_vib)
        armed = np.asarray(self.armed_at(t), dtype=bool)
        slow = np.empty((self.imus, n, 3))
        accel = np.empty((self.imus, n, 3))
        white_std = np.zeros((self.imus, 3))
        self._blk_state = {}
        temp = self.temperature_at(t)
        for i in range(self.imus):
            slow[i] = w @ self.gyro_matrix[i].T + self.gyro_bias[i]
            if self.warmup is not None:
                slow[i] += self.warmup_amplitude[i] * np.exp(-t / self.warmup.tau_s)[:, None]
            slow[i] += (temp[i] - r.ambient_c)[:, None] * self.temp_slope[i]
            accel[i] = f @ self.accel_matrix[i].T + self.accel_bias[i]
            rng = self._rng_noise[i]
            for j, ax in enumerate(GYRO_AXES + ACCEL_AXES):
                if j < 3:
                    var_white, other = self._noise(i, ax, s, rng, white=False)
                    slow[i, :, j] += other
                    white_std[i, j] = math.sqrt(var_white * r.sensor_rate_hz)
                    if r.bias_gm_sigma > 0:
                        key = ("gm_bias", i, j)
                        c = self._gauss_markov(r.bias_gm_sigma, r.bias_gm_tau_s, n, self._rng_gmb, self._state.get(key))
                        self._blk_state[key] = c
                        slow[i, :, j] += c
                else:
                    white, other = self._noise(i, ax, s, rng)
                    accel[i, :, j - 3] += white + other
            if not any(self.axes[a] for a in ACCEL_AXES):
                accel[i] += rng.normal(0.0, DEFAULT_ACCEL_NOISE, (n, 3))
        if self.degrade is not None:
            self._apply_degradation(slow, accel, s)
        white_of = None
        if self.fault is not None and self.fault.kind == "noise":
            white_of = (self.fault.imu, GYRO_AXES.index(self.fault.axis))
        gyro, ts_imu, wout = self._stage.run(t, slow, white_std, env, self._rng_vib, self._rng_sensor, white_of)
        self._blk_raw = gyro.copy()
        self._blk_frozen = None
        if self.fault is not None:
            parts = {} if wout is None else {(self.fault.imu, self.fault.axis): wout}
            self._apply_fault(gyro, s, parts)
        t_imu = None
        if r.stamp == "own":  # each IMU stamped with its own sample time, to the microsecond
            t_imu = np.round(ts_imu * 1e6) / 1e6
        self._blk = VehicleBlock(t, gyro, accel, armed, w, f, temp, t_imu)
        self._i = 0

    def _noise(self, i: int, ax: str, s: np.ndarray, rng: np.random.Generator, white: bool = True):
        """(white part, everything else) of IMU i's model noise on ``ax`` at times ``s`` (since start); with
        ``white=False`` the white part is not drawn and its per-sample variance per Hz (sum of N^2) is
        returned instead."""
        n = s.shape[0]
        fs = self.rate_hz
        draw_white = white
        white = np.zeros(n) if draw_white else 0.0
        other = np.zeros(n)
        for k, term in enumerate(self.axes[ax]):
            e = term["effect"]
            key = (i, ax, k)
            if e == "white_noise":
                if draw_white:
                    white += rng.normal(0.0, term["N"] * math.sqrt(fs), n)
                else:
                    white += term["N"] ** 2
            elif e == "quantization":
                other += quantization(term["Q"], fs, n, rng)
            elif e == "bias_instability":
                other += flicker(term["B"], fs, n, rng)
            elif e == "random_walk":
                c = np.cumsum(rng.normal(0.0, term["K"] / math.sqrt(fs), n)) + self._state.get(key, 0.0)
                self._blk_state[key] = c
                other += c
            elif e == "ramp":
                other += term["R"] * s
            elif e == "gauss_markov":
                c = self._gauss_markov(term["sigma"], term["tau_c"], n, rng, self._state.get(key))
                self._blk_state[key] = c
                other += c
            elif e == "sinusoid":
                ph = self._phases[key]
                other += term["amplitude"] * np.sin(2 * np.pi * term["freq_hz"] * s + ph)
            else:  # pragma: no cover - model validation rejects it
                raise _err(f"unknown effect {e!r}")
        return white, other

    def _gauss_markov(self, sigma, tau_c, n, rng, last):
        from companion.sim.synth import gauss_markov

        y = gauss_markov(sigma, tau_c, self.rate_hz, n, rng)  # stationary start y'_0 ~ N(0, sigma^2)
        if last is None:
            return y
        phi = math.exp(-1.0 / (self.rate_hz * tau_c))
        pk = phi ** np.arange(n)
        # exact continuation: y_0 = phi*last + sqrt(1 - phi^2) y'_0, same innovations afterwards
        return y - pk * y[0] + pk * (phi * last + math.sqrt(max(1.0 - phi * phi, 0.0)) * y[0])

    def _apply_degradation(self, gyro, accel, s):
        d = self.degrade
        on = s >= d.at
        if not on.any():
            return
        term, e = d.term, d.term["effect"]
        n, fs, rng = s.shape[0], self.rate_hz, self._rng_deg
        key = ("degrade",)
        if e == "white_noise":
            extra = rng.normal(0.0, term["N"] * math.sqrt(fs), n)
        elif e == "bias_instability":
            extra = flicker(term["B"], fs, n, rng)
        elif e == "random_walk":
            extra = np.cumsum(rng.normal(0.0, term["K"] / math.sqrt(fs), n) * on) + self._state.get(key, 0.0)
            self._blk_state[key] = extra
        else:
            extra = self._gauss_markov(term["sigma"], term["tau_c"], n, rng, self._state.get(key))
            self._blk_state[key] = extra
        extra = np.where(on, extra, 0.0)
        if d.axis in GYRO_AXES:
            gyro[d.imu, :, GYRO_AXES.index(d.axis)] += extra
        else:
            accel[d.imu, :, ACCEL_AXES.index(d.axis)] += extra

    def _apply_fault(self, gyro, s, white_parts):
        fl = self.fault
        j = GYRO_AXES.index(fl.axis)
        y = gyro[fl.imu, :, j]
        on = s >= fl.at
        if not on.any():
            return
        i0 = int(np.argmax(on))
        n_on = int(on.sum())
        if fl.kind == "stuck":
            if i0 > 0:
                frozen = float(y[i0 - 1])
                self._blk_frozen = (i0, frozen)
            elif self._frozen is not None:
                frozen = self._frozen
            else:
                frozen = float(self._prev_raw[fl.imu, j]) if self._prev_raw is not None else float(y[0])
                self._blk_frozen = (0, frozen)
            dither = self._rng_fault.normal(0.0, fl.size, n_on) if fl.size > 0 else 0.0
            y[on] = frozen + dither
        elif fl.kind == "noise":
            y[on] += (fl.size - 1.0) * white_parts[(fl.imu, fl.axis)][on]
        elif fl.kind == "bias":
            y[on] += fl.size
        elif fl.kind == "spikes":
            hit = self._rng_fault.random(n_on) < fl.size
            sign = self._rng_fault.choice([-1.0, 1.0], n_on)
            y[on] += np.where(hit, sign * fl.amplitude, 0.0)
        elif fl.kind == "drift":
            y[on] += fl.size * (s[on] - fl.at)
        elif fl.kind == "saturate":
            y[on] = np.clip(y[on], -fl.size, fl.size)


# ----------------------------------------------------------------------------------------------- tlog output
def write_tlog(path, sim: VehicleSimulator, duration_s: float, sysid: int = 1, compid: int = 1,
               heartbeat_hz: float = 1.0, mavlink2: bool = True, t0_unix: float = 1.7e9,
               block_s: float = 600.0) -> dict:
    """Write ``duration_s`` of the simulator to a tlog as an ArduPilot autopilot would send it.

    IMU0 as RAW_IMU (``time_usec``), IMU1 as SCALED_IMU2, IMU2 as SCALED_IMU3 (``time_boot_ms``), gyro
    int16 mrad/s and accel int16 mG, rounded to the nearest LSB and clipped to int16; a HEARTBEAT every
    ``1/heartbeat_hz`` s of simulated time from the first sample on, with the armed bit (``base_mode``
    128) set while a flight is armed. Written block by block (constant memory). The encoder is
    :mod:`companion.mavlink.tlog_writer`'s. Returns counts ``{"imu_messages", "heartbeats"}``.
    """
    from companion.mavlink.tlog_writer import ImuTlogStream

    duration_s = _finite("duration (s)", duration_s, lo=0.0, lo_open=True)
    counts = {"imu_messages": 0, "heartbeats": 0}
    next_hb = sim.t_next
    with ImuTlogStream(path, sysid=sysid, compid=compid, mavlink2=mavlink2, t0_unix=t0_unix) as out:
        for blk in sim.blocks(duration_s, block_s):
            if blk.n == 0:
                continue
            hb = []
            if heartbeat_hz > 0:
                t_last = blk.t[-1]
                while next_hb <= t_last:
                    hb.append(next_hb)
                    next_hb += 1.0 / heartbeat_hz
            hb = np.asarray(hb)
            streams = [(IMU_MESSAGES[i], i, *blk.imu(i)) + (() if blk.temperature is None else (blk.temperature[i],))
                       for i in range(sim.imus)]
            out.write(streams, hb, np.asarray(sim.armed_at(hb), dtype=bool).reshape(-1))
            counts["imu_messages"] += blk.n * sim.imus
            counts["heartbeats"] += hb.size
    return counts


__all__ = ["VehicleSimulator", "VehicleBlock", "Fault", "Degradation", "Flight", "Handling", "Schedule", "WarmUp",
           "ImuSpread", "write_tlog", "FAULT_KINDS", "FAULT_SIZE_UNITS", "FAULT_DEFAULT_SIZE", "IMU_MESSAGES",
           "rotation_nb", "body_rates", "specific_force_at_rest"]
