"""Armed state of a tlog from the vehicle's HEARTBEATs, on the IMU messages' own clock.

Truth comes from outside the reader: the simulator's --arm-at/--disarm-at, frames packed and decoded by
pymavlink itself, and pymavlink's reading of the real ArduSub tlog."""

from __future__ import annotations

import json

import numpy as np
import pytest

from companion.cli.main import main
from companion.sources import load
from companion.sources.still import armed_intervals, select_still

GUARD_S = 3.0  # select_still's default guard around armed periods
T0_UNIX = 1.7e9


def _pymavlink_read(path):
    """(vehicle HEARTBEATs [(stamp, sysid, compid, type, autopilot, armed)], RAW_IMU [(stamp, sysid, time s)])
    as pymavlink decodes the file."""
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    hb, imu = [], []
    while True:
        msg = m.recv_match(type=["HEARTBEAT", "RAW_IMU"])
        if msg is None:
            break
        if msg.get_type() == "HEARTBEAT":
            hb.append((msg._timestamp, msg.get_srcSystem(), msg.get_srcComponent(), msg.type, msg.autopilot,
                       bool(msg.base_mode & 128)))
        else:
            imu.append((msg._timestamp, msg.get_srcSystem(), msg.time_usec * 1e-6))
    m.close()
    return hb, np.array(imu)


def _on_imu_clock(stamp, imu):
    """The IMU clock's time at record stamp ``stamp``: the nearest RAW_IMU's time plus the stamp difference."""
    k = int(np.argmin(np.abs(imu[:, 0] - stamp)))
    return float(imu[k, 2] + (stamp - imu[k, 0]))


def _analyze_selection(path, tmp_path):
    out = tmp_path / "r.json"
    assert main(["analyze", str(path), "--quiet", "--axes", "gx,gy,gz", "--json", str(out)]) == 0
    return json.loads(out.read_text())["sources"][0]["selection"]


def _overlap(intervals, a, b):
    return sum(max(0.0, min(y, b) - max(x, a)) for x, y in intervals)


def test_simulated_vehicle_flight_armed_period_left_out(tmp_path, repo_root, capsys):
    """`companion simulate --vehicle --arm-at A --disarm-at D`: the reader's transitions are the file's
    HEARTBEATs as pymavlink decodes them, and analyze leaves out [A, D] with its guard."""
    path = tmp_path / "flight.tlog"
    assert main(["simulate", str(repo_root / "companion" / "examples" / "sample_model.yaml"), "--duration", "300", "--out", str(path),
                 "--vehicle", "--arm-at", "120", "--disarm-at", "200", "--seed", "4"]) == 0
    hb, imu = _pymavlink_read(path)
    flags = [(s, a) for s, *_, a in hb]
    on = next(s for s, a in flags if a)
    off = next(s for s, a in flags if s > on and not a)
    arm, disarm = _on_imu_clock(on, imu), _on_imu_clock(off, imu)
    # the simulator's clock starts at 1 s since boot, HEARTBEATs at 1 Hz: --arm-at 120 is seen at 121 s
    assert arm == pytest.approx(121.0, abs=1.0) and disarm == pytest.approx(201.0, abs=1.0)
    res = load(path)
    assert res.meta["has_armed_state"]
    got = armed_intervals(res.meta["armed"], 1e9)
    assert len(got) == 1 and got[0] == pytest.approx((arm, disarm), abs=1e-3)
    capsys.readouterr()
    sel = _analyze_selection(path, tmp_path)
    assert sel["method"] == "armed state + motion"
    assert _overlap(sel["intervals"], arm - GUARD_S, disarm + GUARD_S) == 0.0
    assert sel["armed_s"] >= disarm - arm
    assert sel["still_s"] > 200.0  # the rest of the 300 s is still and kept


def _write_bench_tlog(path, vehicle_armed=(), gcs_armed=True, second_system=True, latency_s=0.04,
                      boot_t0=500.0, duration=200.0, reboot_at=None, second_armed=None):
    """A vehicle at rest (RAW_IMU at 50 Hz, noise only) with 1 Hz HEARTBEATs, every frame packed by pymavlink.

    ``vehicle_armed``: [(t0, t1)] boot times (s) where the vehicle's own HEARTBEAT has the armed bit. Other
    senders: a ground station (sys 255, type GCS, autopilot INVALID, armed bit set when ``gcs_armed``), the
    vehicle's companion computer (sys 1 comp 194, type ONBOARD_CONTROLLER) and gimbal (comp 154, type
    GIMBAL, autopilot GENERIC) with the armed bit, and, with ``second_system``, another vehicle (sys 2)
    armed throughout that sends no IMU data. Record stamps: boot time + 1.7e9 + a random link latency of up
    to ``latency_s``. ``reboot_at``: a boot time at which the autopilot restarts (its clock starts again at
    1 s; the stamps go on). ``second_armed``: [(t0, t1)]: the second vehicle also sends RAW_IMU (same clock)
    and is armed only then."""
    from pymavlink.dialects.v20 import ardupilotmega as d

    from companion.mavlink.tlog_writer import TlogWriter

    rng = np.random.default_rng(7)
    senders = {k: d.MAVLink(None, srcSystem=k[0], srcComponent=k[1]) for k in
               [(1, 1), (255, 190), (1, 194), (1, 154), (2, 1)]}
    n = int(duration * 50)
    tb = boot_t0 + np.arange(n) / 50.0  # wall time since the first boot
    clock = tb.copy()
    if reboot_at is not None:
        clock[tb >= reboot_at] = tb[tb >= reboot_at] - reboot_at + 1.0
    events = [(float(t), 1, k) for k, t in enumerate(tb)]
    events += [(float(t), 0, -1) for t in np.arange(np.ceil(boot_t0), boot_t0 + duration)]
    events.sort()
    with TlogWriter(path) as w:
        for t, kind, k in events:
            stamp = T0_UNIX + t + rng.uniform(0.0, latency_s)
            if kind == 1:
                g = np.rint(rng.normal(0.0, 3.0, 3)).astype(int)
                a = np.rint(rng.normal(0.0, 2.0, 3)).astype(int) + np.array([0, 0, -1000])
                mav = senders[(1, 1)]
                msg = mav.raw_imu_encode(int(round(clock[k] * 1e6)), *a.tolist(), *g.tolist(), 0, 0, 0, 0, 4200)
                w.write_raw(msg.pack(mav), stamp)
                if second_armed is not None:
                    mav = senders[(2, 1)]
                    w.write_raw(mav.raw_imu_encode(int(round(clock[k] * 1e6)), *a.tolist(), *g.tolist(), 0, 0, 0, 0,
                                                   4200).pack(mav), stamp)
                continue
            armed = any(a <= t < b for a, b in vehicle_armed)
            frames = [((1, 1), (2, 3, 0x81 if armed else 0x01, 0, 4 if armed else 3))]
            if gcs_armed:
                frames.append(((255, 190), (6, 8, 192, 0, 4)))
            frames += [((1, 194), (18, 8, 128, 0, 3)), ((1, 154), (26, 0, 128, 0, 3))]
            if second_system:
                on = second_armed is None or any(a <= t < b for a, b in second_armed)
                frames.append(((2, 1), (2, 3, 0x81 if on else 0x01, 0, 4)))
            for who, (typ, ap, base, custom, status) in frames:
                mav = senders[who]
                w.write_raw(mav.heartbeat_encode(typ, ap, base, custom, status).pack(mav), stamp)


def test_armed_vehicle_at_rest_is_left_out(tmp_path):
    """Armed while the IMU shows no motion at all (nothing but the HEARTBEAT tells): 560-620 s is left out with
    its guard, on the IMU's clock, though each HEARTBEAT arrives with up to 40 ms of link latency."""
    path = tmp_path / "bench.tlog"
    _write_bench_tlog(path, vehicle_armed=[(560.0, 620.0)])
    hb, imu = _pymavlink_read(path)
    vehicle = [(s, a) for s, sysid, comp, typ, ap, a in hb if (sysid, comp) == (1, 1)]
    arm = _on_imu_clock(next(s for s, a in vehicle if a), imu)
    disarm = _on_imu_clock(next(s for s, a in vehicle if s > T0_UNIX + 561 and not a), imu)
    assert arm == pytest.approx(560.0, abs=0.05) and disarm == pytest.approx(620.0, abs=0.05)
    res = load(path)
    got = armed_intervals(res.meta["armed"], 1e9)
    assert len(got) == 1 and got[0] == pytest.approx((arm, disarm), abs=0.05)
    sel = select_still(res.imu_streams(), res.meta)
    assert sel.method == "armed state + motion"
    assert _overlap(sel.intervals, arm - GUARD_S, disarm + GUARD_S) == 0.0
    assert _overlap(sel.intervals, 500.0, 700.0) == pytest.approx(200.0 - (disarm - arm) - 2 * GUARD_S, abs=2.0)


def test_ground_station_companion_gimbal_and_other_system_heartbeats_do_not_count(tmp_path, capsys):
    """A disarmed vehicle among HEARTBEATs that carry the armed bit: a GCS (QGC sends base_mode 192), the
    vehicle's companion computer and gimbal (same system, other components), and a second, armed vehicle
    that sends no IMU data. None of them is the analysed vehicle's autopilot: never armed, all still."""
    path = tmp_path / "crowd.tlog"
    _write_bench_tlog(path)
    hb, _ = _pymavlink_read(path)
    armed_senders = {(sysid, comp) for _, sysid, comp, *_, a in hb if a}
    assert armed_senders == {(255, 190), (1, 194), (1, 154), (2, 1)}  # the file holds the distractors
    res = load(path)
    assert res.meta["has_armed_state"]
    assert armed_intervals(res.meta["armed"], 1e9) == []
    assert [(s["sysid"], s["compid"]) for s in res.meta["armed_source"]] == [(1, 1)]
    assert res.meta["armed_source"][0]["heartbeats"] == sum(1 for _, sysid, comp, *_ in hb if (sysid, comp) == (1, 1))
    sel = select_still(res.imu_streams(), res.meta)
    assert sel.method == "armed state + motion" and len(sel.intervals) == 1 and sel.still_s > 199.0
    assert main(["inspect", str(path)]) == 0
    assert "log: armed state (HEARTBEAT of sys1/comp1, 200 messages): never armed" in capsys.readouterr().out


def test_two_vehicles_with_imus_each_armed_on_its_own(tmp_path):
    """Two systems send IMU data: each one's armed periods count (the selection takes every IMU of the log)."""
    path = tmp_path / "two.tlog"
    _write_bench_tlog(path, vehicle_armed=[(540.0, 560.0)], second_armed=[(600.0, 630.0)], gcs_armed=True)
    res = load(path)
    assert sorted((s["sysid"], s["compid"]) for s in res.meta["armed_source"]) == [(1, 1), (2, 1)]
    got = armed_intervals(res.meta["armed"], 1e9)
    assert len(got) == 2
    assert got[0] == pytest.approx((540.0, 560.0), abs=0.05) and got[1] == pytest.approx((600.0, 630.0), abs=0.05)


def test_no_vehicle_heartbeat_is_no_armed_state(tmp_path, capsys):
    """Only a ground station's HEARTBEATs: the tlog has no armed state, and inspect says so."""
    from pymavlink.dialects.v20 import ardupilotmega as d

    from companion.mavlink.tlog_writer import TlogWriter

    path = tmp_path / "gcs_only.tlog"
    rng = np.random.default_rng(3)
    veh, gcs = d.MAVLink(None, 1, 1), d.MAVLink(None, 255, 190)
    with TlogWriter(path) as w:
        for k in range(3000):
            t = k / 50.0
            if k % 50 == 0:
                w.write_raw(gcs.heartbeat_encode(6, 8, 192, 0, 4).pack(gcs), T0_UNIX + t)
            g = np.rint(rng.normal(0, 3, 3)).astype(int).tolist()
            w.write_raw(veh.raw_imu_encode(int(t * 1e6), 0, 0, -1000, *g, 0, 0, 0, 0, 0).pack(veh), T0_UNIX + t)
    res = load(path)
    assert not res.meta["has_armed_state"] and res.meta["armed"] == []
    assert select_still(res.imu_streams(), res.meta).method == "motion (no armed state in this source)"
    assert main(["inspect", str(path)]) == 0
    assert "log: armed state: none (no autopilot HEARTBEAT from sys1" in capsys.readouterr().out


def test_armed_after_a_reboot_lands_in_its_boot_session(tmp_path):
    """The autopilot runs from 20 to 120 s since boot, reboots (its clock starts again at 1 s) and is armed
    130 s later: the arming is on the second session's clock (131 s since that boot) and moves with its
    samples when the sessions are laid end to end. Its time (131 s) is later than the first session's
    HEARTBEATs (20-119 s), so only the state repeated at the reboot tells the sessions apart."""
    path = tmp_path / "reboot.tlog"
    _write_bench_tlog(path, vehicle_armed=[(250.0, 270.0)], boot_t0=20.0, duration=300.0, reboot_at=120.0,
                      gcs_armed=False, second_system=False)
    res = load(path)
    (shift,) = [s["shift_s"] for s in res.meta["sessions"][1:]]
    got = armed_intervals(res.meta["armed"], 1e9)
    assert len(got) == 1 and got[0] == pytest.approx((131.0 + shift, 151.0 + shift), abs=0.05)
    sel = select_still(res.imu_streams(), res.meta)
    assert _overlap(sel.intervals, got[0][0] - GUARD_S, got[0][1] + GUARD_S) == 0.0
    assert sel.armed_s == pytest.approx(20.0 + 2 * GUARD_S, abs=2.0)


@pytest.mark.shared
def test_real_ardusub_tlog_vehicle_never_armed_though_gcs_and_companion_say_armed(shared_data, tmp_path, capsys):
    """The real ArduSub tlog: pymavlink decodes HEARTBEATs with the armed bit from QGC (255/190, GCS) and
    from the sub's companion computer (1/194, ONBOARD_CONTROLLER); the sub's autopilot (1/1, SUBMARINE,
    ArduPilot) never sets it. Read as never armed, and the selection says it used the armed state."""
    log = shared_data / "tlogs" / "ardusub_2023-04-18.tlog"
    hb, _ = _pymavlink_read(log)
    armed_senders = {(sysid, comp, typ, ap) for _, sysid, comp, typ, ap, a in hb if a}
    assert armed_senders == {(255, 190, 6, 8), (1, 194, 18, 8)}
    autopilot = [a for _, sysid, comp, typ, ap, a in hb if (sysid, comp) == (1, 1)]
    res = load(log)
    assert res.meta["has_armed_state"] and armed_intervals(res.meta["armed"], 1e9) == []
    assert res.meta["armed_source"] == [{"sysid": 1, "compid": 1, "heartbeats": len(autopilot),
                                         "clock": "RAW_IMU[0] sys1/comp1"}]
    assert main(["inspect", str(log)]) == 0
    assert f"log: armed state (HEARTBEAT of sys1/comp1, {len(autopilot)} messages): never armed" in capsys.readouterr().out
    sel = _analyze_selection(log, tmp_path)
    assert sel["method"] == "armed state + motion" and sel["armed_s"] == 0.0
