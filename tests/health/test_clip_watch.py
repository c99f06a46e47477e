"""The clip watch (health/clip_watch.py) on its own: a clip named after NEED samples at it, at any rate up to
20 Hz; a steady turn, a biased gyro at rest and healthy motion never; a sample at the message's limit at once."""

from __future__ import annotations

import numpy as np
import pytest

from companion.health.clip_watch import NEED, WINDOW, ClipWatch
from companion.health.hold import FAULT, OK

LSB = 1e-3


def feed(g: np.ndarray, rate: float = 2.0, limit: float = 32.767):
    w = ClipWatch(limit)
    t = 1.0 + np.arange(g.shape[0]) / rate
    for k in range(0, g.shape[0], 7):  # in pieces, as a replay hands them
        w.add(0, t[k:k + 7], g[k:k + 7])
    return t, w.take()


def motion(n: int, seed: int, amp: float = 0.5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.round(rng.uniform(-amp, amp, (n, 3)) / LSB) * LSB


@pytest.mark.parametrize("seed", range(5))
def test_a_clip_is_named_after_need_samples_at_it(seed):
    g = motion(400, seed)
    g[200:] = np.clip(g[200:], -0.3, 0.3)
    t, ev = feed(g)
    (te, first), *_ = ev
    assert first.state == FAULT and first.kind == "saturation" and first.value == pytest.approx(0.3)
    j = "xyz".index(first.axis[1])
    k = int(np.searchsorted(t, te))
    at = int(np.count_nonzero(np.abs(g[200:k + 1, j]) == 0.3))
    assert NEED <= at <= 2 * NEED and k - 200 < WINDOW


@pytest.mark.parametrize("seed", range(5))
def test_healthy_motion_a_steady_turn_and_a_biased_gyro_at_rest_are_no_clip(seed):
    rng = np.random.default_rng(seed)
    assert feed(motion(3000, seed))[1] == []
    steady = np.round((0.2 + rng.normal(0.0, 0.3 * LSB, (600, 3))) / LSB) * LSB  # below its step: 200/201
    assert feed(steady)[1] == []
    biased = np.round((0.1745 + rng.normal(0.0, 2 * LSB, (600, 3))) / LSB) * LSB
    assert feed(biased)[1] == []


def test_a_sample_at_the_message_limit_is_named_at_once_and_a_value_beyond_a_clip_clears_it():
    g = motion(100, 1)
    g[50, 2] = 32.767
    t, ev = feed(g)
    assert [(round(te, 6), e.axis, e.state) for te, e in ev] == [(round(t[50], 6), "gz", FAULT)]
    g = motion(400, 2)
    g[100:250] = np.clip(g[100:250], -0.3, 0.3)
    _, ev = feed(g)
    states = [e.state for _, e in ev if e.axis == ev[0][1].axis]
    assert states[:2] == [FAULT, OK]


def test_a_stream_above_20_hz_is_left_to_the_block_test():
    g = motion(2000, 3)
    g[1000:] = np.clip(g[1000:], -0.3, 0.3)
    assert feed(g, rate=50.0)[1] == []
