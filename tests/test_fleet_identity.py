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
