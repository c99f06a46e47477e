"""Simulated telemetry (1-10 Hz, jittery, a lost message now and then) of a vehicle at rest then flying, and its
run through the pipeline the way ``run`` feeds it: shared by tests/service/test_telemetry_rates.py,
tests/service/test_fault_rates.py and benchmarks/bench_telemetry_rates.py (the samples each fault needs)."""

from __future__ import annotations

import numpy as np

from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline
from companion.service.pipeline_config import PipelineConfig
from tests.support.sinks import RecordingSink

LSB = 1e-3
MESSAGES = ("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")


def telemetry(rate: float, seconds: float, seed: int, imus: int = 2, armed_at: float = 20.0, rest_noise: float = 2e-3):
    """(t, gyro per IMU, accel per IMU): a vehicle at rest, flying from ``armed_at`` (body rates of +-0.5
    rad/s changing from sample to sample, the accelerometer turning with the attitude), sampled at ``rate``
    with +-20 % jitter and 3 % of the messages lost, gyro in 1 mrad/s steps."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate)
    t = 1.0 + (np.arange(n) + rng.uniform(-0.2, 0.2, n)) / rate
    t = t[rng.random(n) >= 0.03]
    fly = (t >= armed_at)[:, None]
    w = np.where(fly, rng.uniform(-0.5, 0.5, (t.size, 3)), 0.0)
    tilt = np.where(fly, rng.uniform(-0.3, 0.3, (t.size, 2)), 0.02)
    acc = np.column_stack([9.81 * np.sin(tilt[:, 0]), 9.81 * np.sin(tilt[:, 1]), -9.81 * np.cos(tilt[:, 0])])
    g = [np.round((w + rng.normal(0, rest_noise, w.shape) + np.where(fly, rng.normal(0, 0.02, w.shape), 0)) / LSB) * LSB
         for _ in range(imus)]
    a = [acc + rng.normal(0, 0.05, acc.shape) for _ in range(imus)]
    return t, g, a


def run(t, g, a, armed_at: float = 20.0):
    sink = RecordingSink()
    p = Pipeline(PipelineConfig(), Reporter(sink, 1.0))
    keys = [StreamKey(1, 1, MESSAGES[i], i) for i in range(len(g))]
    for c0 in np.arange(float(np.floor(t[0])), t[-1] + 1.0, 1.0):
        p.on_heartbeat(1, 2, 3, 128 if c0 >= armed_at else 0)
        sel = (t >= c0) & (t < c0 + 1.0)
        for i, key in enumerate(keys):
            if sel.any():
                p.on_samples(key, t[sel], g[i][sel], a[i][sel])
    return p, sink
