"""The realistic simulator's per-IMU low-pass (Realism.imu_lpf_hz) and vibration through each IMU's mounting
(Realism.vibration_mounted): what the in-flight noise benchmark relies on."""

from __future__ import annotations

import numpy as np
import pytest

from companion.errors import CompanionError
from companion.sim.body_motion import Flight, Schedule
from companion.sim.realism import Realism
from companion.sim.vehicle import ImuSpread, VehicleSimulator

MODEL = {"rate_hz": 200.0, "axes": {a: [{"effect": "white_noise", "N": 1e-5}] for a in ("gx", "gy", "gz")}}


def _sim(**kw):
    real = Realism(sensor_rate_hz=1000.0, flight={"rotor_hz": 0.0, "broadband": 0.3}, idle={"broadband": 0.3}, **kw)
    sim = VehicleSimulator(MODEL, imus=2, seed=3, realism=real, schedule=Schedule(flights=[Flight(5.0, 125.0)]),
                           spread=ImuSpread(scale=0.02, misalignment_deg=1.0))
    blk = sim.run(120.0)
    on = blk.armed
    return sim, blk.gyro[0][on], blk.gyro[1][on]


def _band_power(x, lo, hi, fs=200.0):
    f = np.fft.rfftfreq(x.shape[0], 1 / fs)
    p = np.abs(np.fft.rfft(x - x.mean())) ** 2
    return p[(f >= lo) & (f < hi)].sum()


def test_each_imu_has_its_own_cutoff():
    _, g0, g1 = _sim(imu_lpf_hz=(10.0, 60.0, 60.0))
    # 40-80 Hz: far above IMU 0's 10 Hz cut-off, below IMU 1's 60 Hz
    assert _band_power(g0[:, 0], 40, 80) < 0.05 * _band_power(g1[:, 0], 40, 80)
    assert _band_power(g0[:, 0], 0.5, 3) == pytest.approx(_band_power(g1[:, 0], 0.5, 3), rel=0.2)


def test_mounted_vibration_follows_the_imus_relative_mounting():
    """With the vibration mounted, the vibration-dominated difference w_1 - M w_0 (M = C_1 C_0^-1) is far
    smaller than with the vibration added after the mounting."""
    out = []
    for mounted in (False, True):
        sim, g0, g1 = _sim(vibration_mounted=mounted)
        m = sim.gyro_matrix[1] @ np.linalg.inv(sim.gyro_matrix[0])
        out.append(np.var(g1 - g0 @ m.T - (g1 - g0 @ m.T).mean(axis=0)))
    assert out[1] < 0.2 * out[0]


def test_bad_per_imu_cutoffs_are_one_error_line():
    with pytest.raises(CompanionError, match="imu_lpf_hz"):
        Realism(imu_lpf_hz=(10.0, 20.0))
    with pytest.raises(CompanionError, match="imu_lpf_hz"):
        Realism(imu_lpf_hz=(10.0, 20.0, 900.0))
