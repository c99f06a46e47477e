"""A CSV's time column: its unit decided from the spacing (float noise tolerated), refused when ambiguous or
coarser than the rate, and a time that restarts read as a new segment, never interleaved with the rows before."""

from __future__ import annotations

import numpy as np
import pytest

from companion.cli.main import main
from companion.errors import CompanionError
from companion.sources import load

N = 6000
RATE = 100.0


def _csv(path, t, seed=3):
    rng = np.random.default_rng(seed)
    d = rng.normal(0.0, 1e-3, (t.shape[0], 6))
    d[:, 5] -= 9.80665
    rows = "\n".join(",".join([repr(float(ti))] + [repr(float(v)) for v in r]) for ti, r in zip(t, d))
    path.write_text("time_s,gx,gy,gz,ax,ay,az\n" + rows + "\n")
    return path


def test_ms_with_float_noise_is_refused_not_read_as_seconds(tmp_path, capsys):
    """0.0, 10.0, 20.0, 30.000000000000004, ...: read as 0.1 Hz seconds (N 30x too large) with rc 0."""
    t = np.arange(N) * 0.1 * 100.0  # a 10 ms step computed in floats
    assert t[3] == 30.000000000000004 and not np.all(t == np.round(t))
    p = _csv(tmp_path / "ms.csv", t)
    assert main(["inspect", str(p)]) == 2
    assert capsys.readouterr().err == (
        f"companion: error: {p}: time_s looks like milliseconds (median step 10, whole numbers): pass --time-unit ms "
        "(or divide the column by 1000); --time-unit s if the times really are whole seconds\n")
    s = load(p, time_unit="ms").imu_streams()[0]
    assert s.samples == N and s.timing.rate_hz == pytest.approx(RATE)


def test_an_ambiguous_step_is_refused_with_the_rate_of_each_unit(tmp_path):
    p = _csv(tmp_path / "a.csv", np.arange(N) * 2.5)
    with pytest.raises(CompanionError) as exc:
        load(p)
    assert str(exc.value) == (f"{p}: time_s steps by a median of 2.5: 0.4 Hz in seconds, 400 Hz in milliseconds, "
                              "4e+05 Hz in microseconds; pass --time-unit s, ms or us to say which")
    assert load(p, time_unit="ms").imu_streams()[0].timing.rate_hz == pytest.approx(400.0)


@pytest.mark.parametrize("unit", [None, "s", "ms"])
def test_whole_seconds_at_100_rows_a_second_are_refused(tmp_path, capsys, unit):
    """`--time-unit s` dropped 5,940 of 6,000 rows as duplicates and gave N 8.5x too high."""
    p = _csv(tmp_path / "w.csv", np.floor(np.arange(N) / RATE))
    argv = ["inspect", str(p)] + ([] if unit is None else ["--time-unit", unit])
    assert main(argv) == 2
    assert capsys.readouterr().err == (
        f"companion: error: {p}: 6000 rows carry only 60 distinct times (100 rows per time value): the time "
        "column's resolution is coarser than the sample rate, so the samples cannot be timed; write time_s with "
        "more digits\n")


def test_a_few_repeated_rows_are_still_read(tmp_path):
    t = np.arange(N) / RATE
    t[1::50] = t[0::50][: t[1::50].shape[0]]  # every 50th row repeats the time before it
    s = load(_csv(tmp_path / "r.csv", t)).imu_streams()[0]
    assert s.timing.duplicates == N // 50 and s.timing.rate_hz == pytest.approx(RATE, rel=0.02)


def test_a_time_that_restarts_is_a_new_segment_not_interleaved(tmp_path, capsys):
    """Two 30 s series one after another were sorted into one series of 200 rows a second (only a note)."""
    half = np.arange(N // 2) / RATE
    p = _csv(tmp_path / "two.csv", np.r_[half, half + 0.005])
    res = load(p)
    s = res.imu_streams()[0]
    assert s.samples == N and len(s.segments) == 2
    assert s.timing.rate_hz == pytest.approx(RATE)
    assert s.timing.resets == 1 and s.timing.backwards == 0
    assert ("two.csv: time_s restarts 1 time(s) (line 3002): the rows are read in file order, each restart a new "
            "segment, not sorted into the earlier rows") in res.meta["notes"]
    assert not any("sorted by time_s" in n for n in res.meta["notes"])


def test_shuffled_rows_are_still_sorted(tmp_path):
    t = np.arange(N) / RATE
    o = np.random.default_rng(1).permutation(N)
    res = load(_csv(tmp_path / "shuf.csv", t[o]))
    s = res.imu_streams()[0]
    np.testing.assert_array_equal(s.t, t)
    assert any("sorted by time_s" in n for n in res.meta["notes"])
