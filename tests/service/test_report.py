"""`companion run` reports: nothing invented on a healthy replay, 1-sigma and bound markers in
NAMED_VALUE_FLOAT, a baseline that must match the stream."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from companion.cli.main import main
from companion.mavlink.reporter import NAME_RE, Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline, PipelineConfig
from tests.support.sinks import RecordingSink

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "tlogs" / "sample.tlog"
KEY = StreamKey(1, 1, "HIGHRES_IMU", 0)
FS = 50.0
N_TRUE = 1.0e-3  # rad/s/sqrt(Hz), white noise only: no B, no K


@pytest.mark.soak
@pytest.mark.parametrize("seed", [0])
def test_healthy_white_noise_replay_invents_no_b_or_k(seed):
    rng = np.random.default_rng(seed)
    sink = RecordingSink()
    p = Pipeline(PipelineConfig.from_mapping({"baseline_s": 300}), Reporter(sink, 1.0))
    n = int(1200 * FS)
    g = rng.normal(0.0, N_TRUE * math.sqrt(FS), (n, 3))
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (n, 3))
    for k in range(n):
        p.on_sample(KEY, k / FS, g[k], a[k])
    v = sink.values
    assert all(NAME_RE.match(name) for name in v)
    for ax in "XYZ":
        assert v[f"IMU0G{ax}_BS"] == -1.0 and v[f"IMU0G{ax}_KS"] == -1.0  # bounds, not values
        n_dh = N_TRUE / (math.pi / 180.0 / 60.0)
        assert abs(v[f"IMU0G{ax}_N"] / n_dh - 1.0) < 4 * v[f"IMU0G{ax}_NS"] / n_dh + 1e-9
        assert v[f"IMU0G{ax}_NS"] > 0
    assert not any("degrading" in t for _, t in sink.texts)
    assert v["IMU0G_HLTH"] == 0.0
    ch = p.channels[0]
    for ax in ("gx", "gy", "gz"):
        assert set(p.current_params(ch, ax)) == {"N"}  # bounds are never compared with the baseline


def cut_sample(tmp_path_factory, seconds):
    """The first ``seconds`` of the sample tlog, cut at a record boundary: the same stream (RAW_IMU, 50 Hz,
    1 mrad/s)."""
    from companion.sources import tlog

    data = SAMPLE.read_bytes()
    idx = tlog.scan(data)
    t = idx.stamp_us.astype(np.float64) * 1e-6
    cut = int(idx.pos[np.flatnonzero(t > t[0] + seconds)[0]]) - 8  # the record's 8-byte time stamp
    path = tmp_path_factory.mktemp("short") / f"short{seconds:g}.tlog"
    path.write_bytes(data[:cut])
    return path


@pytest.fixture(scope="module")
def short_sample(tmp_path_factory):
    """The first 5 minutes of the sample tlog: a quarter of the replay time."""
    return cut_sample(tmp_path_factory, 300.0)


@pytest.fixture(scope="module")
def minute_sample(tmp_path_factory):
    """The first minute: the baseline's stream description is checked at the first block, its N at the
    first Allan check after 30 s of still data (run.min_report_s), about 40 s in; a longer record only
    repeats that check every 10 s."""
    return cut_sample(tmp_path_factory, 60.0)


def baseline_file(tmp_path, message="RAW_IMU", rate=50.0, lsb=1e-3, scale=1.0):
    axes = {}
    for ax, n in (("gx", 3.5e-4), ("gy", 3.0e-4), ("gz", 4.0e-4)):
        n = math.hypot(n, 4.1e-5) * scale
        axes[ax] = {"terms": [{"effect": "white_noise", "N": n, "ci95": {"N": [0.99 * n, 1.01 * n]}}],
                    "quantization": None if lsb is None else {"lsb": lsb}}
    path = tmp_path / "base.json"
    path.write_text(json.dumps({"source": "x", "streams": [{"message": message, "instance": 0, "sysid": 1,
                                                            "compid": 1, "rate_hz": rate, "axes": axes}]}))
    return str(path)


@pytest.mark.parametrize("kw, msg", [
    ({"message": "CSV", "rate": 100.0, "lsb": None}, "message CSV vs stream RAW_IMU; rate 100 Hz vs stream 50 Hz; "
                                                      "gyro LSB none (float) vs stream 0.001 rad/s"),
    ({"rate": 200.0}, "rate 200 Hz vs stream 50 Hz"),
    ({"lsb": 2e-3}, "gyro LSB 0.002 rad/s vs stream 0.001 rad/s"),
    ({"scale": 3437.75}, "not SI units"),  # N written in deg/sqrt(h) instead of rad/s/sqrt(Hz)
])
def test_a_baseline_of_another_stream_is_one_error_line(tmp_path, capsys, kw, msg, minute_sample):
    # the refusal (rc 2) shows the comparison lies inside the one-minute record, so the forced run goes past
    # it; "healthy" (not "learning") shows its Allan checks judged the stream against the forced baseline
    path = baseline_file(tmp_path, **kw)
    rc = main(["run", "--source", str(minute_sample), "--baseline", path, "--quiet", "--no-state"])
    err = capsys.readouterr().err
    assert rc == 2 and msg in err and "--baseline-force" in err and len(err.strip().splitlines()) == 1
    if "scale" not in kw:
        rc = main(["run", "--source", str(minute_sample), "--baseline", path, "--baseline-force", "--quiet",
                   "--no-state"])
        out = capsys.readouterr().out
        assert rc == 0 and "IMU0 (RAW_IMU, 50.0 Hz): healthy;" in out


def test_a_matching_baseline_is_accepted(tmp_path, capsys, short_sample):
    rc = main(["run", "--source", str(short_sample), "--baseline", baseline_file(tmp_path), "--quiet", "--no-state"])
    out = capsys.readouterr().out
    assert rc == 0 and "healthy" in out and "degrading" not in out


@pytest.mark.parametrize("rate", [400.0, 300.0])
def test_scaled_imu2_stamped_in_ms_off_the_ms_grid(rate):
    """SCALED_IMU2 at 400 Hz carries time_boot_ms stepping 2, 3, 2, 3 ms: the stream is 400 Hz (the median
    step alone says 500 or 333 Hz, which would scale N by sqrt(1.25) and raise "timing irregular"), N is
    right, and no fault is raised."""
    rng = np.random.default_rng(int(rate))
    sink = RecordingSink()
    p = Pipeline(PipelineConfig.from_mapping({"baseline_s": 60}), Reporter(sink, 1.0))
    key = StreamKey(1, 1, "SCALED_IMU2", 1)
    n_si = 3e-3
    n = int(150 * rate)
    t = np.floor((2.0 + np.arange(n) / rate) * 1e3) / 1e3
    g = np.round(rng.normal(0.0, n_si * math.sqrt(rate), (n, 3)) / 1e-3) * 1e-3
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (n, 3))
    for k in range(n):
        p.on_sample(key, t[k], g[k], a[k])
    ch = p.channels[1]
    # the rate comes from the last 64 intervals: 1 ms of stamp resolution over 64 periods is 0.5 % at most
    assert ch.rate_hz == pytest.approx(rate, rel=0.006) and ch.counts["rate_changes"] == 0
    assert not p.transitions and not [x for _, x in sink.texts if "learned" not in x], sink.texts
    n_true = math.sqrt(n_si**2 + 1e-6 / (12 * rate)) / (math.pi / 180.0 / 60.0)  # deg/sqrt(h), with rounding
    for ax in "XYZ":
        assert sink.values[f"IMU1G{ax}_N"] == pytest.approx(n_true, rel=0.05)
