"""The tlog reader against pymavlink: exact counts, identical values, garbage recovered, v1/v2, signing."""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as dialect

from tests.support.pymavlink_reference import pymavlink_messages

from companion.mavlink.tlog_writer import write_imu_tlog
from companion.samples import StreamKey
from companion.sources import load, messages as M, tlog
from companion.sources.decode import imu_sample_from_message

T0 = 1.7e9


def test_message_table_matches_pymavlink():
    for name, layout in M.LAYOUTS.items():
        cls = dialect.mavlink_map[layout.msgid]
        assert cls.msgname == name
        assert cls.crc_extra == layout.crc_extra
        assert list(layout.dtype.names) == list(cls.ordered_fieldnames)
        assert layout.full_len == cls.unpacker.size
    # every CRC_EXTRA of the dialect is in the reader's table
    for msgid, cls in dialect.mavlink_map.items():
        assert M.CRC_EXTRA_TABLE[msgid] == cls.crc_extra


# stream plan: (message, sysid, compid, instance, rate_hz, compass_only)
PLAN = [
    ("RAW_IMU", 1, 1, 0, 50.0, False),
    ("SCALED_IMU2", 1, 1, 1, 25.0, False),
    ("SCALED_IMU3", 1, 1, 2, 10.0, True),
    ("HIGHRES_IMU", 2, 1, 0, 100.0, False),
    ("HIGHRES_IMU", 2, 1, 1, 40.0, False),
]
DURATION = 8.0


def _encode(mav, name, t, g, a, inst, compass_only):
    if name == "RAW_IMU":
        return mav.raw_imu_encode(int(round(t * 1e6)), *a, *g, 100, -200, 300, inst, 4123)
    if name.startswith("SCALED_IMU"):
        enc = {"SCALED_IMU2": mav.scaled_imu2_encode, "SCALED_IMU3": mav.scaled_imu3_encode}[name]
        if compass_only:
            return enc(int(round(t * 1e3)), 0, 0, 0, 0, 0, 0, 150, -20, 400, 0)
        return enc(int(round(t * 1e3)), *a, *g, 0, 0, 0, 3900)
    return mav.highres_imu_encode(int(round(t * 1e6)), *(a * 0.01), *(g * 1e-3), 0.1, 0.2, 0.3,
                                  1013.0, 0.0, 12.0, 35.5, 0x3F, inst)


def make_mixed_tlog(path, mavlink2=True, garbage=False, seed=0):
    """Interleaved IMU streams of PLAN plus HEARTBEAT and NAMED_VALUE_FLOAT; returns (records, garbage bytes)."""
    rng = np.random.default_rng(seed)
    junk_rng = np.random.default_rng(seed + 1000)  # garbage must not change the messages
    events = []
    for si, (name, sysid, compid, inst, rate, compass) in enumerate(PLAN):
        n = int(round(DURATION * rate))
        for k in range(n):
            events.append((10.0 + k / rate, si))
    events.sort()
    mavs = {}
    out = bytearray()
    records = 0
    bad = 0
    hb_next = 0.0
    for idx, (t, si) in enumerate(events):
        name, sysid, compid, inst, rate, compass = PLAN[si]
        mav = mavs.setdefault((sysid, compid), dialect.MAVLink(None, srcSystem=sysid, srcComponent=compid))
        msgs = []
        if t >= hb_next:
            msgs.append(mav.heartbeat_encode(2, 3, 0, 0, 3))
            msgs.append(mav.named_value_float_encode(int(t * 1e3), b"GYR_N", float(t)))
            hb_next += 1.0
        g = rng.integers(-300, 300, 3)
        a = rng.integers(-1200, 1200, 3)
        msgs.append(_encode(mav, name, t, g, a, inst, compass))
        for m in msgs:
            frame = m.pack(mav, force_mavlink1=not mavlink2)
            mav.seq = (mav.seq + 1) % 256
            out += int(round((T0 + t) * 1e6)).to_bytes(8, "big") + frame
            records += 1
        if garbage and idx % 37 == 5:
            junk = junk_rng.integers(0, 256, int(junk_rng.integers(1, 41)), dtype=np.uint8)
            junk[0] = 0xFD  # a false start right away
            out += junk.tobytes()
            bad += junk.shape[0]
    path.write_bytes(bytes(out))
    return records, bad


@pytest.mark.parametrize("garbage", [False, True])
@pytest.mark.parametrize("mavlink2", [True, False])
def test_mixed_streams_exact_counts_rates_and_pymavlink_values(tmp_path, mavlink2, garbage):
    path = tmp_path / "mixed.tlog"
    records, junk = make_mixed_tlog(path, mavlink2, garbage, seed=1 + mavlink2)
    res = load(path)
    assert res.totals["frames"] == records
    assert res.totals["bad_bytes"] == junk
    keys = [s.key for s in res.streams]
    expect = sorted(StreamKey(sy, co, name, inst) for name, sy, co, inst, _, _ in PLAN)
    assert keys == expect
    for s in res.streams:
        name, sy, co, inst, rate, compass = next(p for p in PLAN if StreamKey(p[1], p[2], p[0], p[3]) == s.key)
        assert s.samples == int(round(DURATION * rate))
        assert s.timing.rate_hz == pytest.approx(rate, rel=1e-9)
        assert s.timing.gaps == 0 and s.timing.duplicates == 0 and s.timing.resets == 0
        assert s.segments == [(0, s.samples)]
        assert s.timing.duration_s == pytest.approx((s.samples - 1) / rate, abs=1e-6)
        assert s.is_imu is (not compass)
    # identical values: pymavlink decodes the clean file; live decoding (imu_sample_from_message) == ours
    clean = tmp_path / "clean.tlog"
    make_mixed_tlog(clean, mavlink2, False, seed=1 + mavlink2)
    ref = {}
    for m in pymavlink_messages(clean):
        assert m.get_type() != "BAD_DATA"
        smp = imu_sample_from_message(m)
        if smp is not None:
            ref.setdefault(smp.key, []).append((smp.t_s, *smp.gyro, *smp.accel))
    for s in res.streams:
        r = np.array(ref[s.key])
        np.testing.assert_array_equal(s.t, r[:, 0])
        np.testing.assert_array_equal(s.gyro, r[:, 1:4])
        np.testing.assert_array_equal(s.accel, r[:, 4:7])
    raw = next(s for s in res.streams if s.key.message == "RAW_IMU")
    assert raw.gyro_lsb == 1e-3 and raw.accel_lsb == pytest.approx(9.80665e-3)
    hr = next(s for s in res.streams if s.key.message == "HIGHRES_IMU")
    assert hr.gyro_lsb is None and np.all(hr.temperature == np.float32(35.5))
    if mavlink2:  # RAW_IMU temperature is an extension: lost on MAVLink 1... unless pymavlink sent it
        assert np.all(raw.temperature == pytest.approx(41.23))


def test_pymavlink_field_equality_on_a_large_written_file(tmp_path):
    n = 20_000
    rng = np.random.default_rng(7)
    t = 3.0 + np.arange(n) / 400.0
    gyro = rng.normal(0, 0.05, (n, 3))
    accel = rng.normal(0, 0.5, (n, 3)) + [0, 0, -9.8]
    path = tmp_path / "r.tlog"
    write_imu_tlog(path, t, gyro, accel, temperature=np.linspace(30, 40, n))
    ref = np.array([[m.time_usec, m.xgyro, m.ygyro, m.zgyro, m.xacc, m.yacc, m.zacc, m.temperature]
                    for m in pymavlink_messages(path) if m.get_type() == "RAW_IMU"], dtype=np.float64)
    s = load(path).streams[0]
    assert s.samples == n == ref.shape[0]
    np.testing.assert_array_equal(s.t, ref[:, 0] * 1e-6)
    np.testing.assert_array_equal(s.gyro, ref[:, 1:4] * 1e-3)
    np.testing.assert_array_equal(s.accel, ref[:, 4:7] * (9.80665e-3))
    np.testing.assert_array_equal(s.temperature, ref[:, 7] * 0.01)


def test_garbage_that_breaks_pymavlink_is_recovered(tmp_path):
    """1-40 garbage bytes every 500 records (the corruption measured on a real radio link, smaller)."""
    n = 6000
    src = tmp_path / "c.tlog"
    t = np.arange(n) / 50.0
    write_imu_tlog(src, t, np.full((n, 3), 0.01), np.full((n, 3), 1.0), heartbeat_hz=0)
    data = src.read_bytes()
    rec = len(data) // n
    rng = np.random.default_rng(0)
    parts, junk = [], 0
    for i in range(0, n, 500):
        parts.append(data[i * rec:(i + 500) * rec])
        g = rng.integers(0, 256, int(rng.integers(1, 41)), dtype=np.uint8).tobytes()
        parts.append(g)
        junk += len(g)
    bad = tmp_path / "g.tlog"
    bad.write_bytes(b"".join(parts))
    res = load(bad)
    assert res.streams[0].samples == n
    assert res.totals["frames"] == n and res.totals["bad_bytes"] == junk
    pm = sum(1 for m in pymavlink_messages(bad) if m.get_type() == "RAW_IMU")
    assert pm <= n  # pymavlink may lose sync (it does in the benchmark); we never do


def test_corrupted_frame_is_counted_not_decoded(tmp_path):
    n = 300
    path = tmp_path / "x.tlog"
    write_imu_tlog(path, np.arange(n) / 100.0, np.zeros((n, 3)) + 0.002, np.zeros((n, 3)), heartbeat_hz=0)
    data = bytearray(path.read_bytes())
    index = tlog.scan(bytes(data))
    p = int(index.pos[100])
    data[p + 14] ^= 0x55  # a payload byte of frame 100
    index = tlog.scan(bytes(data))
    assert index.frames == n - 1
    assert index.bad_frames == 1
    assert index.bad_bytes == int(index.header_len[0] + index.length[0] + 2 + 8)


def test_signed_and_truncated_mavlink2(tmp_path):
    mav = dialect.MAVLink(None, srcSystem=3, srcComponent=1)
    mav.signing.secret_key = bytes(range(32))
    mav.signing.sign_outgoing = True
    mav.signing.link_id = 1
    mav.signing.timestamp = 1
    out = bytearray()
    for k in range(20):
        # all-zero extension fields and zero mag: trailing zeros are trimmed on the wire
        m = mav.raw_imu_encode(1_000_000 + k * 10_000, 1, 2, 3, 4, 5, 6 + k, 0, 0, 0, 0, 0)
        frame = m.pack(mav)
        mav.seq = (mav.seq + 1) % 256
        assert frame[2] & 0x01 and frame[1] < M.RAW_IMU.full_len
        out += int((T0 + k * 0.01) * 1e6).to_bytes(8, "big") + frame
    path = tmp_path / "s.tlog"
    path.write_bytes(bytes(out))
    res = load(path)
    s = res.streams[0]
    assert res.totals["frames"] == 20 and res.totals["bad_bytes"] == 0
    assert s.key == StreamKey(3, 1, "RAW_IMU", 0) and s.samples == 20
    np.testing.assert_array_equal(s.gyro[:, 2], (6 + np.arange(20)) * 1e-3)
    assert s.temperature is None
    assert s.timing.rate_hz == pytest.approx(100.0)


def test_config_scale_override(tmp_path):
    n = 200
    scale = np.deg2rad(0.05)  # ADIS16405 counts in RAW_IMU
    path = tmp_path / "adis.tlog"
    gyro = np.tile([0.0, scale * 7, -scale * 3], (n, 1))
    write_imu_tlog(path, np.arange(n) / 100.0, gyro, np.zeros((n, 3)), gyro_scale=scale, accel_scale=0.0327)
    cfg = {"streams": [{"message": "RAW_IMU", "instance": 0, "gyro_scale": float(scale), "accel_scale": 0.0327}]}
    s = load(path, config=cfg).streams[0]
    np.testing.assert_allclose(s.gyro, gyro, rtol=1e-12, atol=1e-15)
    assert s.gyro_lsb == scale
    s_default = load(path).streams[0]
    np.testing.assert_array_equal(s_default.gyro[:, 1], 7e-3)  # read as mrad/s without the override


@pytest.mark.parametrize("cfg,expect", [
    ({"streams": {"message": "RAW_IMU"}}, "must be a list"),
    ({"streams": [{"gyro_scale": 1.0}]}, "at least 'message'"),
    ({"streams": [{"message": "RAW_IMU", "gyro_scal": 1.0}]}, "unknown key"),
    ({"streams": [{"message": "ATTITUDE"}]}, "is not one of"),
    ({"streams": [{"message": "RAW_IMU", "gyro_scale": -1}]}, "positive"),
])
def test_config_errors_are_one_line(tmp_path, cfg, expect):
    from companion.errors import CompanionError

    n = 20
    path = tmp_path / "c.tlog"
    write_imu_tlog(path, np.arange(n) / 10.0, np.zeros((n, 3)) + 0.01, np.zeros((n, 3)))
    with pytest.raises(CompanionError, match=expect):
        load(path, config=cfg)
    bad_yaml = tmp_path / "bad.yaml"
    bad_yaml.write_text("streams: [\n")
    with pytest.raises(CompanionError, match="invalid YAML"):
        load(path, config=bad_yaml)


def test_live_decode_scalar_path_equals_the_array_path():
    """The int16 messages' scalar path gives the array path's samples bit for bit (scale overrides,
    compass-only rows, temperature 0 = none, extreme codes)."""
    import os

    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from companion.sources.decode import ScaleTable, _instance, _to_si

    mav = mavlink.MAVLink(None, srcSystem=3, srcComponent=7)
    rng = np.random.default_rng(11)
    scales = ScaleTable([{"message": "SCALED_IMU2", "gyro_scale": 8.7266e-4, "accel_scale": 0.0326561}])
    for _ in range(300):
        v = [int(x) for x in rng.integers(-32768, 32768, 9)]
        if rng.random() < 0.2:
            v[:6] = [0] * 6
        temp = int(rng.choice([0, int(rng.integers(-32768, 32768))]))
        name = str(rng.choice(["RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3"]))
        if name == "RAW_IMU":
            msg = mav.raw_imu_encode(int(rng.integers(0, 2**63)), *v, int(rng.integers(0, 256)), temp)
        else:
            msg = getattr(mav, name.lower() + "_encode")(int(rng.integers(0, 2**32)), *v, temp)
        msg = mav.decode(bytearray(msg.pack(mav)))
        got = imu_sample_from_message(msg, scales)
        layout = M.IMU_LAYOUTS[name]
        rec = np.array([tuple(getattr(msg, f) for f in layout.dtype.names)], dtype=layout.dtype)
        key = StreamKey(3, 7, name, int(_instance(layout, rec)[0]))
        ref = _to_si(layout, key, rec, scales)
        assert got.key == key and got.is_imu == ref.is_imu
        assert got.t_s == ref.t[0] and got.gyro == tuple(ref.gyro[0]) and got.accel == tuple(ref.accel[0])
        assert got.temperature == (None if ref.temperature is None else ref.temperature[0])
