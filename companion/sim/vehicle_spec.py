"""What a simulated vehicle is made of and what can go wrong with it: the per-IMU spread, the warm-up drift, a
growing noise term and the injected gyro fault (frozen dataclasses, checked on construction; numpy only).

:class:`companion.sim.vehicle.VehicleSimulator` takes these; they are re-exported from
:mod:`companion.sim.vehicle`, the documented place to import them from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from companion.sim.body_motion import _err, _finite

GYRO_AXES = ("gx", "gy", "gz")
ACCEL_AXES = ("ax", "ay", "az")
MAX_IMUS = 3  #: an ArduPilot autopilot logs and sends at most three IMUs (RAW_IMU, SCALED_IMU2, SCALED_IMU3)
#: MAVLink message of each IMU index in a tlog or on the link (ArduPilot's convention)
IMU_MESSAGES = ("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")

FAULT_KINDS = ("stuck", "noise", "bias", "spikes", "drift", "saturate", "flight_noise")  #: the injectable gyro faults
#: what ``Fault.size`` means for each kind (SI)
FAULT_SIZE_UNITS = {
    "stuck": "std in rad/s of a dither added to the frozen value (0: exactly frozen)",
    "noise": "factor on the axis' white-noise std (e.g. 6: six times noisier)",
    "bias": "step in rad/s added to the output (signed)",
    "spikes": "fraction of samples (0-1] hit by a +-amplitude outlier",
    "drift": "ramp in rad/s per s added from the fault on (signed)",
    "saturate": "clip level in rad/s: the output is limited to +-size",
    "flight_noise": "factor on the axis' own noise: its white noise and its pick-up of the frame's vibration",
}
#: each kind's size when none is given (``Fault(size=None)``, ``--fault`` without ``--fault-size``)
FAULT_DEFAULT_SIZE = {"stuck": 0.0, "noise": 6.0, "bias": math.radians(1.0), "spikes": 0.005,
                      "drift": 1e-4, "saturate": 0.5, "flight_noise": 2.0}


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
    - ``flight_noise``: as ``noise``, and with :class:`companion.sim.realism.Realism` what the IMU picks up
      of the frame's vibration (its ``imu_vibration_gain``) is multiplied by ``size`` too: the IMU's own
      output beyond the body's rotation grows in flight (a loosened or damaged mount), not only at rest.

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
        if self.kind in ("stuck", "noise", "flight_noise"):
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
                "drift": " rad/s/s", "saturate": " rad/s clip",
                "flight_noise": "x own noise"}[self.kind]
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

