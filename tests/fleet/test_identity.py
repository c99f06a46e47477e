"""Log identity from tlog metadata, checked against frames packed by pymavlink itself."""

from __future__ import annotations

from companion.fleet.identity import tlog_identity
from companion.mavlink.tlog_writer import TlogWriter


def test_board_id_gyro_ids_and_start_time_from_pymavlink_frames(tmp_path):
    p = tmp_path / "meta.tlog"
    with TlogWriter(p, sysid=7, compid=1) as w:
        w.write(w.mav.heartbeat_encode(2, 3, 0, 0, 3), t_unix=1.76e9)
        w.write(w.mav.autopilot_version_encode(0, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0,
                                               0x1234ABCD5678EF01), t_unix=1.76e9 + 1)
        w.write(w.mav.param_value_encode(b"INS_GYR_ID", 2359586.0, 6, 900, 10), t_unix=1.76e9 + 2)
        w.write(w.mav.param_value_encode(b"INS_GYR2_ID", 2229282.0, 6, 900, 11), t_unix=1.76e9 + 2)
        w.write(w.mav.param_value_encode(b"INS_ACC_ID", 1.0, 6, 900, 12), t_unix=1.76e9 + 2)
    ident = tlog_identity(p.read_bytes())
    assert ident["board_id"] == "1234abcd5678ef01"
    assert ident["board_by_sysid"] == {7: "1234abcd5678ef01"}
    assert ident["imu_ids"] == {0: 2359586, 1: 2229282}
    assert abs(ident["start_time"] - 1.76e9) < 1e-3


def test_no_metadata_is_absent_not_an_error(tmp_path):
    p = tmp_path / "plain.tlog"
    with TlogWriter(p) as w:
        w.write(w.mav.heartbeat_encode(2, 3, 0, 0, 3), t_unix=1.7e9)
        w.write(w.mav.autopilot_version_encode(0, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0),
                t_unix=1.7e9)  # uid 0: "not provided"
    ident = tlog_identity(p.read_bytes())
    assert ident["board_id"] is None and ident["imu_ids"] == {}


def test_dataflash_board_banner_gyro_ids_and_gps_start_time(tmp_path):
    """A written DataFlash log: the boot banner's MCU id, INS_GYR*_ID and a GPS record's UTC time."""
    import numpy as np

    from companion.fleet.identity import log_identity
    from companion.sim.dataflash_writer import write_imu_log
    from companion.sources import load

    rate, n = 100.0, 2000
    t = 37.5 + np.arange(n) / rate
    g = np.zeros((2, n, 3))
    a = np.zeros((2, n, 3))
    a[..., 2] = -9.80665
    p = tmp_path / "id.bin"
    unix_at_t0 = 1_762_000_000.25  # 2025-11-01, leap seconds 18
    write_imu_log(p, t, g, a, params={"INS_GYR_ID": 2621706, "INS_GYR2_ID": 2687754, "INS_GYR3_ID": 0},
                  messages=["ArduCopter V4.6.2 (1ebd4d99)", "ChibiOS: 88b84600",
                            "Pixhawk4 0047002B 34385105 36363539", "Frame: QUAD/X"],
                  gps_utc=(float(t[500]), unix_at_t0 + 5.0))
    ident = log_identity(load(p).meta)
    assert ident["board_id"] == "0047002b3438510536363539" and ident["board"] == "Pixhawk4"
    assert ident["imu_ids"] == {0: 2621706, 1: 2687754}  # 0: no third gyro
    assert abs(ident["start_time"] - unix_at_t0) < 2e-3  # GMS is whole milliseconds


def test_dataflash_without_banner_or_gps_has_no_identity(tmp_path):
    import numpy as np

    from companion.fleet.identity import log_identity
    from companion.sim.dataflash_writer import write_imu_log
    from companion.sources import load

    t = np.arange(500) / 50.0
    write_imu_log(tmp_path / "bare.bin", t, np.zeros((500, 3)), np.zeros((500, 3)), messages=["Frame: QUAD"])
    ident = log_identity(load(tmp_path / "bare.bin").meta)
    assert ident["board_id"] is None and ident["imu_ids"] == {} and ident["start_time"] is None


def test_real_dataflash_logs_identity(shared_data):
    """The real logs' banners, read independently with pymavlink's DFReader."""
    from pymavlink import DFReader

    from companion.fleet.identity import log_identity
    from companion.sources import load

    for name in ("dronekit_log171.bin", "methodic_backend_log_80k.bin"):
        path = shared_data / "ardupilot" / name
        ref = DFReader.DFReader_binary(str(path))
        banner = None
        while banner is None:
            m = ref.recv_match(type="MSG")
            if m is None:
                break
            words = m.Message.split()
            if len(words) == 4 and all(len(w) == 8 for w in words[1:]) and words[0] not in ("PX4:", "Frame:"):
                banner = words
        ident = log_identity(load(path).meta)
        assert banner is not None
        assert ident["board"] == banner[0] and ident["board_id"] == "".join(banner[1:]).lower()
        if name.startswith("methodic"):
            assert ident["imu_ids"] == {0: 2621706, 1: 2687754}
        if ident["start_time"] is not None:  # a plausible UTC date: 2014 .. 2026
            assert 1.39e9 < ident["start_time"] < 1.80e9


def test_real_ulog_identity_matches_pyulog(shared_data):
    from pyulog import ULog

    from companion.fleet.identity import log_identity
    from companion.sources import load

    for path in sorted((shared_data / "px4").glob("*.ulg")):
        ref = ULog(str(path)).msg_info_dict
        ident = log_identity(load(path).meta)
        want = str(ref.get("sys_uuid") or "").strip().lower() or None
        assert ident["board_id"] == want
        assert ident["board"] == (str(ref.get("ver_hw") or "").strip() or None)
