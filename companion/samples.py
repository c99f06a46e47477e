"""Plain containers for IMU samples: what every reader produces and every analysis consumes.

No I/O and no pymavlink here. Everything is SI: time in seconds (from the message's own timestamp,
never arrival time), gyro in rad/s, accel in m/s^2, temperature in degC.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

GYRO_AXES = ("gx", "gy", "gz")  #: gyro axes, rad/s
ACCEL_AXES = ("ax", "ay", "az")  #: accelerometer axes, m/s^2
AXES = GYRO_AXES + ACCEL_AXES


@dataclass(frozen=True, order=True)
class StreamKey:
    """Identity of one IMU stream: every IMU instance of every vehicle is its own stream.

    ``message`` is the MAVLink message name (``RAW_IMU``, ``SCALED_IMU``, ``SCALED_IMU2``,
    ``SCALED_IMU3``, ``HIGHRES_IMU``) or ``CSV`` for a CSV file; ``instance`` is the IMU number
    (RAW_IMU/HIGHRES_IMU ``id`` extension, 0 for SCALED_IMU, 1 for SCALED_IMU2, 2 for SCALED_IMU3).
    """

    sysid: int
    compid: int
    message: str
    instance: int

    def label(self) -> str:
        return f"{self.message}[{self.instance}] sys{self.sysid}/comp{self.compid}"


@dataclass
class TimingReport:
    """What the time base of a stream looked like, counted, never silently repaired."""

    rate_hz: float = float("nan")  # detected nominal sample rate (median of intervals)
    duration_s: float = 0.0  # sum of the durations of all segments
    gaps: int = 0  # intervals longer than 1.5x the nominal period (within a segment or splitting one)
    duplicates: int = 0  # samples with the same timestamp as the previous one (dropped)
    backwards: int = 0  # timestamps going backwards by a little (dropped)
    resets: int = 0  # timestamps jumping far back: autopilot reboot (starts a new segment)
    jitter_rms: float = 0.0  # rms deviation of intervals from the nominal period, in seconds
    damaged: int = 0  # samples with a non-finite time, an infinite value or a NaN gyro value (dropped)


@dataclass
class ImuStream:
    """The samples of one IMU stream in SI units.

    ``t`` is strictly increasing within each segment; ``segments`` are half-open index ranges
    ``(start, stop)`` into the arrays, split at autopilot reboots (time resets) and long gaps.
    ``is_imu`` is False for a SCALED_IMU2/3 that only carries a compass (accel and gyro all zero).
    """

    key: StreamKey
    t: np.ndarray  # (n,) float64 seconds
    gyro: np.ndarray  # (n, 3) float64 rad/s
    accel: np.ndarray  # (n, 3) float64 m/s^2
    temperature: np.ndarray | None = None  # (n,) degC or None
    is_imu: bool = True
    segments: list[tuple[int, int]] = field(default_factory=list)
    timing: TimingReport = field(default_factory=TimingReport)
    gyro_lsb: float | None = None  # quantisation step of the gyro values in rad/s, if the format has one
    accel_lsb: float | None = None  # quantisation step of the accel values in m/s^2, if the format has one

    @property
    def samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def rate_hz(self) -> float:
        return self.timing.rate_hz

    def axis(self, name: str) -> np.ndarray:
        """One axis by its canonical name: gx, gy, gz (rad/s) or ax, ay, az (m/s^2)."""
        if name in GYRO_AXES:
            return self.gyro[:, GYRO_AXES.index(name)]
        if name in ACCEL_AXES:
            return self.accel[:, ACCEL_AXES.index(name)]
        raise KeyError(f"unknown axis {name!r}; expected one of {', '.join(AXES)}")

    def longest_segment(self) -> tuple[int, int]:
        if not self.segments:
            return (0, self.samples)
        return max(self.segments, key=lambda s: s[1] - s[0])
