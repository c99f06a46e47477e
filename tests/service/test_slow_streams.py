"""Streams far slower than the IMU: a PX4 log's vehicle_imu at 2 Hz beside sensor_combined at ~220 Hz, a
telemetry stream at 2 Hz.

The disagreement test compares two IMUs at the slower stream's instants. Found on a public PX4 log
(flight-review-rs' battery_brownout.ulg): the 2 Hz stream was interpolated between its snapshots, half a second
apart, at the fast stream's instants; in flight that line is no rate, and the healthy pair "disagreed" on gyro Y
twice. Then a 2 Hz stream was never compared at all (too few samples in the recent blocks, and half its
intervals counted as gaps)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline_config import PipelineConfig
from companion.service.pipeline import Pipeline
from tests.support.sinks import RecordingSink

G = np.array([0.0, 0.0, -9.80665])


def _flight_rate(t, seed):
    """A flight's body rates (rad/s): a few sinusoids of 0.3-3 Hz, 0.2-1 rad/s each, per axis."""
    rng = np.random.default_rng(seed)
    out = np.zeros((t.size, 3))
    for a in range(3):
        for _ in range(4):
            out[:, a] += rng.uniform(0.2, 1.0) * np.sin(2 * math.pi * rng.uniform(0.3, 3.0) * t + rng.uniform(0, 6.3))
    return out


def _fly(slow_hz, seed, bias=0.0, seconds=120.0):
    """IMU0 at 200 Hz and IMU1 at ``slow_hz`` sampling the same rotation (each with its own noise), armed
    after 30 s at rest; IMU1's X axis ``bias`` rad/s off from 60 s."""
    p = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
    rng = np.random.default_rng(100 + seed)
    t_fast = np.arange(0.0, seconds, 1 / 200.0) + 1.0
    t_slow = np.arange(0.0, seconds, 1 / slow_hz) + 1.0 + 0.0013
    streams = []
    for k, t in ((0, t_fast), (1, t_slow)):
        w = np.where((t > 31.0)[:, None], _flight_rate(t, seed), 0.0) + rng.normal(0.0, 2e-3, (t.size, 3))
        if k == 1:
            w[t >= 60.0, 0] += bias
        a = G + rng.normal(0.0, 0.02, (t.size, 3)) + np.where((t > 31.0)[:, None], 0.5, 0.0)
        streams.append((StreamKey(1, 1, "HIGHRES_IMU", k), t, w, a))
    step = 1.0
    for s0 in np.arange(1.0, seconds + 1.0, step):
        if abs(s0 - 31.0) < 1e-9:
            p.on_heartbeat(1, 2, 3, 128)  # armed: a quadrotor (MAV_TYPE 2) of ArduPilot (3)
        for key, t, w, a in streams:
            sel = (t >= s0) & (t < s0 + step)
            if sel.any():
                p.on_samples(key, t[sel], w[sel], a[sel])
    return p


def test_a_healthy_pair_at_200_and_2_hz_does_not_disagree_in_flight():
    for seed in range(3):
        p = _fly(2.0, seed)
        assert not [x for _, x in p.transitions if "disagree" in x], p.transitions


def test_a_pair_at_200_and_10_hz_is_compared_at_the_slow_instants_and_a_biased_imu_is_named():
    for seed in range(2):
        healthy = _fly(10.0, seed)
        assert not [x for _, x in healthy.transitions if "disagree" in x], healthy.transitions
        biased = _fly(10.0, seed, bias=15.0 * math.pi / 180.0)
        named = [x for _, x in biased.transitions if "disagree" in x]
        assert any("gyro X disagrees" in x for x in named), biased.transitions


def test_a_biased_imu_logged_at_2_hz_is_named_against_its_200_hz_twin():
    # two samples per 1-s block: the comparison waits for enough common instants over several blocks
    # instead of never testing the pair (three recent blocks held 6 samples, fewer than a test needs)
    for seed in range(2):
        biased = _fly(2.0, seed, bias=15.0 * math.pi / 180.0)
        named = [x for _, x in biased.transitions if "disagree" in x]
        assert any("gyro X disagrees" in x for x in named), biased.transitions



def test_a_stream_too_slow_for_the_per_imu_tests_is_said_so():
    # a 1-s block of a 2 Hz stream holds 3 samples, fewer than a block's noise needs: the tests that read it
    # (noise, bias, spikes, stuck at rest) never learn a reference; the user is told what is watched instead
    from companion.service.run_session import summary_lines

    p = _fly(2.0, 0, seconds=60.0)
    notes = {r["imu"]: r["notes"] for r in p.summary()}
    assert notes[0] == [] and len(notes[1]) == 1 and "2.0 Hz a 1-s block holds 3 samples" in notes[1][0], notes
    assert any(line.startswith("  note: IMU1: at 2.0 Hz") for line in summary_lines(p))
    assert not [r for r in _fly(10.0, 0, seconds=40.0).summary() if r["notes"]]


@pytest.mark.soak
def test_a_still_2_hz_stream_with_jitter_is_one_record_for_the_estimators():
    # consecutive 1-s blocks of a 2 Hz stream are one period (0.5 s) apart, which was also the junction
    # threshold (half a block): timestamp jitter made every other pair of blocks a junction, the estimators
    # saw pieces of a few seconds and the shared ArduSub tlog's z axis a bias instability from tau <= 4 s.
    # Late messages (a period split into 0.1-0.4 s + the rest) took the rate 3 % high.
    n_true = 3e-4  # rad/s/sqrt(Hz): white rate noise of std N sqrt(fs) at 2 Hz
    for seed in range(3):
        rng = np.random.default_rng(seed)
        t = 5.0 + np.arange(800) * 0.5 + rng.normal(0.0, 3e-4, 800)
        late = rng.choice(np.arange(10, 790), 8, replace=False)
        t[late] += rng.uniform(0.1, 0.4, late.size)
        w = rng.normal(0.0, n_true * math.sqrt(2.0), (t.size, 3))
        a = G + rng.normal(0.0, 0.02, (t.size, 3))
        p = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
        key = StreamKey(1, 1, "HIGHRES_IMU", 0)
        for s0 in np.arange(5.0, 405.0, 1.0):
            sel = (t >= s0) & (t < s0 + 1.0)
            p.on_samples(key, t[sel], w[sel], a[sel])
        ch = p.channels[0]
        assert ch.rate_hz == pytest.approx(2.0, rel=2e-3)
        for ax in ("gx", "gy", "gz"):
            assert len(ch.fast[ax].segments()) == 1, ch.fast[ax].segments()
            terms = {x["effect"]: x for x in p.final_terms(ch, ax)}
            # about 750 samples: N's relative sd about 3 %; 4 sd
            assert terms["white_noise"]["N"] == pytest.approx(n_true, rel=0.12)
            assert terms["bias_instability"]["bound"], terms["bias_instability"]
