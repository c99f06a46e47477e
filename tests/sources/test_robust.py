"""Robustness: truncated, mutated and random tlogs never crash the walker; pathological time bases stay fast."""

from __future__ import annotations

import time

import numpy as np
import pytest

from companion.errors import CompanionError
from companion.mavlink.tlog_writer import write_imu_tlog
from companion.sources import load, tlog
from companion.sources.timestamps import analyse


@pytest.fixture
def small_tlog(tmp_path):
    n = 400
    path = tmp_path / "s.tlog"
    write_imu_tlog(path, np.arange(n) / 100.0, np.full((n, 3), 0.003), np.full((n, 3), 0.2))
    return path, n


def test_truncated_file_keeps_every_complete_frame(small_tlog):
    path, n = small_tlog
    data = path.read_bytes()
    full = tlog.scan(data)
    for cut in (0, 1, 7, 8, 9, 12, 30, len(data) // 2, len(data) - 1):
        idx = tlog.scan(data[:cut])
        complete = int(np.sum(full.pos + full.header_len + full.length + 2 <= cut))
        assert idx.frames == complete
        assert idx.bad_bytes == cut - int(np.sum((full.header_len + full.length + 10)[:complete]))


def test_random_and_mutated_bytes_never_crash(small_tlog):
    path, n = small_tlog
    data = path.read_bytes()
    rng = np.random.default_rng(11)
    for _ in range(20):
        junk = rng.integers(0, 256, int(rng.integers(0, 4000)), dtype=np.uint8).tobytes()
        idx = tlog.scan(junk)
        assert idx.bad_bytes + sum(int(x) for x in (idx.header_len + idx.length + 10)) == len(junk)
        b = bytearray(data)
        for i in rng.integers(0, len(b), 40):
            b[i] = int(rng.integers(0, 256))
        idx = tlog.scan(bytes(b))
        assert n - 40 <= idx.counts.get("RAW_IMU", 0) <= n  # each mutation destroys at most one frame


def test_random_file_is_a_clean_error(tmp_path):
    p = tmp_path / "noise.tlog"
    p.write_bytes(np.random.default_rng(1).integers(0, 256, 10_000, dtype=np.uint8).tobytes())
    with pytest.raises(CompanionError, match="no IMU"):
        load(p)


def test_sawtooth_time_base_is_linear():
    t = np.tile(np.arange(100) / 10.0, 3000)  # 2,999 reboots
    t0 = time.process_time()  # CPU time of this process: a busy machine does not inflate it
    keep, seg, rep = analyse(t, 1e-6)
    assert time.process_time() - t0 < 5.0  # a quadratic walk over 3,000 segments would take minutes
    assert rep.resets == 2999 and len(seg) == 3000 and rep.rate_hz == pytest.approx(10.0)


def test_frame_hidden_inside_a_payload_is_not_counted(tmp_path):
    """A valid RAW_IMU frame (with a stamp and a fake next magic) inside a FILE_TRANSFER_PROTOCOL payload:
    both pass the CRC, they overlap, the outer (earlier) one wins."""
    from companion.mavlink.tlog_writer import TlogWriter

    path = tmp_path / "nested.tlog"
    with TlogWriter(path) as w:
        inner = w.mav.raw_imu_encode(123456, 1, 2, 3, 4, 5, 6, 7, 8, 9, 0, 0).pack(w.mav)
        blob = bytes(8) + inner + bytes(8) + b"\xfd"
        payload = blob + bytes(251 - len(blob) - 1) + b"\x01"
        w.write(w.mav.heartbeat_encode(2, 3, 0, 0, 3), t_unix=1.7e9)
        w.write(w.mav.file_transfer_protocol_encode(0, 0, 0, payload), t_unix=1.7e9 + 0.1)
        w.write(w.mav.heartbeat_encode(2, 3, 0, 0, 3), t_unix=1.7e9 + 1)
    idx = tlog.scan(path.read_bytes())
    assert idx.counts == {"HEARTBEAT": 2, "FILE_TRANSFER_PROTOCOL": 1}
    assert idx.bad_bytes == 0 and idx.bad_frames == 0
