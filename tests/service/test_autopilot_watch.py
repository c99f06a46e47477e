"""``run`` and the autopilot's own IMU health: SYS_STATUS/VIBRATION fed message by message (a live link), a
STATUSTEXT when a gyro is newly marked unhealthy, and the summary's cross-check in a replay."""

from __future__ import annotations

from companion.cli.main import main
from companion.mavlink.reporter import Reporter
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.run_session import summary_lines
from tests.sources.test_autopilot_health import _px4_tlog
from tests.support.sinks import RecordingSink


def test_link_messages_give_one_statustext_and_the_summary_line(tmp_path):
    from pymavlink import mavutil

    path = tmp_path / "px4.tlog"
    _px4_tlog(path)
    sink = RecordingSink()
    p = Pipeline(PipelineConfig.from_mapping({"baseline_s": 30}), Reporter(sink, 1.0))
    m = mavutil.mavlink_connection(str(path))
    while True:
        msg = m.recv_match()
        if msg is None:
            break
        p.handle(msg)
    said = [text for _, text in sink.texts if text.startswith("autopilot:")]
    assert said == ["autopilot: IMU1 gyro unhealthy (3D_GYRO2)"]  # once, when it turned unhealthy
    lines = summary_lines(p)
    imu1 = next(line for line in lines if line.startswith("autopilot: IMU1:"))
    assert imu1.startswith("autopilot: IMU1: autopilot: gyro unhealthy (SYS_STATUS) 12.0-30.5 s; clip count rose "
                           "by 140 (VIBRATION.clipping_1, first at 21.0 s)")
    assert imu1.endswith("(autopilot only)")
    assert any(line.startswith("autopilot: IMU0: autopilot: nothing wrong") for line in lines)


def test_replay_summary_names_the_imu_the_autopilot_flags(tmp_path, capsys):
    path = tmp_path / "px4.tlog"
    _px4_tlog(path)
    main(["run", "--source", str(path), "--no-state", "--quiet"])
    out = capsys.readouterr().out
    assert ("autopilot: IMU1: autopilot: gyro unhealthy (SYS_STATUS) 12.0-30.5 s; clip count rose by 140 "
            "(VIBRATION.clipping_1, first at 21.0 s) | ours: ") in out
