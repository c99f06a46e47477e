"""Stream-rate changes are not motion: a router that sets stream rates every 15 s (MAVProxy's default
beside a companion that asks its rate back) must leave the pipeline still data to learn from and raise
no alarm. Fed to a Pipeline directly, in message time.

Model: a still vehicle, white rate noise N = 3e-3 rad/s/sqrt(Hz) per axis rounded to 1 mrad/s (RAW_IMU),
accel noise 0.02 m/s^2; the stream at 50 Hz for 9 s, then 4 Hz for 6 s, repeated (what MAVProxy's 4 Hz
request every 15 s and the companion's request back gave in real time: 4-6 s at 4 Hz in every 15 s).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline, PipelineConfig
from tests.support.sinks import RecordingSink

KEY = StreamKey(1, 1, "RAW_IMU", 0)
N_SI = 3e-3
FAULT_WORDS = ("stuck", "dead", "noise", "bias", "spike", "drift", "saturat", "timing", "disagree", "degrad")


def alternating_times(duration_s, fast_hz=50.0, fast_s=9.0, slow_hz=4.0, slow_s=6.0, t0=1.0):
    """Sample times (s) of a stream at ``fast_hz`` for ``fast_s``, then ``slow_hz`` for ``slow_s``, repeated."""
    out, t = [], t0
    while t < t0 + duration_s:
        for hz, span in ((fast_hz, fast_s), (slow_hz, slow_s)):
            n = int(round(span * hz))
            out.append(t + np.arange(n) / hz)
            t += n / hz
    return np.round(np.concatenate(out) * 1e6) * 1e-6  # time_usec


@pytest.mark.parametrize("seed", [0, 1])
def test_a_router_setting_stream_rates_every_15_s_leaves_still_data_and_raises_no_alarm(seed):
    rng = np.random.default_rng(seed)
    sink = RecordingSink()
    p = Pipeline(PipelineConfig.from_mapping({"baseline_s": 60}), Reporter(sink, 1.0))
    t = alternating_times(450.0)
    t = np.concatenate([t, t[-1] + 0.25 + np.arange(1000) / 50.0])  # and 20 s at 50 Hz to end with
    dt = np.diff(t, prepend=t[0] - 0.02)
    # white rate noise of density N: sample std N / sqrt(dt) at any rate (the mean rate over each interval)
    g = np.round(rng.normal(0.0, 1.0, (t.size, 3)) * (N_SI / np.sqrt(dt))[:, None] / 1e-3) * 1e-3
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (t.size, 3))
    for k in range(t.size):
        p.on_sample(KEY, float(t[k]), g[k], a[k])
    texts = [x for _, x in sink.texts]
    ch = p.channels[0]
    assert ch.rate_switches >= 50, (ch.rate_switches, ch.counts)  # the stream did switch, twice per 15 s
    assert not [x for x in texts if any(w in x.lower() for w in FAULT_WORDS)], texts
    # 30 cycles of 9 s at 50 Hz: 3 s of each go to the rate switch and one block to the look-ahead, about
    # 5 s of still data per cycle; settling 10 s after every switch left none at all
    assert "IMU0 gyro baseline learned" in texts, (texts, ch.counts)
    assert sink.values["IMU0G_HLTH"] == 0.0
    # once the baseline is learned and checked, HLTH stays 0 through the 4 Hz stretches too (2 means "no
    # baseline yet"; before this change it read 2 at 4 Hz until 30 s of data at that rate were used)
    learned_at = next(i for i, m in enumerate(sink.msgs) if m[0] == "T" and "baseline learned" in m[2])
    after = [m[2] for m in sink.msgs[learned_at:] if m[0] != "T" and m[1] == "IMU0G_HLTH"]
    assert 0.0 in after, after
    after = after[after.index(0.0):]  # from the first check after learning on
    assert set(after) == {0.0}, after
    n_true = math.sqrt(N_SI**2 + 1e-6 / (12 * 50.0)) / (math.pi / 180.0 / 60.0)  # deg/sqrt(h), with rounding
    for ax in "XYZ":
        assert sink.values[f"IMU0G{ax}_N"] == pytest.approx(n_true, rel=0.15)


def wandering_times(duration_s, lo_hz=1.6, hi_hz=4.2, cycle_s=120.0, t0=1.0):
    """Sample times of a telemetry stream whose rate the autopilot lowers and raises as its link gets busy
    (ArduPilot slows its streams while the radio's buffer fills): the rate moves smoothly between ``lo_hz``
    and ``hi_hz`` and back every ``cycle_s`` (a real 1000-s tlog: 1.6-4.2 Hz, its intervals 0.24-0.70 s)."""
    out, t = [], t0
    while t < t0 + duration_s:
        phase = 0.5 - 0.5 * math.cos(2 * math.pi * (t - t0) / cycle_s)
        t += 1.0 / (lo_hz + (hi_hz - lo_hz) * phase)
        out.append(t)
    return np.round(np.asarray(out) * 1e6) * 1e-6


def test_a_stream_whose_rate_keeps_wandering_is_logged_a_few_times_then_summed_up():
    rng = np.random.default_rng(5)
    sink, lines = RecordingSink(), []
    p = Pipeline(PipelineConfig.from_mapping({"baseline_s": 60}), Reporter(sink, 1.0), log=lines.append)
    t = wandering_times(1200.0)
    g = np.round(rng.normal(0.0, 3e-3, (t.size, 3)) / 1e-3) * 1e-3  # point samples of a filtered gyro
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (t.size, 3))
    for k in range(t.size):
        p.on_sample(KEY, float(t[k]), g[k], a[k])
    ch = p.channels[0]
    assert ch.rate_switches >= 6, ch.rate_switches  # the stream did switch, again and again (a factor 2.6)
    changed = [x for x in lines if "rate changed" in x]
    assert len(changed) == 3, lines
    assert len([x for x in lines if "keeps changing" in x]) == 1, lines
    (row,) = p.summary()
    (note,) = [n for n in row["notes"] if "rate changed" in n]
    assert f"changed {ch.rate_switches} times" in note, note
    lo, hi = (float(x) for x in note.split("between ")[1].split(" Hz")[0].split(" and "))
    assert 1.4 <= lo <= 2.2 and 3.4 <= hi <= 4.5, note  # the range of the rates that were taken
    texts = [x for _, x in sink.texts]
    assert not [x for x in texts if any(w in x.lower() for w in FAULT_WORDS)], texts


def stepped_times(steps, t0=1.0):
    """Sample times of a stream at ``hz`` for ``span`` s for each ``(hz, span)`` of ``steps`` in turn."""
    out, t = [], t0
    for hz, span in steps:
        n = int(round(span * hz))
        out.append(t + np.arange(1, n + 1) / hz)
        t = out[-1][-1]
    return np.round(np.concatenate(out) * 1e6) * 1e-6


def test_a_rate_near_one_kept_before_does_not_throw_the_richer_one_away():
    """A telemetry stream whose rate the autopilot lowers and raises: 300 s at 2.5 Hz, 20 s at 3.1, 20 s at
    3.8, then 100 s at 2.5 again, still throughout. Putting 3.1 Hz aside replaced every kept rate within
    20 % of it, so the 300 s of 2.5 Hz went, and the return to 2.5 Hz restored the 20 s of 3.1 (a real tlog's
    IMU1 ended with 0 s of its 323 still blocks in any estimator). Now both are kept and the richer comes back."""
    rng = np.random.default_rng(11)
    sink = RecordingSink()
    p = Pipeline(PipelineConfig.from_mapping({"baseline_s": 600}), Reporter(sink, 1.0))
    t = stepped_times([(2.5, 300.0), (3.1, 20.0), (3.8, 20.0), (2.5, 100.0)])
    g = np.round(rng.normal(0.0, 3e-3, (t.size, 3)) / 1e-3) * 1e-3
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (t.size, 3))
    for k in range(t.size):
        p.on_sample(KEY, float(t[k]), g[k], a[k])
    ch = p.channels[0]
    assert ch.rate_switches == 3, ch.rate_switches
    assert ch.rate_hz == pytest.approx(2.5, rel=0.05)
    # the first 300 s (less the settling and the first blocks) and most of the last 100 s are in this rate's
    # estimators; before, 20 s of 3.1 Hz and the last 100 s
    assert ch.fed_s > 330.0, (ch.fed_s, ch.kept_rates())
    (row,) = p.summary()
    assert row["other_rates"][0] == 2 and row["other_rates"][1] > 20.0, row["other_rates"]  # 3.1 and 3.8 Hz kept
