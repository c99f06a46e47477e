"""Taps on a standing vehicle are no gyro spikes; isolated glitches are, with or without the accelerometer.

Found on a public PX4 log (px4-ulog-rs' corrupt_actuator_armed_wrong_size.ulg, never armed): taps on the
vehicle moved the accelerometer 20-40 robust sigmas for 6-10 samples at 200 Hz and two gyro axes at once,
one per second for four seconds, and run said "IMU0 gyro Y spikes 0.11 %"."""

from __future__ import annotations

import numpy as np
import pytest

from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline_config import PipelineConfig
from companion.service.pipeline import Pipeline
from tests.support.sinks import RecordingSink

FS = 200.0
G = np.array([0.0, 0.0, -9.80665])


def _run(seed, taps=(), glitches=(), glitch_accel=0.0, seconds=100.0):
    """At rest at 200 Hz; ``taps``: times of a knock (a damped 60 Hz ring of the accelerometer, 0.3 m/s^2
    decaying in 30 ms: 6 sigma or more for ~10 samples, and a one-sample jump of gyro X and Y, as on the log); ``glitches``: times of a one-sample gyro Y outlier of
    0.3 rad/s (and of the accelerometer by ``glitch_accel`` m/s^2: a corrupted IMU sample)."""
    rng = np.random.default_rng(seed)
    t = 1.0 + np.arange(int(seconds * FS)) / FS
    g = rng.normal(0.0, 2e-3, (t.size, 3))
    a = G + rng.normal(0.0, 0.015, (t.size, 3))
    for t0 in taps:
        d = t - t0
        ring = np.where(d >= 0, np.exp(-np.maximum(d, 0) / 0.03) * np.sin(2 * np.pi * 60.0 * d), 0.0)
        a += 0.3 * ring[:, None] * np.array([1.0, 0.7, 0.5])
        k = int(np.searchsorted(t, t0))
        g[k, :2] += np.array([0.05, -0.04])  # the gyro jumps for a sample and is back (as on the log)
    for t0 in glitches:
        k = int(np.argmin(np.abs(t - t0)))
        g[k, 1] += 0.3
        a[k, 2] += glitch_accel
    p = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
    p.on_samples(StreamKey(1, 1, "HIGHRES_IMU", 0), t, g, a)
    return [x for _, x in p.transitions if "spikes" in x and "cleared" not in x]


def test_taps_on_a_standing_vehicle_are_not_gyro_spikes():
    for seed in range(3):
        # before the still references exist (as on the log) and after
        assert not _run(seed, taps=(12.3, 13.4, 14.6, 15.5, 16.7, 60.2, 61.1, 62.5, 63.3, 64.8)), seed


@pytest.mark.soak
def test_isolated_glitches_are_spikes_with_or_without_the_accelerometer():
    ts = (60.2, 61.1, 62.5, 63.3, 64.8, 70.2, 71.1, 72.5)  # after the still references (30 blocks) exist
    for seed in range(3):
        assert any("gyro Y spikes" in x for x in _run(seed, glitches=ts)), seed
        # the accelerometer's glitch with it, 20 sigma or 200: the gate does not take one sample for motion
        for acc in (0.3, 3.0):
            assert any("gyro Y spikes" in x for x in _run(seed, glitches=ts, glitch_accel=acc)), (seed, acc)
