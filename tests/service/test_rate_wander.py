"""A slow stream whose intervals wander (ArduPilot's telemetry slow-down on a busy radio) keeps its rate; a
stream asked for another rate (a ground station's 1 Hz -> 4 Hz -> 1 Hz) is still followed within seconds."""

from __future__ import annotations

import numpy as np
import pytest

from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline
from companion.service.pipeline_config import PipelineConfig
from tests.support.sinks import RecordingSink

SOAK = pytest.mark.soak  # the further seeds run by benchmarks/soak_checks.py: the suite's time


def slowed_times(seconds: float, seed: int, base: float = 0.5) -> np.ndarray:
    """Message times of a 2 Hz stream the autopilot slows while its radio buffer is full, as in the Phoenix
    tlogs (intervals 0.5-1.4 s): the interval climbs by 0.06 s a message to a random peak, then falls back
    by 0.02-0.04 s a message, with runs of whole 0.5 s between the climbs."""
    rng = np.random.default_rng(seed)
    t, s, out, up, peak = 1.0, 0.0, [], False, 0.0
    while t < seconds:
        if not up and s <= 0.0 and rng.random() < 0.2:
            up, peak = True, rng.uniform(0.2, 0.6)
        if up:
            s += 0.06
            up = s < peak
        else:
            s = max(0.0, s - rng.choice([0.02, 0.04]))
        t += base + s + rng.uniform(-0.002, 0.002)
        out.append(t)
    return np.array(out)


def requested_times(plan, seed: int) -> np.ndarray:
    """``plan``: (seconds, Hz) stretches, each at its rate with +-20 % jitter and 3 % of the messages lost."""
    rng = np.random.default_rng(seed)
    out, t0 = [], 1.0
    for dur, rate in plan:
        n = int(dur * rate)
        t = t0 + (np.arange(n) + rng.uniform(-0.2, 0.2, n)) / rate
        out.append(t[rng.random(n) >= 0.03])
        t0 += dur
    return np.concatenate(out)


def feed(t: np.ndarray, seed: int = 0) -> Pipeline:
    rng = np.random.default_rng(seed)
    p = Pipeline(PipelineConfig(), Reporter(RecordingSink(), 1.0))
    g = np.round(rng.normal(0.0, 2e-3, (t.size, 3)) / 1e-3) * 1e-3
    a = np.array([0.0, 0.0, -9.81]) + rng.normal(0.0, 0.02, (t.size, 3))
    key = StreamKey(1, 1, "RAW_IMU", 0)
    for c0 in np.arange(np.floor(t[0]), t[-1] + 1.0, 1.0):
        p.on_heartbeat(1, 2, 3, 0)
        sel = (t >= c0) & (t < c0 + 1.0)
        if sel.any():
            p.on_samples(key, t[sel], g[sel], a[sel])
    return p


@pytest.mark.parametrize("seed", [0] + [pytest.param(k, marks=SOAK) for k in (1, 2, 3)])
def test_a_stream_slowed_by_a_busy_radio_keeps_its_rate(seed):
    """20 minutes of intervals wandering between 0.5 and 1.4 s: with the 20 % rule alone the stream switched
    rate 16-29 times in such a log; here a few times at most, and never to a rate outside its range."""
    t = slowed_times(1200.0, seed)
    p = feed(t, seed)
    ch = p.channels[0]
    assert ch.rate_switches <= 4, p.rate_log
    assert all(0.65 <= new <= 2.1 for _, _, _, new in p.rate_log)
    assert not [x for x in p.transitions if "cleared" not in x[1]]


@pytest.mark.parametrize("seed", [0] + [pytest.param(k, marks=SOAK) for k in (1, 2)])
def test_a_requested_rate_change_is_followed_both_ways(seed):
    """1 Hz for 5 minutes, 4 Hz for 2 minutes, 1 Hz again: both changes followed within 15 s (four times
    the rate's spread apart: never taken for a wander), the rate right each time, no alarm."""
    t = requested_times([(300.0, 1.0), (120.0, 4.0), (300.0, 1.0)], seed)
    p = feed(t, seed)
    switches = [(te, new) for te, imu, _, new in p.rate_log]
    up = [te for te, new in switches if new == pytest.approx(4.0, rel=0.1) and te > 301.0]
    down = [te for te, new in switches if new == pytest.approx(1.0, rel=0.1) and te > 421.0]
    assert up and up[0] - 301.0 <= 15.0, switches
    assert down and down[0] - 421.0 <= 15.0, switches
    assert len(switches) == 2, switches
    assert not [x for x in p.transitions if "cleared" not in x[1]]
