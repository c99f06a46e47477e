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


def _realism(fmt: str, rng, gains, vibration: float, max_offset_s: float):
    from companion.sim.realism import Realism

    rate, fs, (f_lo, f_hi), lsb = FORMATS[fmt]
    fc = tuple(float(x) for x in rng.uniform(f_lo, f_hi, 3))
    skew = (0.0,) + tuple(float(x) for x in rng.uniform(0.0, max_offset_s, 2))
    vib = {"rotor_hz": 111.0, "harmonics": [0.3 * vibration, 0.15 * vibration], "broadband": 0.1 * vibration,
           "wander": 0.05}
    idle = {"rotor_hz": 60.0, "harmonics": [0.05 * vibration], "broadband": 0.02 * vibration}
    return Realism(sensor_rate_hz=fs, gyro_lpf_hz=fc[0], imu_lpf_hz=fc, imu_noise_gain=tuple(gains), skew_s=skew,
                   flight=vib, idle=idle, vibration_mounted=True), fc, skew


def draw_flight(seed: int, fmt: str = "log400", imus: int = 3, flight_s: float = 600.0, n_lo: float = 0.5,
                n_hi: float = 3.0, spread: float = 0.005, max_offset_s: float = 0.002, vibration: float = 1.0,
                still_s: float = 0.0) -> FlightDraw:
    """One random flight (module docstring); ``still_s`` seconds disarmed before arming."""
    from companion.sim.body_motion import Flight, Schedule
    from companion.sim.vehicle import ImuSpread, VehicleSimulator

    rng = np.random.default_rng([seed, 4711])
    rate, _, _, lsb = FORMATS[fmt]
    gains = rng.uniform(n_lo, n_hi, 3)
    model = {"rate_hz": rate, "axes": {a: [{"effect": "white_noise", "N": DEG_SQRT_H},
                                           {"effect": "bias_instability", "B": 3e-6}] for a in ("gx", "gy", "gz")}}
    real, fc, skew = _realism(fmt, rng, gains, vibration, max_offset_s)
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
                      [(sim.t_start, t0 - 1.0)] if still_s else [])
