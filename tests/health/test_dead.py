"""A dead gyro (every sample exactly 0, as in a real 2014 rover log with an absent MPU-9250) is named by
inspect, analyze (before the armed-state refusal), fleet and run. The logs are written by the simulator's
DataFlash writer: two IMUs, IMU1's gyro all zeros, armed from the first sample to the last."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from companion.health.dead import constant_axes, dead_gyro_text
from companion.sim.dataflash_writer import write_imu_log

REPO = Path(__file__).resolve().parents[2]


def companion(*args, cwd=None):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "companion", *args], capture_output=True, text=True, env=env,
                          timeout=300, cwd=cwd)


def dead_log(path, armed_throughout=True, seconds=90.0):
    rng = np.random.default_rng(4)
    n = int(seconds * 50)
    t = 5.0 + np.arange(n) / 50.0
    g = np.stack([rng.normal(0.0, 2e-3, (n, 3)), np.zeros((n, 3))])
    a = np.stack([np.array([0.0, 0.0, -9.81]) + rng.normal(0.0, 0.05, (n, 3)) for _ in range(2)])
    armed = [(5.0, True)] if armed_throughout else None
    write_imu_log(path, t, g, a, layout="4.x", params={"INS_GYRO_FILTER": 20.0}, armed=armed)
    return path


def test_constant_axes():
    g = np.zeros((100, 3))
    g[:, 1] = np.arange(100) * 1e-3
    assert constant_axes(g) == [0, 2]
    assert constant_axes(g[:5]) == []  # too short to tell
    assert "exactly 0" in dead_gyro_text("IMU[1]", np.zeros((50, 3)))
    assert "constant (0.0123 rad/s)" in dead_gyro_text("IMU[1]", np.full((50, 3), 0.0123))
    assert dead_gyro_text("IMU[0]", np.random.default_rng(0).normal(size=(50, 3))) is None


def test_inspect_and_analyze_name_the_dead_gyro_before_the_armed_state(tmp_path):
    p = dead_log(tmp_path / "dead.bin")
    r = companion("inspect", str(p), "--json", str(tmp_path / "i.json"))
    assert r.returncode == 4, r.stderr  # the table, and the exit status of a gyro fault found
    assert "IMU[1]" in r.stdout and "gyro dead: X, Y, Z exactly 0" in r.stdout
    assert r.stderr.strip().splitlines()[-1].endswith("(exit status 4)"), r.stderr
    r = companion("analyze", str(p), "--quiet")
    assert r.returncode == 4  # no still data to analyse, but the dead gyro is the finding
    err = r.stderr.strip().splitlines()[-1]
    assert "gyro dead: X, Y, Z exactly 0" in err
    assert err.index("gyro dead") < err.index("armed"), err  # named first
    assert "Traceback" not in r.stderr


def test_analyze_with_still_data_warns_about_the_dead_gyro(tmp_path):
    p = dead_log(tmp_path / "dead_still.bin", armed_throughout=False)
    out = tmp_path / "a.json"
    r = companion("analyze", str(p), "--json", str(out), "--quiet")
    assert r.returncode == 4, r.stderr  # analysed, and a gyro fault found
    assert "gyro dead" in r.stderr
    assert any("gyro dead" in n for n in json.loads(out.read_text())["sources"][0]["notes"])


def test_fleet_records_a_dead_gyro_not_no_still_data(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    dead_log(logs / "dead.bin")
    db = str(tmp_path / "f.sqlite")
    r = companion("fleet", "analyze", str(logs), "--db", db, "--workers", "1")
    assert r.returncode == 4, r.stderr  # not a failed log: a flagged IMU
    assert "1 log(s) analysed, 0 failed" in r.stdout and "no still data" not in r.stdout + r.stderr
    out = tmp_path / "r.json"
    r = companion("fleet", "report", "--db", db, "--json", str(out), "--html", str(tmp_path / "r.html"))
    assert r.returncode == 4, r.stderr
    imus = json.loads(out.read_text())["imus"]
    # the dead IMU ranked first and flagged; its healthy twin (ground and flight rows) is not
    assert [e["imu"] for e in imus if e["flagged"]] == [1] and imus[0]["imu"] == 1
    assert imus[0]["fault"].startswith("gyro dead gx/gy/gz in 1 of 1 flight") and "gyro dead" in imus[0]["fault"]
    assert "FAULT: gyro dead" in (tmp_path / "r.html").read_text()


def test_run_names_the_dead_gyro(tmp_path):
    p = dead_log(tmp_path / "dead_run.bin")
    r = companion("run", "--source", str(p), "--no-state", "--quiet")
    assert r.returncode == 4, r.stderr  # a gyro fault found (README "Exit status")
    assert "companion run: gyro faults or degradation found: IMU1 (exit status 4)" in r.stderr
    # a float log (DataFlash) never reads exactly 0.0 from a live gyro: dead, not "stuck"
    assert "IMU1 gyro X reads exactly 0: dead" in r.stdout and "IMU0 gyro" not in r.stdout.split("at ")[-1]
    assert "stuck" not in r.stdout


def test_a_record_too_short_to_name_a_dead_gyro_says_it_read_exactly_zero(tmp_path):
    # a public rover log holds 1.5 s of a gyro reading exactly 0 (77 samples): `analyze` says "gyro dead",
    # `run` notes it in its summary, for the dead IMU only, and ends with the fault status: a failing gyro
    # must not end as healthy
    p = dead_log(tmp_path / "short.bin", seconds=1.5)
    r = companion("run", "--source", str(p), "--no-state", "--quiet")
    assert r.returncode == 4 and "gyro faults or degradation found: IMU1" in r.stderr, r.stderr
    notes = [ln for ln in r.stdout.splitlines() if "read exactly 0 in all" in ln]
    assert len(notes) == 1 and notes[0].strip().startswith("note: IMU1: gyro X, Y, Z read exactly 0 in all 75 samples"), r.stdout
    # long enough, the dead test names it and no note repeats it
    p = dead_log(tmp_path / "long.bin", seconds=20.0, armed_throughout=False)
    r = companion("run", "--source", str(p), "--no-state", "--quiet")
    assert "IMU1 gyro X reads exactly 0: dead" in r.stdout and "read exactly 0 in all" not in r.stdout, r.stdout


def test_real_rover_log_dead_gyro_named_by_inspect_and_analyze(tmp_path):
    """The public rover log (erlerobot/logs pxf_rover_2-8-2014_mpu9250-ms5611_7.BIN, not in ../shared/data: no
    shared log holds a dead gyro) as its properties: the 2015 DataFlash layout (IMU/IMU2, TimeMS), 8578
    samples at 50 Hz, the second IMU's gyro exactly 0 throughout, armed throughout."""
    rng = np.random.default_rng(4)
    n = 8578
    t = 5.0 + np.arange(n) / 50.0
    g = np.stack([rng.normal(0.0, 2e-3, (n, 3)), np.zeros((n, 3))])
    a = np.stack([np.array([0.0, 0.0, -9.81]) + rng.normal(0.0, 0.05, (n, 3)) for _ in range(2)])
    p = tmp_path / "rover.bin"
    write_imu_log(p, t, g, a, layout="2015", armed=[(5.0, True)])
    r = companion("inspect", str(p))
    assert "IMU[1]" in r.stdout and "gyro dead: X, Y, Z exactly 0 in all 8578 samples" in r.stdout, r.stdout
    assert "IMU[0] sys0/comp0: gyro dead" not in r.stdout
    r = companion("analyze", str(p), "--quiet")
    assert r.returncode != 0 and "gyro dead" in r.stderr


def test_a_float_gyro_reading_exactly_zero_at_10_and_25_hz_is_named_dead():
    """A dead float gyro at a low log rate (a tlog's HIGHRES_IMU at 10 Hz; a DataFlash log's 25 Hz IMU): a
    block never held the 50 equal values the equal-values rule asked for, and nothing was said in a minute.
    Now 100 equal values in a row however they fall into blocks: 10 s at 10 Hz, 4 s at 25 Hz."""
    from companion.mavlink.reporter import Reporter
    from companion.samples import StreamKey
    from companion.service.pipeline_config import PipelineConfig
    from companion.service.pipeline import Pipeline
    from tests.support.sinks import RecordingSink

    for rate, within in ((10.0, 13.0), (25.0, 6.0)):
        p = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
        rng = np.random.default_rng(0)
        t = 1.0 + np.arange(int(60 * rate)) / rate
        a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (t.size, 3))
        p.on_samples(StreamKey(1, 1, "HIGHRES_IMU", 0), t, np.zeros((t.size, 3)), a)
        dead = [(tt, x) for tt, x in p.transitions if "reads exactly 0: dead" in x]
        assert len(dead) == 3 and max(tt for tt, _ in dead) <= within, (rate, p.transitions)

