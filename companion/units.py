"""Datasheet units, used only at the edges (tables, plots, NAMED_VALUE_FLOAT). SI everywhere inside.

Each factor converts the SI value to the datasheet unit by multiplication:

====================  ============  =======================  ====================
effect parameter       SI            gyro datasheet unit      accel datasheet unit
====================  ============  =======================  ====================
Q quantization         rad | m/s     arcsec                   m/s (unchanged)
N white_noise          rad/s/sqrt(Hz) deg/sqrt(h)             m/s/sqrt(h)
B bias_instability     rad/s         deg/h                    mg
K random_walk          rad/s^1.5     deg/h^1.5                m/s/h^1.5
R ramp                 rad/s^2       deg/h^2                  m/s/h^2
sigma (Gauss-Markov)   rad/s         deg/h                    mg
amplitude (sinusoid)   rad/s         deg/h                    mg
tau_c, freq_hz         s, Hz         s, Hz                    s, Hz
====================  ============  =======================  ====================

Checks against ../shared/REFERENCE.md: 1 deg/sqrt(h) = 2.909e-4 rad/s/sqrt(Hz); 1 deg/h = 4.848e-6 rad/s;
1 deg/h^1.5 = 8.08e-8 rad/s^1.5.
"""

from __future__ import annotations

import math

DEG = 180.0 / math.pi  #: deg per rad
G0 = 9.80665  # m/s^2 per g
HOUR = 3600.0  #: s per h: datasheets give noise per hour

GYRO_FACTORS = {
    "Q": DEG * 3600.0,  # rad -> arcsec
    "N": DEG * math.sqrt(HOUR),  # rad/s/sqrt(Hz) = rad/sqrt(s) -> deg/sqrt(h)
    "B": DEG * HOUR,  # rad/s -> deg/h
    "K": DEG * HOUR**1.5,  # rad/s^1.5 -> deg/h^1.5
    "R": DEG * HOUR**2,  # rad/s^2 -> deg/h^2
    "sigma": DEG * HOUR,
    "amplitude": DEG * HOUR,
    "tau_c": 1.0,
    "freq_hz": 1.0,
    "f0": 1.0,
}
GYRO_UNITS = {
    "Q": "arcsec", "N": "deg/sqrt(h)", "B": "deg/h", "K": "deg/h^1.5", "R": "deg/h^2",
    "sigma": "deg/h", "amplitude": "deg/h", "tau_c": "s", "freq_hz": "Hz", "f0": "Hz",
}
ACCEL_FACTORS = {
    "Q": 1.0,  # m/s
    "N": math.sqrt(HOUR),  # m/s^2/sqrt(Hz) = m/s/sqrt(s) -> m/s/sqrt(h)
    "B": 1000.0 / G0,  # m/s^2 -> mg
    "K": HOUR**1.5,  # m/s^2.5 -> m/s/h^1.5
    "R": HOUR**2,  # m/s^3 -> m/s/h^2
    "sigma": 1000.0 / G0,
    "amplitude": 1000.0 / G0,
    "tau_c": 1.0,
    "freq_hz": 1.0,
    "f0": 1.0,
}
ACCEL_UNITS = {
    "Q": "m/s", "N": "m/s/sqrt(h)", "B": "mg", "K": "m/s/h^1.5", "R": "m/s/h^2",
    "sigma": "mg", "amplitude": "mg", "tau_c": "s", "freq_hz": "Hz", "f0": "Hz",
}


def is_gyro_axis(axis: str) -> bool:
    return axis.startswith("g")


def to_datasheet(param: str, value: float, axis: str = "gx") -> float:
    """SI value of parameter ``param`` -> datasheet unit for a gyro (g*) or accel (a*) axis."""
    factors = GYRO_FACTORS if is_gyro_axis(axis) else ACCEL_FACTORS
    return value * factors[param]


def from_datasheet(param: str, value: float, axis: str = "gx") -> float:
    factors = GYRO_FACTORS if is_gyro_axis(axis) else ACCEL_FACTORS
    return value / factors[param]


def datasheet_unit(param: str, axis: str = "gx") -> str:
    return (GYRO_UNITS if is_gyro_axis(axis) else ACCEL_UNITS)[param]


def fmt_value(v: float, digits: int = 3) -> str:
    """A value in a table: ``digits`` significant digits, exponent form outside 1e-3 .. 1e5."""
    if v == 0 or not math.isfinite(v):
        return f"{v:g}"
    return f"{v:.{digits}g}" if 1e-3 <= abs(v) < 1e5 else f"{v:.{digits - 1}e}"


def fmt_interval(v: float, lo: float, hi: float) -> str:
    """``v [lo, hi]`` with 3 significant digits, more (up to 6) where 3 would print the two ends alike: a
    precise N on hours of data read "1.03 [1.03, 1.03]", an interval that says nothing."""
    for d in range(3, 7):
        a, b = fmt_value(lo, d), fmt_value(hi, d)
        if a != b or not hi > lo:
            break
    return f"{fmt_value(v, d)} [{a}, {b}]"


def rate_display(axis: str) -> tuple[float, str]:
    """(factor, unit) from SI to the unit a table or plot of raw samples shows: deg/s for gyro axes, m/s^2
    for accelerometers."""
    from companion.samples import GYRO_AXES

    return (180.0 / math.pi, "deg/s") if axis in GYRO_AXES else (1.0, "m/s^2")
