"""Telemetry rates (1-10 Hz, jittery, a lost message now and then) through the run pipeline: the rate is
learned whatever the intervals, the health values go out from the first second, and a gyro that dies in
flight is named after a known number of samples (saturation and disagreement: test_fault_rates.py)."""

from __future__ import annotations

import numpy as np
import pytest

from companion.health.frozen_watch import NEED
from companion.service.blocks import BlockCutter
from tests.support.telemetry_sim import run, telemetry


def test_a_jittery_1hz_stream_whose_intervals_all_exceed_gap_s_gets_its_rate():
    """Intervals of 0.5-2 s (a ground station's 1 Hz stream on a busy radio): every one is over the 0.5 s
    gap_s, and before the rate was learned from all of them the stream never had a rate."""
    rng = np.random.default_rng(3)
    d = np.r_[np.full(8, 0.501), rng.uniform(0.5, 1.6, 400)]
    t = 1.0 + np.cumsum(d)
    cut = BlockCutter(1.0, 1.0, 0.5, 1e-3)
    rows = np.column_stack([t, np.zeros((t.size, 6))])
    for k in range(t.size):
        list(cut.cut(rows[k:k + 1]))
    assert cut.rate_hz is not None
    assert cut.rate_hz == pytest.approx(1.0 / np.median(d[-64:]), rel=0.25)
    assert cut.counts["gaps"] < 0.1 * t.size


def test_health_values_go_out_from_the_first_second_without_still_data():
    t, g, a = telemetry(1.0, 15.0, seed=1, imus=3, armed_at=0.0)
    p, sink = run(t, g, a, armed_at=0.0)
    sent = {name: ms for ms, name, _ in reversed([m for m in sink.msgs if m[0] != "T"])}
    for i in range(3):
        for suffix in ("G_HLTH", "G_FLT", "G_FLM"):
            assert f"IMU{i}{suffix}" in sent
            assert sent[f"IMU{i}{suffix}"] <= 1000.0 * (t[0] + 1.5)  # message time ms
    assert all(p.health(ch) == 2 for ch in p.channels.values())  # learning, no fault


@pytest.mark.parametrize("rate", [1.0, 2.0, 4.0, 10.0])
def test_a_gyro_dying_in_flight_is_named_within_need_samples_and_one_block(rate):
    t, g, a = telemetry(rate, 140.0 + 30.0 / rate * 10, seed=int(rate * 10))
    onset = 60.0
    g[1][t >= onset] = 0.0
    p, sink = run(t, g, a)
    named = [(te, text) for te, text in p.transitions if "IMU1" in text and "dead" in text]
    assert named, p.transitions
    k0 = int(np.searchsorted(t, onset))
    # every pair of the flight is motion (the twin moves by far more than 0.05 rad/s): NEED pairs after the
    # onset, said at the next block close (up to one block of 1 s, and the block closing sample's wait)
    assert named[0][0] == pytest.approx(t[k0 + NEED], abs=1e-9)
    assert not [x for x in p.transitions if x[1].startswith("IMU0") and "cleared" not in x[1]]
    assert any(m[0] == "T" and "IMU1 gyro" in m[2] and "dead" in m[2] for m in sink.msgs)
    assert sink.values["IMU1G_FLT"] == 11.0  # the dead code, held on the IMU's fault code


def test_a_healthy_pair_at_1hz_raises_nothing():
    t, g, a = telemetry(1.0, 600.0, seed=5, imus=3)
    p, _ = run(t, g, a)
    assert [x for x in p.transitions if "cleared" not in x[1]] == []
    assert all(ch.rate_hz for ch in p.channels.values())


def test_a_gyro_below_resolution_at_rest_is_told_apart_from_a_dead_one():
    """SITL-like: every gyro reads exactly 0 at rest (noise far below 1 mrad/s), then flies: no fault, and
    the summary says the gyro is alive, below RAW_IMU's step, and to ask for HIGHRES_IMU."""
    t, g, a = telemetry(2.0, 200.0, seed=8, imus=2, armed_at=100.0, rest_noise=1e-5)
    assert np.all(g[0][t < 100.0] == 0.0)
    p, _ = run(t, g, a, armed_at=100.0)
    # at rest the block test says what it can ("dead or below resolution", a WARNING); nothing says dead
    # once it moved, and its warnings clear then
    said = [text for _, text in p.transitions]
    assert not [x for x in said if "while moving" in x or "stuck" in x], said
    assert all(("IMU0" in x or "IMU1" in x) and "dead or below resolution" in x for x in said if "cleared" not in x)
    assert not [row["faults"] for row in p.summary() if row["faults"]]
    notes = [n for row in p.summary() for n in row["notes"] if "HIGHRES_IMU" in n and "alive" in n]
    assert len(notes) == 2 and "gyro X, Y, Z read exactly 0 at rest" in notes[0]
