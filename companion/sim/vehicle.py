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
                                       ImuSpread, Degradation)
    from companion.mavlink.vehicle_tlog import write_tlog   # the MAVLink encoding, an adapter

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

    # realistic autopilot data (companion.sim.realism): sensor-rate noise and vibration, the gyro low-pass,
    # decimation, per-IMU skew, temperature bias; blk.temperature (imus, n) degC, blk.t_imu (own stamps)
    VehicleSimulator(model, imus=3, realism=load_preset("copter")["realism"])
    sim.temp_slope[i]                # IMU i's drawn bias-vs-temperature slopes, rad/s per K

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

The body (:mod:`companion.sim.body_motion`): at rest the vehicle sits still at a small tilt; a :class:`Flight`
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

from companion.allan.terms import validate_term
from companion.sim.imu_errors import ImuErrors, warmup_amplitudes
from companion.sim.body_motion import (BodyMotion, Flight, Handling, Schedule, _err, _finite, body_rates,
                                   rotation_nb, specific_force_at_rest)
from companion.sim.realism import Realism, SensorStage
from companion.sim.synth import flicker, quantization
from companion.sim.vehicle_block import VehicleBlock
from companion.sim.vehicle_spec import (ACCEL_AXES, FAULT_DEFAULT_SIZE, FAULT_KINDS, FAULT_SIZE_UNITS, GYRO_AXES,
                                        IMU_MESSAGES, MAX_IMUS, Degradation, Fault, ImuSpread, WarmUp)

DEFAULT_ACCEL_NOISE = 0.02  #: m/s^2 per-sample std, so that an accelerometer the model leaves out is not noise-free



@dataclass(frozen=True)
class _FrozenAt:
    """A stuck fault's frozen value, first in force at sample ``index`` of the current block."""

    index: int
    value: float


# ----------------------------------------------------------------------------------------------- the simulator
class VehicleSimulator:
    """Samples of 1-3 IMUs on one vehicle, block by block (see the module docstring)."""

    BLOCK_S = 600.0  #: s per internal block: flicker noise is synthesised per block, memory stays bounded

    def __init__(self, model, imus: int = 1, seed: int = 0, rate_hz: float | None = None,
                 schedule: Schedule | None = None, fault: Fault | None = None, warmup: WarmUp | None = None,
                 spread: ImuSpread | None = None, degrade: Degradation | None = None, t_start: float = 1.0,
                 rest_tilt_deg: float = 2.0, realism: Realism | None = None):
        self._load_model(model, rate_hz)
        if isinstance(imus, bool) or not isinstance(imus, (int, np.integer)) or not 1 <= imus <= MAX_IMUS:
            raise _err(f"number of IMUs must be 1, 2 or 3, got {imus!r}")
        self.imus = int(imus)
        self.schedule = schedule or Schedule()
        self._check_fault(fault, degrade)
        self.fault = fault
        self.degrade = degrade
        self.warmup = warmup
        self.spread = spread or ImuSpread()
        self.t_start = _finite("t_start", t_start, lo=0.0)
        self.seed = seed
        ss = np.random.SeedSequence(seed)
        rng_motion, rng_spread, rng_warm = self._seed_streams(ss)
        errors = ImuErrors.draw(self.spread, rng_spread)
        self.gyro_matrix, self.accel_matrix = errors.gyro_matrix, errors.accel_matrix
        self.gyro_bias, self.accel_bias = errors.gyro_bias, errors.accel_bias
        self.misalignment = errors.misalignment
        self.warmup_amplitude = warmup_amplitudes(warmup, rng_warm)
        self.motion = BodyMotion(self.schedule, rng_motion, self.rate_hz, rest_tilt_deg)
        self.realism = realism
        self._stage = None
        if realism is not None:
            self._init_realism(realism, ss)
        self._reset_stream()

    def _load_model(self, model, rate_hz: float | None) -> None:
        """``self.rate_hz`` and ``self.axes`` (every axis, its terms validated) from a model mapping or object."""
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

    def _check_fault(self, fault: Fault | None, degrade: Degradation | None) -> None:
        """The fault and the degradation must sit on an IMU the vehicle has (a noise fault on a white term)."""
        if fault is not None:
            if fault.imu >= self.imus:
                raise _err(f"fault on IMU{fault.imu} but the vehicle has {self.imus} IMU(s) (IMU0..IMU{self.imus - 1})")
            if fault.kind == "noise" and not any(t["effect"] == "white_noise" for t in self.axes[fault.axis]):
                raise _err(f"noise fault on {fault.axis}: the model has no white_noise term there (the fault scales it)")
        if degrade is not None and degrade.imu >= self.imus:
            raise _err(f"degradation on IMU{degrade.imu} but the vehicle has {self.imus} IMU(s)")

    def _seed_streams(self, ss: np.random.SeedSequence):
        """The random streams, each a child of ``ss`` in a fixed order (so a seed gives the same vehicle and IMU
        0's noise does not depend on the IMU count); returns the (motion, spread, warm-up) generators used only
        while constructing."""
        c = ss.spawn(6 + 2 * MAX_IMUS)
        rng_motion, self._rng_vib, rng_spread, self._rng_fault, rng_warm = (np.random.default_rng(x) for x in c[:5])
        self._rng_noise = [np.random.default_rng(x) for x in c[5:5 + MAX_IMUS]]
        self._rng_deg = np.random.default_rng(c[5 + MAX_IMUS])
        rng_phase = np.random.default_rng(c[6 + MAX_IMUS])
        self._phases = {(i, ax, k): float(rng_phase.uniform(0, 2 * np.pi))
                        for i in range(MAX_IMUS) for ax in GYRO_AXES + ACCEL_AXES for k in range(len(self.axes[ax]))}
        return rng_motion, rng_spread, rng_warm

    def _init_realism(self, realism: Realism, ss: np.random.SeedSequence) -> None:
        """The realistic gyro path: its own random streams, spawned after the others so that the streams of
        the plain path stay the same for a seed."""
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
        self._stage.mounts = self.gyro_matrix

    def _reset_stream(self) -> None:
        """Nothing taken yet: the position, the noise state carried between blocks, the current block."""
        self.t_next = self.t_start
        self._state: dict = {}  # stateful noise components at the last sample taken
        self._frozen = None  # stuck fault: the frozen value, once the first faulty sample was taken
        self._prev_raw = None  # (imus, 3) pre-fault gyro of the last sample taken
        self._blk: VehicleBlock | None = None
        self._blk_state: dict = {}
        self._blk_raw = None
        self._blk_frozen: _FrozenAt | None = None
        self._i = 0
        self.interval_set = False  # sim-autopilot: a SET_MESSAGE_INTERVAL wins over REQUEST_DATA_STREAM


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
        if self._blk_frozen is not None and j > self._blk_frozen.index:
            self._frozen = self._blk_frozen.value

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
        if self.fault is not None and self.fault.kind in ("noise", "flight_noise"):
            white_of = (self.fault.imu, GYRO_AXES.index(self.fault.axis), self.fault.kind == "flight_noise")
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
                self._blk_frozen = _FrozenAt(i0, frozen)
            elif self._frozen is not None:
                frozen = self._frozen
            else:
                frozen = float(self._prev_raw[fl.imu, j]) if self._prev_raw is not None else float(y[0])
                self._blk_frozen = _FrozenAt(0, frozen)
            dither = self._rng_fault.normal(0.0, fl.size, n_on) if fl.size > 0 else 0.0
            y[on] = frozen + dither
        elif fl.kind in ("noise", "flight_noise"):  # flight_noise: the vibration pick-up is in the part too
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


__all__ = ["VehicleSimulator", "VehicleBlock", "Fault", "Degradation", "Flight", "Handling", "Schedule", "WarmUp",
           "ImuSpread", "FAULT_KINDS", "FAULT_SIZE_UNITS", "FAULT_DEFAULT_SIZE", "IMU_MESSAGES",
           "rotation_nb", "body_rates", "specific_force_at_rest"]
