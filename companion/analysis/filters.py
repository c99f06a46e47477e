"""The low-pass filter an autopilot applies to its IMU data before it logs or sends them, read from its
parameters, and how the logged samples were taken from the filtered signal.

ArduPilot: INS_GYRO_FILTER / INS_ACCEL_FILTER (Hz) filter what the DataFlash IMU message logs and what
RAW_IMU / SCALED_IMU* send; before them (2014-2015 firmware) INS_MPU6K_FILTER set the MPU6000/MPU9250's own
digital low-pass (5, 10, 20, 42, 98 ... Hz; 0 = the firmware's default, which changed between releases, so
unknown) for gyro and accelerometer alike -- the public Erle-Brain rover logs at 5 Hz show a roll-off at
4.6-6.1 Hz in the data; PX4: IMU_GYRO_CUTOFF / IMU_ACCEL_CUTOFF for sensor_combined, sensor_gyro,
vehicle_imu and what the MAVLink IMU messages carry. A value of 0 (filter off) or an absent parameter: unknown.
The parameters come from the log (DataFlash PARM, ULog parameters) or from PARAM_VALUE messages (a tlog, a
live link that carries them).
"""

from __future__ import annotations

import math

#: parameter -> which data it filters (the first parameter a log has for a kind gives its cut-off)
FILTER_PARAMS = {"INS_GYRO_FILTER": ("gyro",), "INS_ACCEL_FILTER": ("accel",),
                 "IMU_GYRO_CUTOFF": ("gyro",), "IMU_ACCEL_CUTOFF": ("accel",),
                 "INS_MPU6K_FILTER": ("gyro", "accel")}
#: messages whose samples come from the filtered signal, per log format (None: MAVLink, a tlog or a live link)
FILTERED_MESSAGES = {"dataflash": ("IMU", "ISB_GYRO_POST", "ISB_ACCEL_POST"), "ulog": ("sensor_combined", "sensor_gyro", "vehicle_imu"),
                     None: ("RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3", "HIGHRES_IMU")}
#: messages that carry the filtered signal averaged over the output interval (delta angle / dt)
AVERAGED_MESSAGES = ("sensor_combined", "vehicle_imu")


def sampling(message: str) -> str:
    """"average" for PX4's sensor_combined and vehicle_imu (delta angle / dt over the publication interval),
    "point" (the latest filtered value) for the rest (DataFlash IMU, sensor_gyro, MAVLink, CSV)."""
    return "average" if message in AVERAGED_MESSAGES else "point"


def filters_from_params(params: dict | None, message: str, fmt: str | None = None) -> dict:
    """{"gyro": Hz, "accel": Hz} of the data of ``message`` in a log of format ``fmt`` ("dataflash", "ulog",
    or None for MAVLink) from the parameters ``params`` (empty where unknown; a CSV has none)."""
    out = {}
    if fmt not in FILTERED_MESSAGES or message not in FILTERED_MESSAGES[fmt]:
        return out
    for name, kinds in FILTER_PARAMS.items():
        v = (params or {}).get(name)
        try:
            v = float(v)
        except (TypeError, ValueError):
            continue
        if v > 0 and math.isfinite(v):
            for kind in kinds:
                out.setdefault(kind, v)
    return out
