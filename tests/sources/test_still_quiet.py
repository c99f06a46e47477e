"""Still selection on quiet logs: slow telemetry (1-2 Hz), noise that is not white at the window's scale, two IMUs
that look alike; and refusals that say why and name the option that works.

Truth: simulated records whose rest and motion times are known, and the real bench tlog of ../shared/data judged
by the independent block rule of benchmarks/stills_reference.py (skipped without the data)."""

from __future__ import annotations

import numpy as np
import pytest

from companion.samples import StreamKey
from companion.sources import build_stream
from companion.sources.decode import RawStream
from companion.sources.still import select_still

G = np.array([0.0, 0.0, -9.80665])


def _stream(instance, t, gyro, accel, message="RAW_IMU"):
    return build_stream(RawStream(StreamKey(1, 1, message, instance), t, gyro, accel, None, True, None, None, 1e-6))


def _bench(seed, rate=1.3, duration=1800.0, events=((600.0, 620.0), (1200.0, 1230.0)), wander=6.0):
    """Two IMUs on a bench at ``rate`` Hz: white noise plus a wander of the means (an AR(1) over about two windows
    of the selection whose window means scatter ``wander`` x what white noise allows), and ``events`` where the
    vehicle is turned by hand (0.2 rad/s about z, the accelerometers shaken)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate)
    move = np.zeros(t.size, dtype=bool)
    for a, b in events:
        move |= (t >= a) & (t < b)
    out = []
    for k in range(2):
        sg, sa = 0.0015, 0.008
        window = max(1.0, 16.0 / rate)
        phi = np.exp(-1.0 / (2.0 * window * rate))
        ar = np.zeros((t.size, 6))
        e = rng.normal(0, 1, (t.size, 6))
        for i in range(1, t.size):
            ar[i] = phi * ar[i - 1] + np.sqrt(1 - phi**2) * e[i]
        # the AR's window means scatter about its own sigma: wander x the white error of a window mean
        k = np.sqrt(window * rate)
        g = rng.normal(0, sg, (t.size, 3)) + ar[:, :3] * wander * sg / k
        a = G + rng.normal(0, sa, (t.size, 3)) + ar[:, 3:] * wander * sa / k
        g[move, 2] += 0.2 * np.sign(np.sin(2 * np.pi * 0.05 * t[move]))
        a[move] += rng.normal(0, 0.5, (int(move.sum()), 3))
        out.append(_stream(k, t, g, a, "RAW_IMU" if k == 0 else "SCALED_IMU2"))
    return out, events


def _inside(iv, a, b):
    return sum(max(0.0, min(y, b) - max(x, a)) for x, y in iv)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("rate", [1.3, 50.0])
def test_a_bench_log_with_wandering_means_is_kept_and_its_handling_left_out(seed, rate):
    streams, events = _bench(seed, rate=rate, duration=1800.0 if rate < 10 else 600.0,
                             events=((600.0, 620.0), (1200.0, 1230.0)) if rate < 10 else ((200.0, 220.0),))
    rest = (1800.0 if rate < 10 else 600.0) - sum(b - a for a, b in events)
    sel = select_still(streams, {"has_armed_state": True, "armed": []})
    for s in streams:
        kept = [(float(s.t[a]), float(s.t[b - 1])) for a, b in sel.ranges(s)]
        assert sum(b - a for a, b in kept) >= 0.8 * rest, (seed, s.key, sel.describe(), sel.notes)
        for a, b in events:  # no second of the handling
            assert _inside(kept, a, b) == 0.0, (seed, s.key, kept)
    assert not sel.excluded, sel.notes  # both IMUs look alike: neither gyro is set aside


def test_a_slow_turn_on_a_wandering_bench_is_still_motion():
    """The wider mean test must still see a steady turn of 0.02 rad/s (1.1 deg/s) that both gyros share."""
    streams, _ = _bench(7, events=())
    for s in streams:
        turn = (s.t >= 900.0) & (s.t < 1000.0)
        s.gyro[turn, 2] += 0.02
    sel = select_still(streams, {"has_armed_state": True, "armed": []})
    assert _inside(sel.intervals, 905.0, 995.0) == 0.0, sel.intervals


def test_armed_throughout_the_window_says_so_and_suggests_all_not_start_end():
    streams, _ = _bench(1, events=())
    meta = {"has_armed_state": True, "armed": [(500.0, True), (900.0, False)]}
    sel = select_still(streams, meta, start=600.0, end=800.0)
    assert not sel.intervals
    note = sel.notes[0]
    assert "armed throughout the --start/--end window" in note and "--all" in note, note
    assert "use --start/--end" not in note and "--start/--end --all" not in note, note
    # --all then analyses that window
    assert select_still(streams, meta, start=600.0, end=800.0, use_all=True).intervals


def test_only_short_still_stretches_suggest_min_still_with_their_length():
    rate = 50.0
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 60.0, 1.0 / rate)
    g = rng.normal(0, 0.002, (t.size, 3))
    a = G + rng.normal(0, 0.01, (t.size, 3))
    for c in (8.0, 22.0, 36.0, 50.0):  # a knock every 14 s: still stretches of about 8 s between the guards
        k = (t >= c) & (t < c + 1.0)
        a[k] += rng.normal(0, 2.0, (int(k.sum()), 3))
    sel = select_still([_stream(0, t, g, a)], {})
    assert not sel.intervals
    note = sel.notes[0]
    assert "longest still stretch of the record is" in note and "--min-still" in note and "--all" in note, note
    n = int(note.split("--min-still ")[1].split()[0])
    assert select_still([_stream(0, t, g, a)], {}, min_segment_s=n).intervals


def test_the_real_bench_tlog_is_used_where_the_independent_rule_finds_rest(shared_data):
    """ardusub_2023-04-18.tlog (never armed, 2 Hz): >= 80 % of the reference's still time analysed, nothing of its
    moving time."""
    from benchmarks.bench_stills import used_intervals
    from benchmarks.stills_reference import intersect, length, reference
    from companion.sources import load

    res = load(str(shared_data / "tlogs" / "ardusub_2023-04-18.tlog"))
    ref = reference(res.imu_streams(), res.meta)
    assert ref.still_s >= 200.0, ref.still  # the data's README: about 270 s at rest, then handled
    sel = select_still(res.imu_streams(), res.meta)
    for inst, iv in used_intervals(sel, res.imu_streams()).items():
        assert length(intersect(iv, ref.still)) >= 0.8 * ref.still_s, (inst, iv, ref.still)
        assert length(intersect(iv, ref.moving)) == 0.0, (inst, iv, ref.moving)


def test_no_stream_analysed_names_each_streams_reason_and_all_where_it_works(tmp_path):
    """A 1 Hz log handled every 24 s: its still stretches (10-13 s between the guards) hold fewer than the 16
    samples of a stream any Allan estimate needs. The refusal names each stream and --all, which analyses the
    record (one gap-free piece of 80 samples)."""
    import subprocess
    import sys

    from companion.sim.dataflash_writer import write_imu_log

    rng = np.random.default_rng(5)
    t = np.arange(0.0, 80.0, 1.0)
    g = rng.normal(0, 0.002, (t.size, 3))
    a = G + rng.normal(0, 0.01, (t.size, 3))
    for c in (18.0, 42.0, 66.0):
        k = (t >= c) & (t < c + 3.0)
        a[k] += rng.normal(0, 2.0, (int(k.sum()), 3))
        g[k] += rng.normal(0, 0.5, (int(k.sum()), 3))
    p = tmp_path / "slow.bin"
    write_imu_log(p, t, np.stack([g, g + 1e-3]), np.stack([a, a]))
    cmd = [sys.executable, "-m", "companion", "analyze", str(p)]
    out = subprocess.run(cmd, capture_output=True, text=True)
    assert out.returncode != 0
    err = out.stderr.strip()
    assert err.startswith("companion: error: no IMU stream analysed") and err.count("not analysed") == 2, err
    assert "IMU[0]" in err and "IMU[1]" in err and "--all analyses it" in err, err
    assert "Traceback" not in out.stderr
    ok = subprocess.run(cmd + ["--all"], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr


def test_one_gyro_drifting_about_a_horizontal_axis_is_not_a_turn_but_a_yaw_is():
    """One IMU at rest, gravity along z: its gyro bias drifts 20 mrad/s about y over 300 s (the accelerometer does
    not tilt, so nothing turned) -- kept; the same size of rate about z (a yaw the accelerometer cannot see) for
    60 s -- motion."""
    rate = 50.0
    rng = np.random.default_rng(11)
    t = np.arange(0.0, 400.0, 1.0 / rate)
    g = rng.normal(0, 0.002, (t.size, 3))
    a = G + rng.normal(0, 0.01, (t.size, 3))
    g[:, 1] += 0.02 * np.clip((t - 50.0) / 300.0, 0.0, 1.0)
    sel = select_still([_stream(0, t, g, a)], {})
    assert sel.still_s >= 0.95 * 400.0, (sel.describe(), sel.intervals)
    yaw = (t >= 200.0) & (t < 260.0)
    g[yaw, 2] += 0.02
    sel = select_still([_stream(0, t, g, a)], {})
    assert _inside(sel.intervals, 203.0, 257.0) == 0.0, sel.intervals
