"""Each IMU's own errors on a shared rigid body: mounting misalignment, scale factor, constant bias and the
cold-start warm-up drift amplitude, drawn once per simulator (numpy only).

The gyro of IMU ``i`` sees the body rate ``w`` as ``C_i w + b_i`` with ``C_i = (I + diag(s_i)) R(m_i)``:
``s_i`` uniform in +-``ImuSpread.scale`` per axis, ``R(m_i)`` a rotation by an angle uniform in
[0, ``ImuSpread.misalignment_deg``] about a uniformly random axis (Rodrigues' formula), ``b_i`` normal with
std ``ImuSpread.gyro_bias``. The accelerometer shares the mounting rotation and has its own scale and bias.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.sim.vehicle_spec import MAX_IMUS, ImuSpread, WarmUp


def misalignment_rotation(rng: np.random.Generator, max_deg: float) -> np.ndarray:
    """A rotation matrix by an angle uniform in [0, ``max_deg``] about a random unit axis ``k``:
    ``R = I + sin(a) K + (1 - cos(a)) K^2`` with ``K`` the cross-product matrix of ``k`` (Rodrigues)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    ang = math.radians(max_deg) * rng.random()
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K


@dataclass(frozen=True)
class ImuErrors:
    """The drawn errors of ``MAX_IMUS`` IMUs (drawn for all of them, so IMU i does not depend on the count)."""

    misalignment: np.ndarray  # (MAX_IMUS, 3, 3) mounting rotation R(m_i)
    gyro_matrix: np.ndarray  # (MAX_IMUS, 3, 3) C_i = (I + diag(s_i)) R(m_i)
    accel_matrix: np.ndarray  # (MAX_IMUS, 3, 3) the accelerometer's own scale on the same rotation
    gyro_bias: np.ndarray  # (MAX_IMUS, 3) rad/s
    accel_bias: np.ndarray  # (MAX_IMUS, 3) m/s^2

    @classmethod
    def draw(cls, spread: ImuSpread, rng: np.random.Generator) -> "ImuErrors":
        """IMU by IMU: rotation, gyro scale, accel scale, gyro bias, accel bias (this draw order is the seed's
        contract: the same seed gives the same vehicle)."""
        out = {k: np.zeros((MAX_IMUS, 3, 3)) for k in ("misalignment", "gyro_matrix", "accel_matrix")}
        out.update({k: np.zeros((MAX_IMUS, 3)) for k in ("gyro_bias", "accel_bias")})
        for i in range(MAX_IMUS):
            Rm = misalignment_rotation(rng, spread.misalignment_deg)
            out["misalignment"][i] = Rm
            out["gyro_matrix"][i] = np.diag(1.0 + rng.uniform(-spread.scale, spread.scale, 3)) @ Rm
            out["accel_matrix"][i] = np.diag(1.0 + rng.uniform(-spread.scale, spread.scale, 3)) @ Rm
            out["gyro_bias"][i] = rng.normal(0.0, spread.gyro_bias, 3)
            out["accel_bias"][i] = rng.normal(0.0, spread.accel_bias, 3)
        return cls(**out)


def warmup_amplitudes(warmup: WarmUp | None, rng: np.random.Generator) -> np.ndarray:
    """(MAX_IMUS, 3) signed warm-up amplitudes a_ij, rad/s: ``|a_ij|`` uniform in [A/2, A], random sign (A the
    warm-up amplitude; zeros without a warm-up)."""
    amp = rng.uniform(0.5, 1.0, (MAX_IMUS, 3)) * rng.choice([-1.0, 1.0], (MAX_IMUS, 3))
    return amp * (warmup.amplitude if warmup is not None else 0.0)
