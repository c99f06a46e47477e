"""Ground and flight conditions (companion.analysis.conditions) and the analyze report's ``flight``/``ground``
entries on a log without still data (armed throughout: analysed, not refused)."""

from __future__ import annotations

import math

import numpy as np

from companion.analysis.conditions import condition_intervals
from tests.redundancy.synthetic import RATE, body_rate

DEG = math.radians(1.0) / 60.0


def _log(seconds=100.0, armed=(20.0, 80.0), air=(30.0, 70.0), seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE)) / RATE
    g = rng.normal(0.0, 1e-3, (t.shape[0], 3))
    on = (t >= armed[0]) & (t < armed[1])
    g[on] += 0.05 * np.sin(2 * np.pi * 90.0 * t[on])[:, None]  # motors: vibration that averages out
    fly = (t >= air[0]) & (t < air[1])
    g[fly] += body_rate(t[fly])
    return t, g


def test_ground_and_flight_from_armed_state_and_motion():
    t, g = _log()
    c = condition_intervals(t, g, [(20.0, True), (80.0, False)], True)
    assert c["method"] == "armed state + motion"
    ground = sum(b - a for a, b in c["ground"])
    flight_s = sum(b - a for a, b in c["flight"])
    assert 10.0 <= ground <= 20.0  # 2 x 10 s on the ground, edges trimmed
    assert all(20.0 <= a and b <= 30.5 or 69.5 <= a and b <= 80.0 for a, b in c["ground"])
    assert 36.0 <= flight_s <= 41.0 and all(28.5 <= a and b <= 71.5 for a, b in c["flight"])


def test_without_armed_state_motion_only_and_no_ground():
    t, g = _log()
    c = condition_intervals(t, g, [], False)
    assert c["ground"] == [] and c["method"].startswith("motion only")
    assert sum(b - a for a, b in c["flight"]) >= 36.0


#: three IMUs of known N armed from the first sample to the last (no still data), 240 s
ARMED = dict(seed=5, n_true=[0.8 * DEG, 1.6 * DEG, 2.4 * DEG], seconds=240.0, offsets=[0.0, 0.001, 0.0005])


def test_an_armed_throughout_log_is_analysed_in_flight(armed_flight):
    """A DataFlash log armed from its first to its last sample (no still data) with three IMUs of known N:
    analyze gives each IMU's in-flight N (the hat) within its interval's reach instead of refusing."""
    res = armed_flight(**ARMED)
    entries, summary = res.entries, res.summary
    assert any("no still data" in n for n in summary["notes"])
    assert len(entries) == 3
    for i, e in enumerate(sorted(entries, key=lambda e: e["instance"])):
        f = e["flight"]
        assert f["seconds"] > 200 and f["method"].startswith("three-cornered hat")
        for r in f["axes"].values():
            wn = [x for x in r["terms"] if x["effect"] == "white_noise"]
            assert wn, r["bounds"]
            lo, hi = wn[0]["ci95"]["N"]
            width = hi - lo
            assert lo - width <= res.n_true[i] <= hi + width
        assert set(e["ground"]) >= {"axes", "seconds", "method"}


def test_the_table_gives_each_imus_flight_figure(armed_flight):
    """The same log's analysis in analyze's table: a flight line for each of the three IMUs, by the hat."""
    from companion.analysis.report_table import format_table

    res = armed_flight(**ARMED)
    table = format_table({"streams": res.entries, "sources": [res.summary]})
    assert table.count("flight: ") == 3 and "three-cornered hat" in table


def test_one_imu_armed_on_the_ground_gets_a_ground_figure(tmp_path):
    """One IMU, armed throughout and not moving (motors running on the ground): its Allan analysis over the
    ground stretch, N of the white noise written (std 1e-3 rad/s at 100 Hz: N = 1e-4) within its interval's
    reach, and the note that the vibration is in it."""
    from companion.analysis.source import analyze_source
    from companion.sim.dataflash_writer import write_imu_log

    rng = np.random.default_rng(8)
    t = 1.0 + np.arange(20000) / 100.0
    g = rng.normal(0.0, 1e-3, (1, t.shape[0], 3))
    a = rng.normal(0.0, 0.01, (1, t.shape[0], 3)) + [0.0, 0.0, -9.8]
    path = tmp_path / "ground.bin"
    write_imu_log(path, t, g, a, armed=[(0.5, True)])
    entries, summary = analyze_source(str(path), ["gx", "gy", "gz"])
    gr = entries[0]["ground"]
    assert gr["method"] == "one IMU" and "vibration" in gr["notes"][0] and gr["seconds"] > 150
    for r in gr["axes"].values():
        wn = [x for x in r["terms"] if x["effect"] == "white_noise"][0]
        lo, hi = wn["ci95"]["N"]
        assert lo - (hi - lo) <= 1e-4 <= hi + (hi - lo)
    assert entries[0]["flight"]["method"] == "none"
