"""The autopilot's view of its IMUs (health/autopilot_view.py): counters, unhealthy intervals, the cross-check."""

from __future__ import annotations

import numpy as np

from companion.health.autopilot_view import (AutopilotEvent, AutopilotImu, AutopilotView, bad_intervals, count_rise,
                                              cross_check, unhealthy, view_lines)


def test_count_rise_sums_increases_and_restarts_at_a_reboot():
    t = np.arange(8.0)
    v = np.array([5, 5, 7, 7, 10, 0, 3, 3], float)  # 5 counted before logging; +2, +3; reboot; +3
    c = count_rise(t, v, "IMU.EG")
    assert (c.first, c.last, c.rise, c.first_rise_s) == (5.0, 3.0, 8.0, 2.0)
    flat = count_rise(t, np.full(8, 4.0), "IMU.EG")
    assert flat.rise == 0 and flat.first_rise_s is None
    assert count_rise(t, np.full(8, np.nan), "x") is None


def test_bad_intervals_run_from_the_first_bad_record_to_the_next_good_one():
    t = np.arange(0.0, 10.0, 0.5)
    ok = ~((t >= 2.0) & (t < 3.5)) & (t < 8.0)
    assert bad_intervals(t, ok) == [(2.0, 3.5), (8.0, 9.5)]
    assert bad_intervals(t, np.ones(t.shape[0], bool)) == []


def test_unhealthy_names_the_boot_of_each_interval():
    t = np.r_[np.arange(0.0, 20.0), np.arange(0.0, 20.0)]  # a reboot at record 20
    ok = np.ones(40, bool)
    ok[25:28] = False
    u = unhealthy(t, ok, "SYS_STATUS", "gyro")
    assert u.intervals == [(5.0, 8.0)] and u.boots == [2]
    assert u.text() == "gyro unhealthy (SYS_STATUS) 5.0-8.0 s (boot 2)"


def _flagged_view() -> AutopilotView:
    t = np.arange(0.0, 40.0, 0.5)
    imu1 = AutopilotImu(1, fields=["SYS_STATUS.gyro2", "VIBRATION.clipping_1"])
    imu1.unhealthy.append(unhealthy(t, ~((t >= 12.0) & (t < 30.5)), "SYS_STATUS", "gyro"))
    imu1.clip = count_rise(t, np.clip((t - 20.0) * 10, 0, 140), "VIBRATION.clipping_1")
    imu0 = AutopilotImu(0, fields=["SYS_STATUS.gyro"])
    imu0.unhealthy.append(unhealthy(t, np.ones(t.shape[0], bool), "SYS_STATUS", "gyro"))
    return AutopilotView("tlog", [imu0, imu1], [AutopilotEvent(3.0, "EKFCHECK", 2)], ["SYS_STATUS", "VIBRATION"])


def test_a_flagged_imu_is_in_the_cross_check_with_the_autopilots_reason_whatever_we_found():
    view = _flagged_view()
    checks = {c.instance: c for c in cross_check(view, {0: [], 1: []}, [0, 1, 2])}
    c1 = checks[1]
    assert c1.autopilot == ["gyro unhealthy (SYS_STATUS) 12.0-30.5 s",
                            "clip count rose by 140 (VIBRATION.clipping_1, first at 20.5 s)"]
    assert c1.verdict == "autopilot only"
    assert c1.line().startswith("IMU1: autopilot: gyro unhealthy (SYS_STATUS) 12.0-30.5 s; clip count rose by 140")
    assert checks[0].verdict == "both healthy" and checks[0].autopilot == []
    assert checks[2].verdict == "no autopilot health data"
    both = {c.instance: c for c in cross_check(view, {1: ["stuck X"]})}
    assert both[1].verdict == "both flag it" and "ours: stuck X" in both[1].line()
    ours_only = {c.instance: c for c in cross_check(view, {0: ["dead"]})}
    assert ours_only[0].verdict == "ours only"
    d = c1.to_dict()
    assert d["autopilot_flagged"] is True and d["line"] == c1.line()


def test_counts_above_zero_at_the_start_are_shown_not_flagged():
    r = AutopilotImu(0)
    r.gyro_errors = count_rise(np.arange(5.0), np.full(5, 12.0), "IMU.ErrG")
    assert not r.flagged()
    assert r.summary() == "nothing wrong: gyro errors 12 (from the start)"


def test_view_lines_and_json():
    view = _flagged_view()
    lines = view_lines(view)
    assert lines[1].startswith("autopilot: IMU1: gyro unhealthy (SYS_STATUS) 12.0-30.5 s; clip count rose by 140")
    assert lines[-1] == "autopilot: 3.0 s ERR EKFCHECK: bad variance"
    d = view.to_dict()
    assert [r["flagged"] for r in d["imus"]] == [False, True]
    assert d["imus"][1]["unhealthy"][0]["intervals"] == [[12.0, 30.5]]
