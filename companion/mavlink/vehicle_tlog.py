"""A simulated vehicle's samples as the tlog an ArduPilot autopilot would have sent (an adapter: the simulator,
:mod:`companion.sim.vehicle`, produces arrays; this module encodes them with :mod:`companion.mavlink.tlog_writer`).
"""

from __future__ import annotations

import numpy as np

from companion.mavlink.tlog_writer import ImuTlogStream
from companion.sim.body_motion import _finite
from companion.sim.vehicle import IMU_MESSAGES, VehicleSimulator


def write_tlog(path, sim: VehicleSimulator, duration_s: float, sysid: int = 1, compid: int = 1,
               heartbeat_hz: float = 1.0, mavlink2: bool = True, t0_unix: float = 1.7e9,
               block_s: float = 600.0) -> dict:
    """Write ``duration_s`` of the simulator to a tlog as an ArduPilot autopilot would send it.

    IMU0 as RAW_IMU (``time_usec``), IMU1 as SCALED_IMU2, IMU2 as SCALED_IMU3 (``time_boot_ms``), gyro
    int16 mrad/s and accel int16 mG, rounded to the nearest LSB and clipped to int16; a HEARTBEAT every
    ``1/heartbeat_hz`` s of simulated time from the first sample on, with the armed bit (``base_mode``
    128) set while a flight is armed. Written block by block (constant memory). The encoder is
    :mod:`companion.mavlink.tlog_writer`'s. Returns counts ``{"imu_messages", "heartbeats"}``.
    """
    duration_s = _finite("duration (s)", duration_s, lo=0.0, lo_open=True)
    counts = {"imu_messages": 0, "heartbeats": 0}
    next_hb = sim.t_next
    with ImuTlogStream(path, sysid=sysid, compid=compid, mavlink2=mavlink2, t0_unix=t0_unix) as out:
        for blk in sim.blocks(duration_s, block_s):
            if blk.n == 0:
                continue
            hb = []
            if heartbeat_hz > 0:
                t_last = blk.t[-1]
                while next_hb <= t_last:
                    hb.append(next_hb)
                    next_hb += 1.0 / heartbeat_hz
            hb = np.asarray(hb)
            streams = [(IMU_MESSAGES[i], i, *blk.imu(i)) + (() if blk.temperature is None else (blk.temperature[i],))
                       for i in range(sim.imus)]
            out.write(streams, hb, np.asarray(sim.armed_at(hb), dtype=bool).reshape(-1))
            counts["imu_messages"] += blk.n * sim.imus
            counts["heartbeats"] += hb.size
    return counts


__all__ = ["write_tlog"]
