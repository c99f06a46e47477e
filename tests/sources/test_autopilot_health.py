"""The autopilot's own IMU health read from each format (sources/autopilot_health.py), against values read
independently: pymavlink's DFReader on DataFlash records, pyulog on ULog topics, pymavlink on tlog frames, and
records written by hand; and the cross-check shown by ``analyze`` and ``inspect``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from companion.cli.main import main
from companion.sources import dataflash as df
from companion.sources import load
from companion.sources.autopilot_health import from_dataflash, from_ulog
from tests.support.sys_status import T0, gyro_unhealthy_tlog, sys_status

REALLOGS = __import__("pathlib").Path("/work/reallogs")


def _dfreader(path, names):
    """{name: [message, ...]} read with pymavlink's DFReader (the reader class itself: mavutil would run a path
    containing /bin/)."""
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(path), zero_time_base=True)
    out = {n: [] for n in names}
    while True:
        m = r.recv_match(type=list(names))
        if m is None:
            return out
        out[m.get_type()].append(m)


def test_dataflash_4x_layout_matches_dfreader(shared_data):
    path = shared_data / "ardupilot" / "methodic_backend_log_80k.bin"
    view = from_dataflash(df.open_log(path))
    ref = _dfreader(path, ("IMU", "VIBE"))
    for inst in sorted({m.I for m in ref["IMU"]}):
        rows = [m for m in ref["IMU"] if m.I == inst]
        r = view.imu(inst)
        assert r.gyro_errors.last == rows[-1].EG and r.accel_errors.last == rows[-1].EA
        assert r.gyro_errors.rise == sum(max(b.EG - a.EG, 0) for a, b in zip(rows, rows[1:]))
        gh = next(u for u in r.unhealthy if u.field == "IMU.GH")
        assert (len(gh.intervals) == 0) == all(m.GH for m in rows)
        assert r.temperature == pytest.approx([min(m.T for m in rows), max(m.T for m in rows)], abs=1e-4)
        vibe = [m for m in ref["VIBE"] if m.IMU == inst]
        assert r.clip.last == vibe[-1].Clip
        assert r.vibration_max == pytest.approx([max(m.VibeX for m in vibe), max(m.VibeY for m in vibe),
                                                 max(m.VibeZ for m in vibe)], rel=1e-6)
    assert len(view.imus) == len({m.I for m in ref["IMU"]}) == 2


def test_dataflash_old_layout_and_err_match_dfreader(shared_data):
    path = shared_data / "ardupilot" / "dronekit_log171.bin"
    view = from_dataflash(df.open_log(path))
    ref = _dfreader(path, ("IMU", "IMU2", "IMU3", "ERR"))
    for inst, name in enumerate(("IMU", "IMU2", "IMU3")):
        rows = ref[name]
        r = view.imu(inst)
        assert r.gyro_errors.field == f"{name}.ErrG" and r.gyro_errors.last == rows[-1].ErrG
        assert r.accel_errors.last == rows[-1].ErrA and r.gyro_errors.first == rows[0].ErrG
    err = [(m.Subsys, m.ECode) for m in ref["ERR"] if m.Subsys in (1, 12, 16, 24, 26, 29)]
    assert [(16 if e.subsystem == "EKFCHECK" else -1, e.code) for e in view.events] == err
    assert [e.text() for e in view.events] == ["241.9 s ERR EKFCHECK: bad variance", "244.5 s ERR EKFCHECK: resolved"]


def test_dataflash_unhealthy_gyro_written_by_hand_is_flagged_and_reported(tmp_path, capsys):
    """A 4.x log whose IMU2 has GH = 0 from 12.0 to 30.5 s and EG rising by 7: the intervals and the rise are
    read back, and ``analyze`` names IMU2 with the autopilot's reason."""
    from companion.sim.dataflash_writer import write_imu_log

    rng = np.random.default_rng(4)
    t = np.arange(0, 60.0, 0.02)
    gyro = rng.normal(0, 0.002, (3, t.shape[0], 3))
    accel = np.tile([0.0, 0.0, -9.81], (3, t.shape[0], 1)) + rng.normal(0, 0.02, (3, t.shape[0], 3))
    path = tmp_path / "gh.bin"
    write_imu_log(path, t, gyro, accel, layout="4.x")
    buf = bytearray(path.read_bytes())
    log = df.open_log(path)
    fmt = log.formats[log.names["IMU"]]
    off = log.offsets[log.names["IMU"]]
    rec = log.records("IMU")
    gh_at, eg_at = 3 + fmt.dtype.fields["GH"][1], 3 + fmt.dtype.fields["EG"][1]
    tt = rec["TimeUS"] * 1e-6
    for o, ti, i in zip(off, tt, rec["I"]):
        if i == 2 and 12.0 <= ti < 30.5:
            buf[o + gh_at] = 0
        if i == 2:
            buf[o + eg_at:o + eg_at + 4] = int(min(max(ti - 40.0, 0), 7)).to_bytes(4, "little")
    path.write_bytes(bytes(buf))
    r = from_dataflash(df.open_log(path)).imu(2)
    gh = next(u for u in r.unhealthy if u.field == "IMU.GH")
    assert gh.intervals == [(pytest.approx(12.0), pytest.approx(30.5))]
    assert r.gyro_errors.rise == 7 and r.gyro_errors.first_rise_s == pytest.approx(41.0)
    out = tmp_path / "r.json"
    assert main(["analyze", str(path), "--axes", "gx", "--quiet", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert ("autopilot: IMU2: autopilot: gyro unhealthy (IMU.GH) 12.0-30.5 s; gyro error count rose by 7 (IMU.EG, "
            "first at 41.0 s) | ours: nothing found (autopilot only)") in text
    assert "autopilot: IMU0: autopilot: nothing wrong" in text
    doc = json.loads(out.read_text())
    by = {s["instance"]: s["autopilot"] for s in doc["streams"]}
    assert by[2]["autopilot_flagged"] is True and by[2]["verdict"] == "autopilot only"
    assert by[0]["autopilot_flagged"] is False
    assert doc["sources"][0]["autopilot"]["view"]["imus"][2]["unhealthy"][0]["intervals"] == [[12.0, 30.5]]


def test_ulog_matches_pyulog(shared_data):
    from pyulog import ULog

    path = shared_data / "px4" / "pyulog_sample_logging_tagged_and_default_params.ulg"
    res = load(path)
    view = res.meta["autopilot"]
    u = ULog(str(path), ["vehicle_imu_status", "sensors_status_imu"])
    status = {d.multi_id: d.data for d in u.data_list if d.name == "vehicle_imu_status"}
    voter = next(d.data for d in u.data_list if d.name == "sensors_status_imu")
    assert sorted(status) == [r.instance for r in view.imus] == [0, 1, 2]
    for i, d in status.items():
        r = view.imu(i)
        assert r.gyro_errors.last == d["gyro_error_count"][-1] and r.accel_errors.last == d["accel_error_count"][-1]
        clip = sum(d[f"accel_clipping[{k}]"].astype(float) for k in range(3))
        assert r.clip.last == clip[-1] and r.clip.first == clip[0]
        assert r.gyro_vibration_max == pytest.approx(float(d["gyro_vibration_metric"].max()))
        slot = next(k for k in range(4) if voter[f"gyro_device_ids[{k}]"][-1] == d["gyro_device_id"][-1])
        healthy = voter[f"gyro_healthy[{slot}]"]
        gh = next(x for x in r.unhealthy if x.field == "sensors_status_imu.gyro_healthy")
        assert (gh.intervals == []) == bool(np.all(healthy))
        assert r.gyro_inconsistency_max == pytest.approx(float(np.abs(voter[f"gyro_inconsistency_rad_s[{slot}]"]).max()))
    assert res.totals["frames"] == sum(res.messages.values())  # the health topics are not counted as IMU topics


def test_tlog_matches_pymavlink(shared_data):
    from pymavlink import mavutil

    path = shared_data / "tlogs" / "ardusub_2023-04-18.tlog"
    view = load(path).meta["autopilot"]
    m = mavutil.mavlink_connection(str(path))
    unhealthy_gyro, vib = 0, []
    while True:
        msg = m.recv_match(type=["SYS_STATUS", "VIBRATION"])
        if msg is None:
            break
        if msg.get_type() == "SYS_STATUS":
            unhealthy_gyro += not (msg.onboard_control_sensors_health & 1)
        else:
            vib.append((msg.vibration_x, msg.vibration_y, msg.vibration_z, msg.clipping_0))
    r = view.imu(0)
    assert "SYS_STATUS" in view.fields and "VIBRATION" in view.fields
    assert unhealthy_gyro == 0 and all(u.intervals == [] for u in r.unhealthy)
    v = np.array(vib)
    assert r.vibration_max == pytest.approx(list(v[:, :3].max(axis=0)), rel=1e-6)
    assert r.clip.last == v[-1, 3]


@pytest.mark.skipif(not (REALLOGS / "tlogs_extra" / "phoenix_mission1.tlog").exists(), reason="fetched logs absent")
def test_real_tlog_unhealthy_gyro_intervals_match_pymavlink():
    """An ArduPilot tlog whose SYS_STATUS marks the gyros unhealthy twice for about a second: the same number of
    intervals, each as long (+-0.5 s: SYS_STATUS comes at 1-2 Hz and its time is the nearest IMU message's)."""
    from pymavlink import mavutil

    path = REALLOGS / "tlogs_extra" / "phoenix_mission1.tlog"
    m = mavutil.mavlink_connection(str(path))
    ref, start = [], None
    while True:
        msg = m.recv_match(type=["SYS_STATUS"])
        if msg is None:
            break
        if msg.get_srcSystem() != 1:
            continue
        used = msg.onboard_control_sensors_present & msg.onboard_control_sensors_enabled & 1
        bad = used and not (msg.onboard_control_sensors_health & 1)
        if bad and start is None:
            start = msg._timestamp
        elif not bad and start is not None:
            ref.append(msg._timestamp - start)
            start = None
    r = load(path).meta["autopilot"].imu(0)
    got = [b - a for a, b in next(u for u in r.unhealthy if u.sensor == "gyro").intervals]
    assert len(got) == len(ref) == 2
    assert got == pytest.approx(ref, abs=0.5)


def _px4_tlog(path, gyro2_bad=(12.0, 30.5), clip_from=20.0, clip_total=140, base_mode=0):
    """A PX4 vehicle's tlog written message by message with pymavlink: RAW_IMU of 3 IMUs at 50 Hz for 60 s,
    HEARTBEAT at 1 Hz, SYS_STATUS at 2 Hz with 3D_GYRO2 unhealthy over ``gyro2_bad``, VIBRATION at 1 Hz with
    clipping_1 rising by 10 a second from ``clip_from`` up to ``clip_total``."""
    from companion.mavlink.tlog_writer import TlogWriter

    rng = np.random.default_rng(7)
    sensors = 1 | 2 | (1 << 17) | (1 << 18)
    t0 = 1.7e9
    with TlogWriter(path) as w:
        mav = w.mav
        for k in range(3000):
            t = k * 0.02
            if k % 50 == 0:
                w.write(mav.heartbeat_encode(2, 12, base_mode, 0, 3), t0 + t)
                clip = int(min(max(t - clip_from, 0) * 10, clip_total))
                w.write(mav.vibration_encode(int(t * 1e6), 1.0, 1.2, 2.0, 0, clip, 0), t0 + t)
            if k % 25 == 0:
                health = sensors & ~(1 << 17) if gyro2_bad[0] <= t < gyro2_bad[1] else sensors
                w.write(sys_status(mav, sensors, health), t0 + t)
            for i in range(3):
                g = rng.integers(-3, 4, 3)
                w.write(mav.raw_imu_encode(int(t * 1e6), 0, 0, 1000, g[0], g[1], g[2], 0, 0, 0, i, 0), t0 + t)


def test_tlog_sys_status_and_vibration_written_by_hand(tmp_path, capsys):
    path = tmp_path / "px4.tlog"
    _px4_tlog(path)
    view = load(path).meta["autopilot"]
    r1 = view.imu(1)
    assert r1.reasons() == ["gyro unhealthy (SYS_STATUS) 12.0-30.5 s",
                            "clip count rose by 140 (VIBRATION.clipping_1, first at 21.0 s)"]
    assert not view.imu(0).flagged() and not view.imu(2).flagged()  # PX4: 3D_GYRO is the first gyro only
    out = tmp_path / "i.json"
    assert main(["inspect", str(path), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert ("autopilot: IMU1 (sys1): gyro unhealthy (SYS_STATUS) 12.0-30.5 s; clip count rose by 140 "
            "(VIBRATION.clipping_1, first at 21.0 s)") in text
    doc = json.loads(out.read_text())
    assert [i["flagged"] for i in doc["autopilot"]["imus"]] == [False, True, False]


def test_ardupilot_sys_status_gyro_bit_applies_to_every_imu(tmp_path):
    """ArduPilot clears 3D_GYRO when any of its gyros is unhealthy: the interval goes to every IMU of the system."""
    path = tmp_path / "ap.tlog"
    gyro_unhealthy_tlog(path, autopilot=3, imus=2)  # MAV_AUTOPILOT_ARDUPILOTMEGA
    view = load(path).meta["autopilot"]
    for i in (0, 1):
        assert view.imu(i).reasons() == ["gyro unhealthy (SYS_STATUS 3D_GYRO, all IMUs) 5.0-8.0 s"]


def test_analyze_of_an_armed_log_names_the_imu_its_autopilot_flags(tmp_path, capsys):
    """Armed throughout: no still data, the ground figures instead; the autopilot's flagged IMU is named."""
    path = tmp_path / "armed.tlog"
    _px4_tlog(path, base_mode=128)
    assert main(["analyze", str(path), "--axes", "gx", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "autopilot: IMU1: autopilot: gyro unhealthy (SYS_STATUS) 12.0-30.5 s; clip count rose by 140" in out
    assert "IMU0: autopilot: nothing wrong" in out  # every IMU listed; only IMU1 flagged


def test_ulog_preflight_inconsistency_matches_pyulog(shared_data):
    from pyulog import ULog

    path = shared_data / "px4" / "pyulog_sample.ulg"
    view = load(path).meta["autopilot"]
    d = next(d.data for d in ULog(str(path), ["sensor_preflight"]).data_list if d.name == "sensor_preflight")
    assert view.gyro_inconsistency_max == pytest.approx(float(np.abs(d["gyro_inconsistency_rad_s"]).max()))
    assert view.imus == [] and view.fields == ["sensor_preflight"]


@pytest.mark.skipif(not (REALLOGS / "flightreview").is_dir(), reason="fetched logs absent")
def test_ulog_gyro_clipping_rise_matches_pyulog():
    """PX4's EKF-failure log: both IMUs clip (accel), the second's gyro too; each rise as pyulog's values give it."""
    from pyulog import ULog

    path = REALLOGS / "flightreview" / "crates_converter_tests_fixtures_ekf_failure.ulg"
    view = load(path).meta["autopilot"]
    for d in ULog(str(path), ["vehicle_imu_status"]).data_list:
        r = view.imu(d.multi_id)
        for rec, which in ((r.clip, "accel_clipping"), (r.gyro_clip, "gyro_clipping")):
            total = sum(d.data[f"{which}[{k}]"].astype(float) for k in range(3))
            assert rec.rise == float(np.sum(np.clip(np.diff(total), 0, None)))  # no reboot in this log
    assert [r.flagged() for r in view.imus] == [True, True]
    assert view.imu(1).gyro_clip.rise > 0 and view.imu(0).gyro_clip.rise == 0


@pytest.mark.network
def test_inspect_live_link_shows_the_autopilots_sys_status(tmp_path, capsys):
    """A PX4 vehicle on UDP whose SYS_STATUS marks the second gyro unhealthy from its 50th IMU message on:
    ``inspect`` on the link names IMU1 with that reason, in the text and the JSON."""
    import socket
    import threading
    import time

    from pymavlink.dialects.v20 import ardupilotmega as dialect

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    stop = threading.Event()
    sensors = 1 | 2 | (1 << 17) | (1 << 18)

    def sender():
        mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        k = 0
        t_end = time.monotonic() + 120.0  # until the test stops it; bounded
        while not stop.is_set() and time.monotonic() < t_end:
            msgs = [mav.raw_imu_encode(1_000_000 + k * 10_000, 0, 0, -1000, 1, 2, 3, 0, 0, 0, i, 4000) for i in (0, 1)]
            if k % 10 == 0:
                msgs.append(mav.heartbeat_encode(2, 12, 0, 0, 3))
                msgs.append(sys_status(mav, sensors, sensors & ~(1 << 17) if k >= 50 else sensors))
            for m in msgs:
                sock.sendto(m.pack(mav), ("127.0.0.1", port))
                mav.seq = (mav.seq + 1) % 256
            k += 1
            time.sleep(0.01)
        sock.close()

    th = threading.Thread(target=sender, daemon=True)
    th.start()
    out = tmp_path / "live.json"
    try:
        rc = main(["inspect", f"udpin:127.0.0.1:{port}", "--duration", "2", "--json", str(out)])
    finally:
        stop.set()
        th.join(5)
    assert rc == 4  # the sender's gyro reads a constant 1, 2, 3 mrad/s: inspect names it (exit status 4)
    text = capsys.readouterr().out
    line = next(x for x in text.splitlines() if x.startswith("autopilot: IMU1"))
    assert line.startswith("autopilot: IMU1 (sys1): gyro unhealthy (SYS_STATUS) ")
    doc = json.loads(out.read_text())
    assert doc["autopilot"]["format"] == "live"
    assert [i["flagged"] for i in doc["autopilot"]["imus"]] == [False, True]


def test_another_components_sys_status_does_not_end_an_unhealthy_interval(tmp_path):
    """A companion computer (compid 191) of the same system sends SYS_STATUS without IMU bits between the
    autopilot's: the autopilot's interval stays one."""
    from companion.mavlink.tlog_writer import TlogWriter

    path = tmp_path / "cc.tlog"
    with TlogWriter(tmp_path / "unused.tlog", compid=191) as other:
        cc = other.mav

        def companion_sys_status(w, t):
            w.write_raw(sys_status(cc, 1 << 5, 1 << 5).pack(cc), T0 + t + 0.01)

        gyro_unhealthy_tlog(path, autopilot=12, beside=companion_sys_status)  # MAV_AUTOPILOT_PX4
    r = load(path).meta["autopilot"].imu(0)
    assert r.reasons() == ["gyro unhealthy (SYS_STATUS) 5.0-8.0 s"]
