"""The tlog writer: pymavlink (an independent decoder) must read back exactly what was written."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.pymavlink_reference import pymavlink_messages

from companion.mavlink.tlog_writer import TlogWriter, write_imu_tlog
from companion.sources import messages as M


def _signal(n, seed=3):
    rng = np.random.default_rng(seed)
    t = 12.0 + np.arange(n) / 400.0
    gyro = rng.normal(0.0, 0.02, (n, 3))
    accel = rng.normal(0.0, 0.2, (n, 3)) + [0.0, 0.0, -9.80665]
    return t, gyro, accel


@pytest.mark.parametrize("mavlink2", [True, False])
@pytest.mark.parametrize("message", ["RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3"])
def test_int16_messages_round_trip_through_pymavlink(tmp_path, message, mavlink2):
    n = 1500
    t, gyro, accel = _signal(n)
    gyro[5] = [1e3, -1e3, 0.0]  # clipped to int16
    path = tmp_path / "x.tlog"
    assert write_imu_tlog(path, t, gyro, accel, message=message, instance=0, temperature=41.27,
                          mavlink2=mavlink2, sysid=7, compid=3, heartbeat_hz=2.0) == n
    msgs = pymavlink_messages(path)
    imu = [m for m in msgs if m.get_type() == message]
    hb = [m for m in msgs if m.get_type() == "HEARTBEAT"]
    assert len(msgs) == len(imu) + len(hb)  # no BAD_DATA
    assert len(imu) == n
    assert len(hb) == int(np.floor((t[-1] - t[0]) * 2.0)) + 1
    assert all(m.get_srcSystem() == 7 and m.get_srcComponent() == 3 for m in msgs)
    assert all((m.base_mode & 0x80) == 0 and m.type == 2 for m in hb)
    gx = np.array([[m.xgyro, m.ygyro, m.zgyro] for m in imu])
    ax = np.array([[m.xacc, m.yacc, m.zacc] for m in imu])
    np.testing.assert_array_equal(gx, np.clip(np.rint(gyro / 1e-3), -32768, 32767))
    np.testing.assert_array_equal(ax, np.rint(accel / 9.80665e-3))
    if message == "RAW_IMU":
        np.testing.assert_array_equal([m.time_usec for m in imu], np.rint(t * 1e6))
    else:
        np.testing.assert_array_equal([m.time_boot_ms for m in imu], np.rint(t * 1e3))
    if mavlink2:
        assert all(m.temperature == 4127 for m in imu)
    # sequence numbers count every message of the link
    seqs = np.array([m.get_seq() for m in msgs])
    np.testing.assert_array_equal(seqs, np.arange(len(msgs)) % 256)


def test_highres_floats_and_custom_scale(tmp_path):
    n = 800
    t, gyro, accel = _signal(n, seed=5)
    path = tmp_path / "h.tlog"
    write_imu_tlog(path, t, gyro, accel, message="HIGHRES_IMU", instance=2, temperature=30.5)
    imu = [m for m in pymavlink_messages(path) if m.get_type() == "HIGHRES_IMU"]
    assert len(imu) == n
    got = np.array([[m.xgyro, m.ygyro, m.zgyro, m.xacc, m.yacc, m.zacc] for m in imu])
    np.testing.assert_array_equal(got, np.hstack([gyro, accel]).astype(np.float32))
    assert {m.id for m in imu} == {2}
    assert all(m.temperature == 30.5 for m in imu)
    # a custom scale: ADIS16405 0.05 deg/s per LSB in RAW_IMU
    scale = np.deg2rad(0.05)
    write_imu_tlog(path, t, gyro, accel, message="RAW_IMU", gyro_scale=scale, accel_scale=3.33e-3 * 9.80665)
    raw = [m for m in pymavlink_messages(path) if m.get_type() == "RAW_IMU"]
    np.testing.assert_array_equal([m.ygyro for m in raw], np.rint(gyro[:, 1] / scale))


def test_tlog_writer_any_message_and_crc(tmp_path):
    path = tmp_path / "g.tlog"
    with TlogWriter(path, sysid=9, compid=191) as w:
        frame = w.write(w.mav.named_value_float_encode(1234, b"GYR_N", 1.5), t_unix=1.7e9)
        w.write(w.mav.heartbeat_encode(18, 8, 0, 0, 4), t_unix=1.7e9 + 1)
    # our scalar CRC agrees with the frame pymavlink packed
    crc = M.crc_x25(frame[1:-2] + bytes([M.CRC_INFO[251][0]]))
    assert crc == int.from_bytes(frame[-2:], "little")
    types = [m.get_type() for m in pymavlink_messages(path)]
    assert types == ["NAMED_VALUE_FLOAT", "HEARTBEAT"]


def test_large_file_is_complete(tmp_path):
    """200,000 messages written in one vectorised call are all there, in order (speed: a benchmark's job,
    benchmarks/bench_ingest.py; a wall-clock limit here would fail on a busy machine)."""
    from companion.sources import tlog

    n = 200_000
    t = np.arange(n) / 400.0
    z = np.zeros((n, 3))
    assert write_imu_tlog(tmp_path / "big.tlog", t, z, z) == n
    index = tlog.scan(tlog.read_file(tmp_path / "big.tlog"))
    assert index.bad_frames == 0 and int((index.msgid == M.RAW_IMU.msgid).sum()) == n
