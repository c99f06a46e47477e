"""Gyro bias against IMU temperature, learned from still blocks, so that a warm-up is not taken for a fault.

A MEMS gyro's bias moves with its temperature (MPU-6000: up to +-20 deg/s over -40..85 degC, typically a
few hundredths of a deg/s per K; BMI088 0.015 deg/s/K): a cold IMU warming by 10-25 K after power-up or
in flight moves its still bias by tenths of a deg/s to over 1 deg/s. Where the log carries the IMU
temperature, the bias tests judge the *residual* after a regression of the still-block means on it.

The slope is learned from pairs of still blocks ``LAG`` still blocks apart (differences, so the bias'
unknown offset and any slow wander common to both drop out), only from pairs whose temperature differs
by at least ``MIN_DT`` K, by least squares through the origin:

    s = sum(dT dx) / sum(dT^2),   shrunk by sum(dT^2) / (sum(dT^2) + SHRINK_K2)

Why differences with a temperature threshold: a real drift while the temperature stands still (a pair
with dT ~ 0 and dx = the drift) carries no weight, so a drift that the temperature does not explain stays
in the residual and is found; a drift that happens to coincide with a warm-up is absorbed only up to the
largest physical slope ``s_max`` (rad/s/K, configurable; clipped). The correction of a block is
s (T - T0), T0 the mean temperature of the reference period (the bias tests' reference is the mean there).

Pure math; no I/O.
"""

from __future__ import annotations

import math
from typing import Mapping

LAG = 30  # still blocks between the two blocks of a pair (30 s of 1 s blocks)
MIN_DT = 0.5  # K: pairs closer in temperature say nothing about the slope (they would carry drift and wander)
SHRINK_K2 = 4.0  # K^2: the slope is shrunk towards 0 until pairs span a few K (sum of dT^2 >> 4 K^2)


class ThermalBias:
    """Linear bias-temperature model of one gyro axis (see the module docstring)."""

    def __init__(self, s_max: float):
        self.s_max = float(s_max)  # rad/s/K
        self.sxx = 0.0  # sum of dT^2 over the pairs used
        self.sxy = 0.0  # sum of dT dx
        self.pairs = 0
        self._t0_sum = 0.0
        self._t0_n = 0

    @property
    def t0(self) -> float:
        """Mean temperature of the reference period (nan without temperature)."""
        return self._t0_sum / self._t0_n if self._t0_n else math.nan

    def add_reference(self, temp: float) -> None:
        """One block of the reference period (its mean temperature, degC; nan: none)."""
        if math.isfinite(temp):
            self._t0_sum += temp
            self._t0_n += 1

    def add_pair(self, dx: float, dtemp: float) -> None:
        """Two still blocks ``LAG`` apart: their mean-rate and temperature differences (later minus earlier)."""
        if not (math.isfinite(dx) and math.isfinite(dtemp)) or abs(dtemp) < MIN_DT:
            return
        self.sxx += dtemp * dtemp
        self.sxy += dtemp * dx
        self.pairs += 1

    @property
    def slope(self) -> float:
        """The bias-temperature slope used (rad/s/K): shrunk while the temperature span is small, within +-s_max."""
        if self.sxx <= 0.0 or not self.s_max > 0:
            return 0.0
        s = self.sxy / (self.sxx + SHRINK_K2)
        return min(max(s, -self.s_max), self.s_max)

    def correction(self, temp: float) -> float:
        """The bias the temperature explains at ``temp`` against the reference period (rad/s; 0 without it)."""
        t0 = self.t0
        if not (math.isfinite(temp) and math.isfinite(t0)):
            return 0.0
        return self.slope * (temp - t0)

    def state_dict(self) -> dict:
        return {"sxx": self.sxx, "sxy": self.sxy, "pairs": self.pairs, "t0_sum": self._t0_sum, "t0_n": self._t0_n}

    def load_state_dict(self, d: Mapping) -> None:
        self.sxx, self.sxy = float(d.get("sxx", 0.0)), float(d.get("sxy", 0.0))
        self.pairs = int(d.get("pairs", 0))
        self._t0_sum, self._t0_n = float(d.get("t0_sum", 0.0)), int(d.get("t0_n", 0))
