"""SYS_STATUS frames and small tlogs of an autopilot that flags its gyro unhealthy for a while, written by hand for
tests/sources/test_autopilot_health.py (what the autopilot-health reader is checked against)."""

from __future__ import annotations

T0 = 1.7e9  # the tlogs' first arrival time (s since the epoch)
GYRO = 1  # MAV_SYS_STATUS_SENSOR_3D_GYRO: onboard_control_sensors_* bit


def sys_status(mav, sensors: int, health: int):
    """A SYS_STATUS with ``sensors`` present and enabled, ``health`` the healthy bits, every other field 0."""
    return mav.sys_status_encode(sensors, sensors, health, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)


def gyro_unhealthy_tlog(path, autopilot: int, imus: int = 1, bad=(5.0, 8.0), beside=None) -> None:
    """20 s of RAW_IMU at 50 Hz from ``imus`` IMUs (constant readings); HEARTBEAT (MAV_AUTOPILOT ``autopilot``) and
    SYS_STATUS at 2 Hz, 3D_GYRO present and unhealthy over ``bad`` (s). ``beside(writer, t)`` writes more frames
    after each SYS_STATUS."""
    from companion.mavlink.tlog_writer import TlogWriter

    with TlogWriter(path) as w:
        mav = w.mav
        for k in range(1000):
            t = k * 0.02
            if k % 25 == 0:
                w.write(mav.heartbeat_encode(2, autopilot, 0, 0, 3), T0 + t)
                w.write(sys_status(mav, 3, 3 & ~GYRO if bad[0] <= t < bad[1] else 3), T0 + t)
                if beside is not None:
                    beside(w, t)
            for i in range(imus):
                w.write(mav.raw_imu_encode(int(t * 1e6), 0, 0, 1000, 1, -1, 0, 0, 0, 0, i, 0), T0 + t)
