"""One source dispatcher: every command decides "which kind of file is this?" with sources.kind_of, so a file
that inspect/analyze read is also replayed by run and found by fleet discovery, the same way."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from companion.cli.main import main
from companion.fleet.discover import is_log_name, log_format
from companion.service.replay import is_replay_source
from companion.sources import kind_of
from companion.sources.kind import FILE_KINDS, file_kind, is_gzip

TABLE = [
    ("flight.tlog", "tlog"), ("FLIGHT.TLOG.GZ", "tlog"), ("2024-05-01 10-00-00.tlog.bin", "tlog"),
    ("x.tlog.bin.gz", "tlog"), ("mav.mavlink", "tlog"), ("mav.mavlink.gz", "tlog"),
    ("00000042.BIN", "dataflash"), ("log.bin.gz", "dataflash"),
    ("log_3.ulg", "ulog"), ("log_3.ulg.gz", "ulog"),
    ("imu.csv", "csv"), ("imu.CSV.gz", "csv"),
    ("udpin:0.0.0.0:14550", "connection"), ("tcp:127.0.0.1:5760", "connection"), ("/dev/ttyACM0", "connection"),
    ("COM3", "connection"),
    ("notes.txt", "unknown"), ("nonsense", "unknown"), ("flight.tlog.txt", "unknown"),
]


@pytest.mark.parametrize("spec, kind", TABLE)
def test_dispatcher_table(spec, kind):
    assert kind_of(spec) == kind
    assert is_gzip(spec) == spec.lower().endswith(".gz")


@pytest.mark.parametrize("spec, kind", TABLE)
def test_load_run_replay_and_fleet_agree(spec, kind):
    """The file kinds are what run replays and what fleet discovery takes, with the fleet's format names."""
    is_file = kind in FILE_KINDS
    assert (file_kind(spec) is not None) == is_file
    assert is_replay_source(spec) == is_file
    assert is_log_name(spec) == is_file
    if is_file:
        assert log_format(spec) == {"tlog": "tlog", "csv": "csv", "dataflash": "bin", "ulog": "ulg"}[kind]


def _still_tlog(path, n=30_000, fs=100.0):
    from companion.mavlink.tlog_writer import write_imu_tlog

    rng = np.random.default_rng(4)
    g = rng.normal(0.0, 0.004, (n, 3))
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (n, 3))
    write_imu_tlog(path, 1.0 + np.arange(n) / fs, g, a)


def test_run_replays_a_dot_mavlink_file_like_a_tlog(tmp_path, capsys):
    """`run --source x.mavlink` replays (it used to fail as an unknown connection) with the tlog's result."""
    # 90 s with a 60 s baseline: the output still holds the whole pipeline (baseline learned, Allan checks
    # against it, the summary's fit); a longer record only repeats the checks (a third of the CPU of 300 s)
    _still_tlog(tmp_path / "x.tlog", n=9_000)
    shutil.copy(tmp_path / "x.tlog", tmp_path / "x.mavlink")
    outs = []
    for name in ("x.tlog", "x.mavlink"):
        rc = main(["run", "--source", str(tmp_path / name), "--quiet", "--baseline-s", "60"])
        cap = capsys.readouterr()
        assert rc == 0, cap.err
        outs.append(cap.out)
    assert "IMU0 (RAW_IMU, 100.0 Hz): healthy;" in outs[0] and "x baseline)" in outs[0]
    assert outs[1] == outs[0]


def test_tlog_bin_replays_with_the_logs_heartbeats(tmp_path):
    """A .tlog.bin is replayed in frame order with its HEARTBEATs (armed state), as the .tlog: it used to go
    through the log reader, which has no armed state, and replayed as disarmed."""
    from companion.service.run_options import RunHooks, RunOptions
    from companion.service.run_session import replay
    from companion.service.pipeline import PipelineConfig
    from companion.mavlink.vehicle_tlog import write_tlog
    from companion.sim.vehicle import Flight, Schedule, VehicleSimulator
    from companion.sources.decode import ScaleTable

    model = {"rate_hz": 100.0, "axes": {ax: [{"effect": "white_noise", "N": 2e-4}] for ax in ("gx", "gy", "gz")}}
    sim = VehicleSimulator(model, imus=1, seed=3, schedule=Schedule(flights=(Flight(20.0, 60.0),)))
    write_tlog(tmp_path / "v.tlog", sim, 90.0)
    shutil.copy(tmp_path / "v.tlog", tmp_path / "v.tlog.bin")
    results = []
    for name in ("v.tlog", "v.tlog.bin"):
        logs = []
        opts = RunOptions(str(tmp_path / name), PipelineConfig(baseline_s=30.0), scales=ScaleTable())
        pipeline, sink, totals = replay(opts, RunHooks(log=logs.append, warn=logs.append))
        results.append((totals, sink.values, logs))
    (t0, v0, l0), (t1, v1, l1) = results
    assert t0["heartbeats"] >= 90 and t1 == t0
    assert "vehicle armed" in l0 and l1 == l0
    assert v1 == v0
