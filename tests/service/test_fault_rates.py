"""Saturation and disagreement at telemetry rates (1, 2, 4, 10 Hz, jittery, a lost message now and then)
through the run pipeline: each fault injected in flight is named within the number of samples its detector
needs at that rate (the table of docs/health.md), and the healthy twins are not named.

* saturation at the message's own limit (32.767 rad/s): 1 sample at the limit (the clip watch at its
  sample up to 20 Hz, the block test at the block's close);
* a clip below the message's range: the clip watch (health/clip_watch.py), NEED samples at the clip within
  WINDOW samples, at any rate up to 20 Hz;
* a gyro off its twins by a bias of 10 deg/s (twice ArduPilot's 5 deg/s consistency limit): the pair test
  (health/disagreement.py): h / (h / hold) = ``disagree_hold_blocks`` tests with full evidence, each of
  MIN_ALIGNED samples or one block, after the test that holds the onset; one or two more where a test's
  evidence falls below the cap (the floor grows with the block's rms rate): (hold + 3) tests.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.health import clip_watch
from companion.health.evidence_rules import FaultLimits
from companion.service.imu_group import MIN_ALIGNED
from tests.support.telemetry_sim import run, telemetry

SOAK = pytest.mark.soak  # run by benchmarks/soak_checks.py: the suite's time keeps the extremes only
RATES = [1.0, pytest.param(2.0, marks=SOAK), pytest.param(4.0, marks=SOAK), 10.0]
SEEDS = [0, pytest.param(1, marks=SOAK)]
ONSET = 50.0
LIMIT = 32.767  # rad/s: int16 mrad/s


def fault_samples_needed(rate: float, block_s: float = 1.0) -> int:
    """The samples after the onset within which the disagreement test names a biased gyro (docs/health.md)."""
    return (FaultLimits().disagree_hold_blocks + 3) * max(MIN_ALIGNED, math.ceil(rate * block_s))


def named(p, imu: int, word: str):
    return [(te, x) for te, x in p.transitions if x.startswith(f"IMU{imu} ") and word in x and "cleared" not in x]


def others_named(p, bad: int):
    return [(te, x) for te, x in p.transitions if not x.startswith(f"IMU{bad} ") and "cleared" not in x
            and "baseline learned" not in x]


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("rate", RATES)
def test_a_gyro_at_the_message_limit_is_named_at_the_block_that_holds_the_sample(rate, seed):
    t, g, a = telemetry(rate, 100.0, seed=100 * seed + int(rate * 10), imus=3)
    after = t >= ONSET
    g[1][after] = np.clip(g[1][after] * 100.0, -LIMIT, LIMIT)  # a violent motion beyond the range
    p, _ = run(t, g, a)
    hits = np.flatnonzero(after & np.any(np.abs(g[1]) >= LIMIT, axis=1))
    sat = named(p, 1, "saturated")
    assert sat, p.transitions
    # the first sample at the limit names it (said at the next block close of any IMU, with that sample's time)
    assert sat[0][0] == pytest.approx(t[hits[0]], abs=1e-9)
    assert not others_named(p, 1), p.transitions


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("rate", RATES)
def test_a_gyro_clipped_below_the_message_range_is_named_after_need_samples_at_the_clip(rate, seed):
    level = 0.3  # rad/s; the flight's body rates reach 0.5
    t, g, a = telemetry(rate, 100.0, seed=100 * seed + int(rate * 10), imus=3)
    after = t >= ONSET
    g[1][after] = np.clip(g[1][after], -level, level)
    p, _ = run(t, g, a)
    sat = named(p, 1, "saturated at 0.3 rad/s")
    assert sat, p.transitions
    te = sat[0][0]
    axis = "XYZ".index(sat[0][1].split()[2])
    at_clip = int(np.count_nonzero(after & (t <= te) & (np.abs(g[1][:, axis]) == level)))
    since = int(np.count_nonzero(after & (t <= te)))
    # NEED at the clip, more where the window also holds healthy values just below it (RATIO); within WINDOW
    assert clip_watch.NEED <= at_clip <= 2 * clip_watch.NEED, (at_clip, since)
    assert since <= clip_watch.WINDOW
    assert not others_named(p, 1), p.transitions


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("rate", RATES)
def test_a_gyro_biased_off_its_twins_is_named_odd_one_out_within_the_samples_needed(rate, seed):
    t, g, a = telemetry(rate, 100.0, seed=100 * seed + int(rate * 10), imus=3)
    g[1][t >= ONSET, 0] += math.radians(10.0)
    p, _ = run(t, g, a)
    dis = named(p, 1, "gyro X disagrees with IMU0/IMU2")
    assert dis, p.transitions
    since = int(np.count_nonzero((t >= ONSET) & (t <= dis[0][0])))
    assert since <= fault_samples_needed(rate), (since, fault_samples_needed(rate))
    assert not others_named(p, 1), p.transitions


@pytest.mark.parametrize("rate", [1.0, pytest.param(4.0, marks=SOAK), pytest.param(10.0, marks=SOAK)])
def test_with_two_imus_at_rest_the_biased_one_is_named_alone(rate):
    """Two IMUs alone cannot say which of them is off in flight (both are suspects there); at rest the true
    rate is 0, and the IMU whose reading left its own mean at rest is named alone, at 1 Hz too (where the
    bias test has no reference: 1 sample a block)."""
    t, g, a = telemetry(rate, 260.0, seed=3, imus=2, armed_at=1e9)
    onset = 200.0
    g[1][t >= onset, 0] += math.radians(10.0)
    p, sink = run(t, g, a, armed_at=1e9)
    dis = named(p, 1, "disagrees with IMU0")
    assert dis, p.transitions
    assert int(np.count_nonzero((t >= onset) & (t <= dis[0][0]))) <= fault_samples_needed(rate)
    assert not others_named(p, 1), p.transitions
    assert sink.values["IMU0G_FLT"] == 0.0 and sink.values["IMU1G_FLT"] > 0.0
