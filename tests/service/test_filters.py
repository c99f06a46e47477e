"""`companion run` models the autopilot's low-pass filter in its online noise figures when the filter is known:
the log's parameters on a replay (.bin, .ulg, a tlog's PARAM_VALUE), PARAM_VALUE on a live link."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from companion.mavlink.reporter import Reporter
from companion.mavlink.tlog_writer import TlogWriter
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.replay import replay_log, replay_tlog
from companion.sim.dataflash_writer import write_imu_log
from companion.sim.filtered_noise import filtered_white_noise, logged_white_level
from companion.sources import load
from companion.analysis.stream import stream_filters
from tests.support.sinks import RecordingSink

FS, FC = 100.0, 20.0
G = np.array([0.0, 0.0, -9.80665])


def _pipeline(**cfg):
    return Pipeline(PipelineConfig.from_mapping({"baseline_s": 60, **cfg}), Reporter(RecordingSink(), 1.0))


def _still(seconds, seed):
    n = int(FS * seconds)
    g = np.stack([filtered_white_noise(n, 1e-3, FS, FC, "point", 10 * seed + k) for k in range(3)], axis=1)
    a = G + np.random.default_rng(seed).normal(0.0, 0.02, (n, 3))
    return np.arange(n) / FS + 1.0, g, a


def test_replay_of_a_dataflash_log_models_its_filter(tmp_path):
    """A .bin with INS_GYRO_FILTER 20 / INS_ACCEL_FILTER 15: every estimator has the log's cut-off (gyro and
    accel apart), the reported white-noise term carries exactly 20 Hz (the log's, not a roll-off found in the
    data, which would differ), and N is the logged white level within its interval (the data's filter is a
    2-pole 20 Hz Butterworth, point-sampled at 100 Hz)."""
    t, g, a = _still(120.0, 1)
    p = tmp_path / "still.bin"
    write_imu_log(p, t, g[None], a[None], params={"INS_GYRO_FILTER": FC, "INS_ACCEL_FILTER": 15.0})
    pl = _pipeline(accel=True)
    replay_log(p, pl)
    ch = pl.channels[0]
    for bank in (ch.fast, ch.slow):
        assert {ax: e.filter_hz for ax, e in bank.items()} == {"gx": FC, "gy": FC, "gz": FC,
                                                                "ax": 15.0, "ay": 15.0, "az": 15.0}
        assert all(e.sampling == "point" for e in bank.values())
    level = logged_white_level(1e-3, FS, FC, "point")
    for ax in ("gx", "gy", "gz"):
        wn = next(x for x in pl.report_terms(ch, ax, full=True) if x["effect"] == "white_noise")
        assert wn["filter_hz"] == FC and not wn["bound"]
        lo, hi = wn["ci95"]["N"]
        assert lo <= level <= hi or abs(wn["N"] / level - 1) < 0.03, (wn, level)


def test_without_filter_parameters_nothing_is_assumed(tmp_path):
    t, g, a = _still(30.0, 2)
    p = tmp_path / "plain.bin"
    write_imu_log(p, t, g[None], a[None])
    pl = _pipeline()
    replay_log(p, pl)
    assert all(e.filter_hz is None for e in pl.channels[0].slow.values())


def _raw_imu(mav, t_s, g, a):
    gi = np.round(np.asarray(g) / 1e-3).astype(int)  # RAW_IMU gyro: int16 mrad/s
    ai = np.round(np.asarray(a) / 9.80665e-3).astype(int)  # accel: milli-g
    return mav.raw_imu_encode(int(t_s * 1e6), *ai, *gi, 0, 0, 0)


def test_live_param_value_reaches_the_estimators():
    """PARAM_VALUE INS_GYRO_FILTER from the vehicle, after its IMU stream started: the estimators model it from
    then on; the same parameter from another system is ignored; an estimator config that names filter_hz
    wins over the link's."""
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    other = mavlink2.MAVLink(None, srcSystem=9, srcComponent=1)

    def msg(m, enc):
        enc.pack(m)  # sets the header (source system) as a received message has it
        return enc

    for cfg, want in (({}, FC), ({"estimator": {"filter_hz": 33.0}}, 33.0)):
        pl = _pipeline(**cfg)
        t, g, a = _still(3.0, 3)
        for k in range(t.size):
            pl.handle(msg(mav, _raw_imu(mav, t[k], g[k], a[k])))
        ch = pl.channels[0]
        assert ch.slow, "the estimators exist before the parameter comes"
        pl.handle(msg(other, other.param_value_encode(b"INS_GYRO_FILTER", 42.0, 9, 900, 5)))
        assert ch.filters == {}
        pl.handle(msg(mav, mav.param_value_encode(b"INS_GYRO_FILTER", FC, 9, 900, 5)))
        assert ch.filters == {"gyro": FC}
        assert {e.filter_hz for e in ch.slow.values()} == {want}
        assert {e.filter_hz for e in ch.fast.values()} == {want}


def test_tlog_param_value_gives_the_filter_to_run_and_to_analyze(tmp_path):
    """A tlog with PARAM_VALUE INS_GYRO_FILTER (sent before the IMU stream, as at a GCS's parameter download):
    replayed, the estimators model it; analysed, the stream's filters carry it (one rule for both)."""
    t, g, a = _still(20.0, 4)
    p = tmp_path / "f.tlog"
    with TlogWriter(p, sysid=1, compid=1) as w:
        w.write(w.mav.heartbeat_encode(2, 3, 0, 0, 3), t_unix=1.76e9)
        w.write(w.mav.param_value_encode(b"INS_GYRO_FILTER", FC, 9, 900, 5), t_unix=1.76e9)
        for k in range(t.size):
            w.write(_raw_imu(w.mav, t[k], g[k], a[k]), t_unix=1.76e9 + t[k])
    pl = _pipeline()
    replay_tlog(p, pl)
    assert {e.filter_hz for e in pl.channels[0].slow.values()} == {FC}
    res = load(str(p))
    s = res.imu_streams()[0]
    assert s.key.message == "RAW_IMU" and stream_filters(s, res.meta) == {"gyro": FC}


@pytest.mark.parametrize("fmt,msg,params,want", [
    ("dataflash", "IMU", {"INS_GYRO_FILTER": 20.0, "INS_ACCEL_FILTER": 10.0}, {"gyro": 20.0, "accel": 10.0}),
    ("dataflash", "ISBD", {"INS_GYRO_FILTER": 20.0}, {}),  # the batch sampler logs the raw sensor
    ("dataflash", "IMU", {"INS_GYRO_FILTER": 0.0}, {}),  # filter off: nothing to model
    ("ulog", "sensor_combined", {"IMU_GYRO_CUTOFF": 30.0}, {"gyro": 30.0}),
    (None, "HIGHRES_IMU", {"IMU_GYRO_CUTOFF": 30.0, "IMU_ACCEL_CUTOFF": math.nan}, {"gyro": 30.0}),
    ("csv", "CSV", {"INS_GYRO_FILTER": 20.0}, {}),
    # 2014-2015 firmware: the MPU6000/MPU9250's own low-pass for gyro and accelerometer; 0 = a default that
    # changed between releases (unknown); the newer per-kind parameters win where a log has both
    ("dataflash", "IMU", {"INS_MPU6K_FILTER": 5.0}, {"gyro": 5.0, "accel": 5.0}),
    ("dataflash", "IMU", {"INS_MPU6K_FILTER": 0.0}, {}),
    ("dataflash", "IMU", {"INS_MPU6K_FILTER": 42.0, "INS_GYRO_FILTER": 20.0}, {"gyro": 20.0, "accel": 42.0}),
])
def test_filter_rules(fmt, msg, params, want):
    from companion.analysis.filters import filters_from_params

    assert filters_from_params(params, msg, fmt) == want
