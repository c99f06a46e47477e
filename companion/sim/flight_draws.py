"""Random simulated flights of a vehicle with 2-3 IMUs and known per-IMU truth, for the in-flight noise
benchmark and tests (numpy and scipy only).

A draw (:func:`draw_flight`): per-IMU white noise N uniform in [n_lo, n_hi] deg/sqrt(h) (the same on the three
axes), a small bias instability, scale-factor and misalignment errors up to ``spread`` (fraction; the
misalignment angle up to the same in rad), per-IMU time offsets uniform in [0, ``max_offset_s``], per-IMU
low-pass cut-offs, vibration (rotor lines and broadband) through each IMU's mounting, and a flight of
``flight_s`` seconds. Two formats: ``"log400"`` (a 400 Hz float log from a 2 kHz sensor, 2-pole cut-offs
20-30 Hz) and ``"tlm50"`` (50 Hz telemetry rounded to int16 mrad/s from a 1 kHz sensor, cut-offs 8-12 Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DEG_SQRT_H = math.radians(1.0) / 60.0  #: 1 deg/sqrt(h) in rad/s/sqrt(Hz)
FORMATS = {
    # rate, sensor rate, cut-off range (Hz), LSB (rad/s, 0: float)
    "log400": (400.0, 2000.0, (20.0, 30.0), 0.0),
    "tlm50": (50.0, 1000.0, (8.0, 12.0), 1e-3),
}


@dataclass
class FlightDraw:
    """One simulated flight: ``t`` (n,), ``gyro`` (imus, n, 3) rad/s, ``rate_hz``, per-IMU ``n_true``
    (rad/s/sqrt(Hz)), ``filter_hz`` and ``offset_s``, the ``lsb``, and the flight's ``intervals`` ((t0, t1)
    in the air), ``ground`` (armed on the ground, motors idling) and ``still`` (disarmed)."""

    t: np.ndarray
    gyro: np.ndarray
    rate_hz: float
    n_true: np.ndarray
    filter_hz: np.ndarray
    offset_s: np.ndarray
    lsb: float
    intervals: list
    ground: list
    still: list
    sensor_hz: float = 0.0
    broadband: float = 0.0

    def alias_floor(self) -> np.ndarray:
        """Per IMU, the white-noise level (N^2, (rad/s)^2/Hz, per axis) that the frame's broadband vibration adds
        to its share of the pair differences by aliasing, and that no calibration of the logged streams can
        cancel (:func:`alias_floor`); 0 for a float log whose filters leave nothing above the Nyquist frequency."""
        return alias_floor(self.filter_hz, self.offset_s, self.rate_hz, self.sensor_hz, self.broadband)


def _alias_response(fc: float, offset_s: float, rate_hz: float, sensor_hz: float) -> np.ndarray:
    """The gain (complex) with which an IMU's logged samples take the vibration at each multiple k rate_hz
    (0 < |k rate_hz| < sensor_hz / 2) down to 0 Hz: its 2-pole low-pass at the sensor rate and the phase of its
    sampling instant (the newest sensor sample at t + offset)."""
    from scipy import signal

    b, a = signal.butter(2, fc, fs=sensor_hz)
    kmax = int(np.floor(0.5 * sensor_hz / rate_hz - 1e-9))
    ks = np.array([k for k in range(-kmax, kmax + 1) if k != 0])
    f = ks * rate_hz
    _, h = signal.freqz(b, a, worN=2 * np.pi * np.abs(f) / sensor_hz)
    h = np.where(ks < 0, np.conj(h), h)
    te = np.floor(offset_s * sensor_hz + 1e-9) / sensor_hz
    return h * np.exp(2j * np.pi * f * te)


def alias_floor(filter_hz, offset_s, rate_hz: float, sensor_hz: float, broadband: float) -> np.ndarray:
    """Per IMU, the aliased broadband vibration's share (N^2 units, (rad/s)^2/Hz) that the pair differences keep.

    Vibration at k rate_hz +- f lands at f in the logged samples; two IMUs with different filters or sampling
    instants take it with different gains and phases, while the body's rotation at f itself (which the
    relative calibration matches) reaches both alike: at f -> 0 the difference of a pair keeps
    E_ab = S sum_k |G_a(k) - G_b(k)|^2 (S = broadband^2 / sensor_hz, the vibration's two-sided PSD), a white
    level no calibration of the logged streams can separate from the IMUs' own noise. Its share per IMU is the
    three-cornered hat of the E_ab (with two IMUs: E_01 for both, the pair's excess)."""
    n = len(filter_hz)
    if broadband <= 0 or sensor_hz <= 2 * rate_hz or n < 2:
        return np.zeros(n)
    S = broadband ** 2 / sensor_hz
    g = [_alias_response(float(filter_hz[i]), float(offset_s[i]), rate_hz, sensor_hz) for i in range(n)]
    E = {(i, j): S * float(np.sum(np.abs(g[i] - g[j]) ** 2)) for i in range(n) for j in range(n) if i < j}
    if n == 2:
        return np.array([E[(0, 1)], E[(0, 1)]])
    out = np.empty(n)
    for i in range(n):
        j, k = [x for x in range(n) if x != i]
        out[i] = (E[tuple(sorted((i, j)))] + E[tuple(sorted((i, k)))] - E[(j, k)]) / 2.0
    return out


def _realism(fmt: str, rng, gains, vibration: float, max_offset_s: float, broadband: float = 1.0):
    from companion.sim.realism import Realism

    rate, fs, (f_lo, f_hi), lsb = FORMATS[fmt]
    fc = tuple(float(x) for x in rng.uniform(f_lo, f_hi, 3))
    skew = (0.0,) + tuple(float(x) for x in rng.uniform(0.0, max_offset_s, 2))
    vib = {"rotor_hz": 111.0, "harmonics": [0.3 * vibration, 0.15 * vibration], "broadband": 0.1 * vibration * broadband,
           "wander": 0.05}
    idle = {"rotor_hz": 60.0, "harmonics": [0.05 * vibration], "broadband": 0.02 * vibration}
    return Realism(sensor_rate_hz=fs, gyro_lpf_hz=fc[0], imu_lpf_hz=fc, imu_noise_gain=tuple(gains), skew_s=skew,
                   flight=vib, idle=idle, vibration_mounted=True), fc, skew


def draw_flight(seed: int, fmt: str = "log400", imus: int = 3, flight_s: float = 600.0, n_lo: float = 0.5,
                n_hi: float = 3.0, spread: float = 0.005, max_offset_s: float = 0.002, vibration: float = 1.0,
                still_s: float = 0.0, broadband: float = 1.0) -> FlightDraw:
    """One random flight (module docstring); ``still_s`` seconds disarmed before arming; ``broadband`` scales the
    flight's broadband vibration alone (0: rotor lines only)."""
    from companion.sim.body_motion import Flight, Schedule
    from companion.sim.vehicle import ImuSpread, VehicleSimulator

    rng = np.random.default_rng([seed, 4711])
    rate, _, _, lsb = FORMATS[fmt]
    gains = rng.uniform(n_lo, n_hi, 3)
    model = {"rate_hz": rate, "axes": {a: [{"effect": "white_noise", "N": DEG_SQRT_H},
                                           {"effect": "bias_instability", "B": 3e-6}] for a in ("gx", "gy", "gz")}}
    real, fc, skew = _realism(fmt, rng, gains, vibration, max_offset_s, broadband)
    arm = 5.0 + still_s
    sched = Schedule(flights=[Flight(arm_at=arm, disarm_at=arm + flight_s + 40.0)])
    sim = VehicleSimulator(model, imus=imus, seed=seed, realism=real, schedule=sched,
                           spread=ImuSpread(scale=spread, misalignment_deg=math.degrees(spread)))
    blk = sim.run(arm + flight_s + 50.0)
    gyro = np.array([blk.gyro[i] for i in range(imus)])
    if lsb:
        gyro = np.round(gyro / lsb) * lsb
    t0 = sim.t_start + arm
    return FlightDraw(blk.t, gyro, rate, gains[:imus] * DEG_SQRT_H, np.array(fc[:imus]), np.array(skew[:imus]),
                      lsb, [(t0 + 25.0, t0 + flight_s + 15.0)], [(t0 + 1.0, t0 + 4.0)],
                      [(sim.t_start, t0 - 1.0)] if still_s else [], real.sensor_rate_hz,
                      float(real.flight.broadband))
