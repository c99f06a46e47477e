"""A log across reboots: the boot sessions laid end to end on one time axis (companion.sources.sessions).

Found on a public PX4 log (px4-ulog-rs' corrupt_format_not_utf8.ulg, three sessions whose message times
overlap): `analyze` refused it with "--start/--end select nothing of the record 5488.2-5232.1 s" though no
--start/--end was given."""

from __future__ import annotations

import json

import numpy as np
import pytest

from companion.cli.main import main
from companion.sources import load

N_TRUE = 2e-3  # rad/s/sqrt(Hz)
FS = 50.0


def _log(path, spans, seed=0):
    """A DataFlash log of white gyro noise at rest written across reboots: one log per (t0, seconds) of
    ``spans`` (the times since boot of that session), the files one after the other (as a logger that keeps
    writing to one file across a restart), in that order."""
    from companion.sim.dataflash_writer import write_imu_log

    rng = np.random.default_rng(seed)
    blob = b""
    for k, (t0, sec) in enumerate(spans):
        t = t0 + np.arange(int(sec * FS)) / FS
        g = rng.normal(0.0, N_TRUE * np.sqrt(FS), (t.size, 3))
        a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (t.size, 3))
        part = path.with_suffix(f".{k}.bin")
        write_imu_log(part, t, g, a)
        blob += part.read_bytes()
        part.unlink()
    path.write_bytes(blob)
    return path


def test_sessions_whose_times_overlap_are_analysed_one_after_the_other(tmp_path, capsys):
    p = _log(tmp_path / "reboots.bin", [(200.0, 150.0), (0.5, 150.0)])
    res = load(p)
    (s,) = res.streams
    assert np.all(np.diff(s.t) > 0)  # one time axis
    assert s.t[7500] - s.t[7499] == pytest.approx(60.0, abs=0.1)  # the second session 60 s after the first
    assert len(s.segments) == 2 and s.timing.resets == 1  # the reboot is still a segment boundary, counted
    assert any("2 boot sessions" in n for n in res.meta["notes"])
    out = tmp_path / "r.json"
    assert main(["analyze", str(p), "--axes", "gx", "--json", str(out)]) == 0
    (stream,) = json.loads(out.read_text())["streams"]
    (n,) = [t["N"] for t in stream["axes"]["gx"]["terms"] if t["effect"] == "white_noise"]
    assert n == pytest.approx(N_TRUE, rel=0.08)  # 300 s of 50 Hz: N's sd about 2 %
    assert "boot sessions" in capsys.readouterr().out


def test_one_session_is_left_as_it_is(tmp_path):
    p = _log(tmp_path / "one.bin", [(10.0, 60.0)])
    (s,) = load(p).streams
    assert s.t[0] == pytest.approx(10.0)


def test_a_damaged_timestamp_is_no_boot_session(tmp_path):
    """One sample at 1.2e13 s (a mutated log) stepped back from: not a reboot to lay end to end (the shift
    of 1.2e13 s left the next samples equal at float64's 2 ms resolution there)."""
    from dataclasses import replace

    from companion.sources.sessions import join_sessions

    res = load(_log(tmp_path / "one.bin", [(10.0, 60.0)]))
    s = res.streams[0]
    t = s.t.copy()
    t[100] = 1.2e13
    out = join_sessions(replace(res, streams=[replace(s, t=t)]))
    assert np.array_equal(out.streams[0].t, t) and "sessions" not in out.meta
