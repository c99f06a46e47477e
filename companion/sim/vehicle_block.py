"""The samples a :class:`companion.sim.vehicle.VehicleSimulator` produces: all IMUs at common times (numpy only)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
