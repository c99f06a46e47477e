"""Still selection (`analyze`, `gap`, `fleet`) when one IMU's gyro changes alone: a gyro frozen at a rate, a
bias step, must not take the other IMUs' rest out of the analysis, and must not be analysed over its fault;
a rotation that only the quieter of two gyros can see is still motion."""

from __future__ import annotations

import numpy as np

from companion.samples import StreamKey
from companion.sources import build_stream
from companion.sources.decode import RawStream
from companion.sources.still import select_still

RATE = 50.0
G = np.array([0.0, 0.0, -9.80665])
SIG_G = 1e-4 * np.sqrt(RATE)  # white rate noise N = 1e-4 rad/s/sqrt(Hz)
SIG_A = 0.01


def _stream(instance, t, gyro, accel):
    return build_stream(RawStream(StreamKey(1, 1, "IMU", instance), t, gyro, accel, None, True, None, None, 1e-6))


def _flight(seed, duration=600.0, flight=(200.0, 300.0), gyro_scale=(1.0, 1.0)):
    """Two IMUs on one airframe: rest, a flight (rotation in every gyro, accel shaken), rest."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / RATE)
    fly = (t >= flight[0]) & (t < flight[1])
    rot = np.zeros((t.size, 3))
    rot[fly] = 0.3 * np.sin(2 * np.pi * 0.2 * t[fly])[:, None]
    out = []
    for k in range(2):
        g = rot + rng.normal(0, SIG_G * gyro_scale[k], (t.size, 3))
        a = G + rng.normal(0, SIG_A, (t.size, 3))
        a[fly] += rng.normal(0, 1.0, (int(fly.sum()), 3))
        out.append((t, g, a))
    return out


def _kept(sel, stream):
    return sum(b - a for a, b in sel.ranges(stream)) / RATE


def test_a_gyro_frozen_in_flight_leaves_its_twins_rest_in_and_its_own_fault_out():
    for seed in range(3):
        (t, g0, a0), (_, g1, a1) = _flight(seed)
        g1[t >= 250.0, 0] = 0.35  # frozen at the rate it read in flight, through the landing and after
        s0, s1 = _stream(0, t, g0, a0), _stream(1, t, g1, a1)
        sel = select_still([s0, s1], {})
        # the vehicle rested 0-200 and 300-600 s: both in for the healthy IMU (less the 3-s guards)
        assert 480.0 <= _kept(sel, s0) <= 500.0, (seed, sel.intervals)
        # the frozen IMU: its rest before the fault only (200 s), never its constant 0.35 after the landing
        assert 190.0 <= _kept(sel, s1) <= 200.0, (seed, sel.ranges(s1))
        assert all(t[b - 1] < 250.0 for a, b in sel.ranges(s1))
        assert any("IMU instance 1" in n and "gyro was frozen" in n for n in sel.notes), sel.notes


def test_one_imu_frozen_gyro_still_counts_as_motion_and_its_healthy_rest_stays():
    """Alone, a gyro at a rate cannot be told from a slow turn: out, as before. Its windows of identical values
    must not set the axis' noise floor (their spread is 0, not a rounding residue), or every healthy window at
    rest is 'moving' and the log has no still data at all."""
    (t, g0, a0), _ = _flight(4)
    g0[t >= 400.0, 2] = 0.35
    s0 = _stream(0, t, g0, a0)
    sel = select_still([s0], {})
    assert sel.intervals, sel.describe()
    kept = _kept(sel, s0)
    assert 285.0 <= kept <= 300.0, sel.intervals  # 0-200 and 300-400 less the guards
    assert all(b <= 400.0 for a, b in sel.intervals)
    assert not sel.excluded


def test_a_slow_turn_only_the_quieter_gyro_sees_is_motion_for_both():
    """IMU1 is 7x noisier than IMU0: a 0.008 rad/s turn lies above IMU0's limit (5 se + 0.005 rad/s) and
    below IMU1's; IMU1 is no witness that the vehicle was still, so the turn is out for both."""
    for seed in range(3):
        (t, g0, a0), (_, g1, a1) = _flight(10 + seed, gyro_scale=(1.0, 7.0))
        turn = (t >= 450.0) & (t < 470.0)
        g0[turn, 2] += 0.008
        g1[turn, 2] += 0.008
        s0, s1 = _stream(0, t, g0, a0), _stream(1, t, g1, a1)
        sel = select_still([s0, s1], {})
        for s in (s0, s1):
            for a, b in sel.ranges(s):
                assert t[b - 1] < 450.0 or t[a] >= 470.0, (seed, s.key, t[a], t[b - 1])
        assert not sel.excluded


def test_a_bias_step_on_one_gyro_at_rest_keeps_the_other_imus_data():
    (t, g0, a0), (_, g1, a1) = _flight(20)
    g1[t >= 450.0, 1] += 0.0175  # 1 deg/s at rest, IMU1 only
    s0, s1 = _stream(0, t, g0, a0), _stream(1, t, g1, a1)
    sel = select_still([s0, s1], {})
    assert 480.0 <= _kept(sel, s0) <= 500.0, sel.intervals
    # IMU1 is analysed on one side of its step, not across it
    r = sel.ranges(s1)
    assert r and (all(t[b - 1] < 450.0 for a, b in r) or all(t[a] >= 450.0 for a, b in r)), r
    assert 1 in sel.excluded


def test_analyze_says_why_an_imu_frozen_throughout_the_rest_is_not_analysed(tmp_path, capsys):
    """IMU1's gyro frozen from the flight on, and the only rest after it: analyze keeps IMU0 and says, for
    IMU1, that its own gyro is why (not 'too short')."""
    from companion.cli.main import main
    from companion.sim.dataflash_writer import write_imu_log

    (t, g0, a0), (_, g1, a1) = _flight(30, duration=400.0, flight=(0.0, 100.0))
    g1[t >= 50.0, 0] = 0.35
    p = tmp_path / "pair.bin"
    write_imu_log(p, t, np.stack([g0, g1]), np.stack([a0, a1]))
    assert main(["analyze", str(p), "--axes", "gx"]) == 0
    out = capsys.readouterr()
    text = out.out + out.err
    assert "IMU instance 1" in text and "its gyro was frozen" in text
    assert "not analysed: its gyro changed alone" in text, text
    assert "IMU[0]" in text
