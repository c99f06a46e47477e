"""DataFlash and ULog readers against pymavlink's DFReader / pyulog: counts, values, layouts, batches and
types the readers skip (the still selection and the fit on simulated flight logs: test_flight_logs.py)."""

from __future__ import annotations

import gzip
import shutil

import numpy as np
import pytest

from companion.cli.main import main
from companion.sim.dataflash_writer import write_imu_log
from companion.sources import load

DF_IMU = ("IMU", "IMU2", "IMU3")


def dfreader_imu(path):
    """Every IMU* message as pymavlink's DFReader decodes it: {(name, instance): rows of t, gyro, accel}."""
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(path))
    out: dict = {}
    counts: dict = {}
    while True:
        m = r.recv_msg()
        if m is None:
            break
        name = m.get_type()
        counts[name] = counts.get(name, 0) + 1
        if name in DF_IMU:
            cols = m.get_fieldnames()
            t = m.TimeUS * 1e-6 if "TimeUS" in cols else m.TimeMS * 1e-3
            inst = m.I if "I" in cols else DF_IMU.index(name)
            out.setdefault(inst, []).append((t, m.GyrX, m.GyrY, m.GyrZ, m.AccX, m.AccY, m.AccZ))
    return {k: np.array(v) for k, v in out.items()}, counts


def _compare_df(path):
    from companion.sources import dataflash as df
    from companion.sources.dataflash_imu import MAX_IMU_INSTANCE, PHANTOM_SAMPLES, imu_raw_streams

    ref, counts = dfreader_imu(path)
    log = df.open_log(path)
    assert log.counts() == counts
    raws, _ = imu_raw_streams(log)
    kept = sorted(r.key.instance for r in raws)
    # DFReader also lists an instance made by a damaged record (one sample of instance 62 where garbage
    # bytes hit a record): skipped as noise (dataflash_imu.MAX_IMU_INSTANCE, PHANTOM_SAMPLES) and noted
    dropped = sorted(set(ref) - set(kept))
    assert set(kept) <= set(ref) and len(log.implausible) == len(dropped)
    assert all(k > MAX_IMU_INSTANCE or ref[k].shape[0] < PHANTOM_SAMPLES for k in dropped)
    for r in raws:
        exp = ref[r.key.instance]
        assert r.t.shape[0] == exp.shape[0]
        np.testing.assert_array_equal(r.t, exp[:, 0])
        np.testing.assert_array_equal(r.gyro, exp[:, 1:4])
        np.testing.assert_array_equal(r.accel, exp[:, 4:7])
    return log


@pytest.mark.parametrize("name", ["dronekit_log171.bin", "methodic_backend_log_80k.bin"])
def test_shared_dataflash_equals_dfreader(shared_data, name):
    log = _compare_df(shared_data / "ardupilot" / name)
    res = load(shared_data / "ardupilot" / name)
    assert res.meta["params"]  # PARM read
    if name.startswith("dronekit"):
        assert [s.samples for s in res.imu_streams()] == [11916] * 3
        assert res.meta["params"]["INS_GYRO_FILTER"] == 20.0
        assert res.meta["armed"] and res.meta["armed"][0][1] is True
        assert len(res.meta["modes"]) == 3
    else:
        assert log.counts()["PARM"] == 1077
    assert main(["inspect", str(shared_data / "ardupilot" / name)]) == 0


def test_inspect_prints_log_parameters_and_armed_state(shared_data, capsys):
    """The armed period, not the arming time alone ("72.6 s armed" read as a duration): from the EV arm event
    (id 10; no disarm event; this old EV has no time field: the IMU message before it gives its time) to the
    last IMU sample, as pymavlink's DFReader reads the log."""
    from pymavlink import DFReader

    path = shared_data / "ardupilot" / "dronekit_log171.bin"
    r = DFReader.DFReader_binary(str(path))
    arm, end, last_imu = None, 0.0, None
    while True:
        m = r.recv_match(type=["EV", "IMU", "IMU2", "IMU3"])
        if m is None:
            break
        if m.get_type() == "EV":
            assert m.Id != 11  # never disarmed in this log
            if m.Id == 10 and arm is None:
                arm = last_imu
        else:
            end = max(end, m.TimeMS * 1e-3)
            if m.get_type() == "IMU":
                last_imu = m.TimeMS * 1e-3
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    assert "INS_GYRO_FILTER 20" in out
    assert (f"log: armed state: armed {arm:.1f}-{end:.1f} s ({end - arm:.0f} s in 1 period; still armed at the end "
            "of the IMU data)") in out


def test_shared_isbd_equals_dfreader(shared_data):
    from pymavlink import DFReader

    path = shared_data / "ardupilot" / "methodic_backend_log_80k.bin"
    r = DFReader.DFReader_binary(str(path))
    mul, xs = None, []
    while True:
        m = r.recv_match(type=["ISBH", "ISBD"])
        if m is None:
            break
        if m.get_type() == "ISBH":
            mul, rate, t0 = m.mul, m.smp_rate, m.SampleUS * 1e-6
        else:
            xs.extend(list(zip(m.x, m.y, m.z)))
    res = load(path)
    (isb,) = [s for s in res.streams if s.key.message == "ISB_GYRO"]
    assert isb.samples == len(xs) == 576
    np.testing.assert_allclose(isb.gyro, np.array(xs) / mul, rtol=0, atol=0)
    assert isb.t[1] - isb.t[0] == pytest.approx(1 / rate)
    assert isb.t[0] == pytest.approx(t0)
    assert np.all(np.isnan(isb.accel))


@pytest.mark.parametrize("name", ["pyulog_sample.ulg", "pyulog_sample_log_small.ulg"])
def test_shared_ulog_counts_equal_pyulog(shared_data, name, tmp_path):
    from pyulog import ULog

    path = shared_data / "px4" / name
    u = ULog(str(path))
    want = {(d.name, d.multi_id): len(d.data["timestamp"]) for d in u.data_list
            if d.name in ("sensor_combined", "sensor_gyro", "vehicle_imu", "sensor_gyro_fifo")}
    res = load(path)
    got = {(s.key.message, s.key.instance): s.samples + s.timing.duplicates + s.timing.backwards for s in res.streams}
    assert got == want
    sc = next(d for d in u.data_list if d.name == "sensor_combined")
    s0 = next(s for s in res.streams if s.key.message == "sensor_combined")
    if s0.timing.duplicates == 0 and s0.timing.backwards == 0:
        np.testing.assert_array_equal(s0.gyro[:, 0], sc.data["gyro_rad[0]"].astype(float))
    assert res.meta["has_armed_state"]
    # .ulg.gz reads the same
    gz = tmp_path / (name + ".gz")
    with open(path, "rb") as fi, gzip.open(gz, "wb") as fo:
        shutil.copyfileobj(fi, fo)
    res_gz = load(gz)
    assert [s.samples for s in res_gz.streams] == [s.samples for s in res.streams]


@pytest.mark.parametrize("layout", ["2015", "3.4", "4.x"])
def test_written_layouts_equal_dfreader_with_garbage(tmp_path, layout):
    rng = np.random.default_rng(7)
    n = 3000
    t = 5.0 + np.arange(n) / 100.0
    g = rng.normal(0, 1e-3, (3, n, 3))
    a = rng.normal(0, 1e-2, (3, n, 3)) + [0, 0, -9.8]
    p = tmp_path / "log.bin"
    write_imu_log(p, t, g, a, layout=layout, params={"INS_GYRO_FILTER": 20}, armed=[(10.0, True), (20.0, False)])
    data = bytearray(p.read_bytes())
    # garbage bytes in the middle of the log (a corrupted block): both readers skip them the same way
    for pos in rng.integers(2000, len(data) - 2000, 5):
        data[pos:pos] = bytes(rng.integers(0, 256, int(rng.integers(1, 30))).astype(np.uint8))
    p.write_bytes(bytes(data))
    _compare_df(p)
    gz = tmp_path / "log.bin.gz"
    gz.write_bytes(gzip.compress(bytes(data)))
    res = load(gz)
    assert res.meta["armed"] == [(10.0, True), (20.0, False)]
    assert res.meta["params"]["INS_GYRO_FILTER"] == 20.0


def test_chain_walk_equals_a_plain_loop():
    """The vectorised chain walk (pointer doubling in blocks) visits exactly what DFReader's loop visits."""
    from companion.sources.dataflash import _orbit

    rng = np.random.default_rng(0)
    for _ in range(60):
        K = int(rng.integers(1, 3000))
        succ = np.minimum(np.arange(K) + rng.integers(1, 4, K), K)
        known = rng.random(K) > 0.002
        chain, i, stop = [], 0, None
        while i < K:
            if not known[i]:
                stop = i
                break
            chain.append(i)
            i = int(succ[i])
        got, got_stop = _orbit(succ, known, block=int(rng.integers(1, 200)))
        assert got.tolist() == chain and got_stop == stop


def test_ulog_gyro_fifo_samples(tmp_path):
    from pyulog import ULog

    from companion.sim.ulog_writer import write_ulog

    rng = np.random.default_rng(13)
    n = 400
    t = 1.0 + np.arange(n) / 100.0
    counts = rng.integers(-300, 300, (1000, 3)).astype(np.int16)
    scale = 1.0e-3
    p = tmp_path / "fifo.ulg"
    write_ulog(p, t, rng.normal(0, 1e-3, (1, n, 3)), rng.normal(0, 1e-2, (1, n, 3)),
               fifo=(2.0, 1000.0, counts, scale, 12))
    u = ULog(str(p))
    rows = next(len(d.data["timestamp"]) for d in u.data_list if d.name == "sensor_gyro_fifo")
    res = load(p)
    (st,) = [s for s in res.streams if s.key.message == "sensor_gyro_fifo"]
    assert res.messages["sensor_gyro_fifo[0]"] == rows == 84  # ceil(1000 / 12)
    assert st.samples == 1000
    np.testing.assert_array_equal(st.gyro, counts.astype(float) * float(np.float32(scale)))  # int16 x scale
    np.testing.assert_allclose(st.t, 2.0 + np.arange(1000) / 1000.0, atol=2e-6)
    assert st.rate_hz == pytest.approx(1000.0, rel=1e-3)
    assert st.gyro_lsb == pytest.approx(scale)


def test_undefined_type_is_skipped_like_dfreader_and_reported(tmp_path, capsys):
    rng = np.random.default_rng(14)
    n = 1000
    t = 1.0 + np.arange(n) / 100.0
    p = tmp_path / "stop.bin"
    write_imu_log(p, t, rng.normal(0, 1e-3, (1, n, 3)), rng.normal(0, 1e-2, (1, n, 3)), layout="4.x")
    b = bytearray(p.read_bytes())
    j = b.find(b"\xa3\x95", len(b) // 2)
    b[j + 2] = 200  # a type no FMT defines: DFReader's indexer skips it byte by byte
    p.write_bytes(bytes(b))
    log = _compare_df(p)
    assert log.counts()["IMU"] == n - 1 and log.bad_bytes > 0
    assert main(["inspect", str(p)]) == 0
    assert "bytes outside valid messages skipped" in capsys.readouterr().out


def test_post_filter_batches_are_named_for_their_own_imu():
    """INS_LOG_BAT_OPT 4 (before and after the filters): ArduPilot writes the post-filter batch of IMU k as
    instance k + the number of IMUs. A public Copter 4.7 log with two IMUs and INS_LOG_BAT_MASK 1 carries
    instances 0 and 2; 2 (a quarter of 0's spread) was read as a third IMU."""
    from companion.sources.dataflash_imu import isb_name

    assert isb_name(True, 0, 4, 2) == ("ISB_GYRO", 0)
    assert isb_name(True, 2, 4, 2) == ("ISB_GYRO_POST", 0)
    assert isb_name(False, 3, 4, 2) == ("ISB_ACCEL_POST", 1)
    assert isb_name(True, 1, 2, 2) == ("ISB_GYRO_POST", 1)  # post-filter only: the sensor's own number
    assert isb_name(True, 2, 0, 3) == ("ISB_GYRO", 2)  # raw batches: as written
    from companion.sources.dataflash_imu import bat_opt

    assert [bat_opt(p) for p in ({"INS_LOG_BAT_OPT": 4.0}, {}, None, {"INS_LOG_BAT_OPT": float("inf")},
                                 {"INS_LOG_BAT_OPT": float("nan")})] == [4, 0, 0, 0, 0]  # a damaged PARM
    from companion.analysis.filters import filters_from_params

    assert filters_from_params({"INS_GYRO_FILTER": 34.0}, "ISB_GYRO_POST", "dataflash") == {"gyro": 34.0}
    assert filters_from_params({"INS_GYRO_FILTER": 34.0}, "ISB_GYRO", "dataflash") == {}


def test_run_replays_the_imu_messages_not_the_batch_bursts(shared_data):
    """The batch sampler's bursts outnumber a log's IMU messages; replayed as IMU 0 they gave no block (a
    second of kHz data every few seconds) and left IMU 0 unwatched. run takes the IMU messages."""
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline_config import PipelineConfig
    from companion.service.pipeline import Pipeline
    from companion.service.replay import replay_log
    from tests.support.sinks import RecordingSink

    p = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
    replay_log(shared_data / "ardupilot" / "methodic_backend_log_80k.bin", p)
    assert p.channels and all(ch.message == "IMU" for ch in p.channels.values())
