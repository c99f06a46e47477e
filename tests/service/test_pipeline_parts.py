"""The pipeline's parts against the sample-by-sample reference: the block cutter's array path equals its
one-row path (timestamps with duplicates, steps back, gaps and a reboot), a replay fed as arrays
(service.replay.feed_in_order) equals feeding every HEARTBEAT and sample one by one in file order, a
baseline of another sensor stops the pipeline with one line instead of raising inside it."""

from __future__ import annotations

import pytest

import math

import numpy as np

from companion import units
from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.blocks import BlockCutter
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.replay import feed_in_order
from companion.sim.vehicle import IMU_MESSAGES, Fault, Flight, Schedule, VehicleSimulator, WarmUp
from tests.support.sinks import RecordingSink

LSB = 1e-3


def messy_times(rng, n=3000, rate=100.0):
    t = 5.0 + np.arange(n) / rate + rng.uniform(0, 2e-4, n)
    t[400] = t[399]  # duplicate
    t[700] = t[698]  # a step back
    t[1000:] += 0.8  # a gap
    t[2000:] -= 30.0  # a reboot
    return t


def test_block_cutter_array_path_equals_one_row_path():
    rng = np.random.default_rng(0)
    t = messy_times(rng)
    rows = np.column_stack([t, rng.normal(size=(t.size, 6))])

    def run(chunks):
        c = BlockCutter(1.0, 1.0, 0.5, 0.0)
        out = []
        for a, b in chunks:
            for ev in c.cut(rows[a:b]):
                out.append((ev[0], ev[1].tolist() if isinstance(ev[1], np.ndarray) else ev[1]) + ev[2:])
        return out, c.counts, c.rate_hz

    one, counts1, rate1 = run([(k, k + 1) for k in range(t.size)])
    arr, counts2, rate2 = run([(0, 150), (150, 1234), (1234, t.size)])
    blocks1 = [e for e in one if e[0] == "block"]
    assert [e for e in arr if e[0] == "block"] == blocks1 and len(blocks1) > 20
    assert [e for e in one if e[0] in ("reset", "gap")] == [e for e in arr if e[0] in ("reset", "gap")]
    assert counts1 == counts2 and rate1 == rate2
    assert counts1["duplicates"] == 1 and counts1["backwards"] == 1 and counts1["gaps"] == 1 and counts1["resets"] == 1
    # every accepted sample is in exactly one "samples" or "block" event
    seen = sum(len(e[1]) for e in arr if e[0] == "samples") + len(blocks1)
    assert seen == counts2["samples"] == t.size - 2


def test_a_2_hz_stream_with_jitter_has_blocks_not_a_gap_every_other_sample():
    # telemetry at 2 Hz and a PX4 log's vehicle_imu: intervals of 0.5 s +- a few ms;
    # with the fixed 0.5 s gap threshold half of them were gaps, each dropping the partial block
    rng = np.random.default_rng(1)
    t = 3.0 + np.arange(240) * 0.5 + rng.uniform(-0.01, 0.01, 240)
    t[120:] += 3.0  # one real gap (six periods)
    rows = np.column_stack([t, rng.normal(size=(t.size, 6))])
    for chunks in ([(k, k + 1) for k in range(t.size)], [(0, t.size)]):
        c = BlockCutter(1.0, 1.0, 0.5, 0.0)
        blocks = [ev for a, b in chunks for ev in c.cut(rows[a:b]) if ev[0] == "block"]
        assert abs(c.rate_hz - 2.0) < 0.05
        # before the rate is known (8 clean intervals) the 0.5 s threshold stands in for the period
        assert 1 <= c.counts["gaps"] <= 20, c.counts
        assert len(blocks) >= 70, len(blocks)


def model():
    return {"rate_hz": 100.0, "axes": {a: [
        {"effect": "white_noise", "N": 2 * LSB / 10.0},
        {"effect": "bias_instability", "B": units.from_datasheet("B", 30.0)},
        {"effect": "random_walk", "K": units.from_datasheet("K", 40.0)}] for a in ("gx", "gy", "gz")}}


def file_order(duration=150.0):
    """Two IMUs and 1 Hz HEARTBEATs interleaved as a tlog holds them (the second IMU's messages a little
    late), with a flight and a gyro freezing in it: (events in order, streams)."""
    sim = VehicleSimulator(model(), imus=2, seed=4, schedule=Schedule(flights=(Flight(80.0, 200.0),)),
                           fault=Fault("stuck", at=120.0, size=0.0, imu=1, axis="gx"), warmup=WarmUp())
    blk = sim.take_until(sim.t_start + duration)

    class S:
        pass

    streams = []
    for i in range(2):
        s = S()
        s.key = StreamKey(1, 1, IMU_MESSAGES[i], i)
        s.t = blk.t.copy()
        s.gyro = np.round(blk.gyro[i] / LSB) * LSB
        s.accel = blk.accel[i]
        streams.append(s)
    streams[1].t = streams[1].t + 0.0003
    hb_t = np.arange(math.floor(blk.t[0]), blk.t[-1], 1.0)
    hb_armed = np.asarray(sim.armed_at(hb_t), dtype=bool).reshape(-1)
    t_ev = np.concatenate([hb_t, streams[0].t + 0.004, streams[1].t])  # arrival: IMU0 sent 4 ms late
    src = np.concatenate([np.full(hb_t.size, -1), np.zeros(blk.n, int), np.ones(blk.n, int)])
    row = np.concatenate([np.arange(hb_t.size), np.arange(blk.n), np.arange(blk.n)])
    order = np.lexsort((src, t_ev))
    return order, src, row, streams, hb_armed


@pytest.mark.soak  # kept out of the README's command for its time (python -m benchmarks.soak_checks)
def test_replay_as_arrays_equals_one_event_at_a_time():
    order, src, row, streams, hb_armed = file_order()
    results = []
    for arrays in (False, True):
        sink = RecordingSink()
        p = Pipeline(PipelineConfig(baseline_s=60.0), Reporter(sink, 1.0))

        def heartbeat(j):
            p.on_heartbeat(1, 2, 3, 128 if hb_armed[j] else 0)

        if arrays:
            used = feed_in_order(p, streams, order, src, row, heartbeat)
        else:
            used = 0
            for i in order:
                if src[i] < 0:
                    heartbeat(row[i])
                else:
                    s = streams[src[i]]
                    used += p.on_sample(s.key, s.t[row[i]], s.gyro[row[i]], s.accel[row[i]])
        results.append((used, p.transitions, sink.msgs, [(r["counts"], r["faults"], r["still_s"]) for r in p.summary()]))
    assert results[0][0] == results[1][0] == 2 * streams[0].t.size
    assert any("stuck" in text for _, text in results[0][1])  # something happened
    assert results[1][1] == results[0][1]
    assert results[1][3] == results[0][3]
    assert results[1][2] == results[0][2]  # every NAMED_VALUE_FLOAT and STATUSTEXT, in order


def test_a_baseline_in_other_units_stops_the_pipeline_with_one_line():
    from companion.health.baseline import Baseline

    rng = np.random.default_rng(1)
    base = Baseline("b.json")
    for ax in ("gx", "gy", "gz"):
        base.set_axis(0, ax, {"N": (1.0, 0.01)})  # rad/s/sqrt(Hz): 1000x the stream's
    p = Pipeline(PipelineConfig(min_report_s=10.0), Reporter(RecordingSink(), 1.0), baseline=base)
    key = StreamKey(1, 1, "RAW_IMU", 0)
    n = 100 * 60
    t = 1.0 + np.arange(n) / 100.0
    g = np.round(rng.normal(0, 2e-3, (n, 3)) / LSB) * LSB
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (n, 3))
    used = p.on_samples(key, t, g, a)
    assert p.failed and "does not match IMU0" in p.failed and "not SI units" in p.failed
    assert "\n" not in p.failed and used > 0
    assert p.on_samples(key, t[-1:] + 1.0, g[-1:], a[-1:]) == 0  # stopped: input ignored


def test_only_int16_messages_are_rounded_and_an_analyze_baseline_of_a_float_log_matches():
    """DataFlash IMU, ULog sensor_combined, HIGHRES_IMU and CSV carry float gyros (as the decoders read them,
    ImuStream.gyro_lsb None): a baseline from `analyze` of such a log (which records no LSB) matches the
    stream (it was refused: 'gyro LSB none (float) vs stream 0.001 rad/s'); an int16 stream against it
    is still refused."""
    from companion.health.baseline import Baseline

    rng = np.random.default_rng(2)
    n = 100 * 30
    t = 1.0 + np.arange(n) / 100.0
    g = rng.normal(0, 2e-3, (n, 3))
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (n, 3))
    for message, refused in (("IMU", False), ("sensor_combined", False), ("HIGHRES_IMU", False), ("RAW_IMU", True)):
        base = Baseline("report.json")
        for ax in ("gx", "gy", "gz"):
            base.set_axis(0, ax, {"N": (2e-4, 1e-5)})
        base.meta[0] = {"message": message, "rate_hz": 100.0, "gyro_lsb": None, "units": "SI"}  # analyze's record
        p = Pipeline(PipelineConfig(min_report_s=10.0), Reporter(RecordingSink(), 1.0), baseline=base)
        gg = np.round(g / LSB) * LSB if message == "RAW_IMU" else g
        p.on_samples(StreamKey(1, 1, message, 0), t, gg, a)
        if refused:
            assert p.failed and "gyro LSB none (float) vs stream 0.001 rad/s" in p.failed
        else:
            assert p.failed is None, (message, p.failed)
