"""Spikes at a 10 Hz log rate and a float gyro frozen with a dither, judged against the accelerometer.

Simulated blocks with a known truth through health.monitor.ImuFaults (the detectors of one IMU, as the
pipeline drives them: on_block for every block, on_quiet for still ones), fast and deterministic.
"""

from __future__ import annotations

import numpy as np

from companion.health.block_stats import block_stats
from companion.health.monitor import ImuFaults

LSB = 1e-3  # int16 mrad/s


def _plane_block(rng, n=11, sigma=0.36 * LSB, level=0.3 * LSB):
    """A 10 Hz block of a quiet gyro rounded to 1 mrad/s (the realistic plane: 0.36 LSB of noise)."""
    return np.round(rng.normal(level, sigma, (n, 3)) / LSB) * LSB


def _learn(f, rng, make, accel=None, blocks=30):
    t0 = 0.0
    for _ in range(blocks):
        y = make(rng)
        st = block_stats(y, f.dd_scale_ref())
        a = None if accel is None else accel(rng, y.shape[0])
        assert f.on_block(st, t0 + np.arange(y.shape[0]) / 10.0, True, y, a) == []
        assert f.on_quiet(st) == []
        t0 += 1.0
    return t0


def test_a_spike_inside_a_10hz_block_is_counted_and_left_out_of_the_noise():
    rng = np.random.default_rng(3)
    ref = np.full(3, np.sqrt(6.0 * ((0.36 * LSB) ** 2 + LSB ** 2 / 12.0)))
    seen = np.zeros(11)
    for k in range(550):
        y = _plane_block(rng)
        i = k % 11
        y[i, 0] += 0.3 * (1 if k % 2 else -1)
        st = block_stats(y, ref)
        seen[i] += st.spikes[0]
        if 0 < i < 10:  # the 0.3 rad/s spike (9e-2 rad^2/s^2 per sample) is not in the noise figure
            assert st.v2[0] < 1e-5
    # every position but the first and last sample, whose spike shape lies half outside the block
    assert seen[0] == seen[-1] == 0 and np.all(seen[1:-1] >= 45)
    healthy = sum(int(block_stats(_plane_block(rng), ref).spikes.sum()) for _ in range(2000))
    assert healthy == 0


def test_a_spike_at_a_10hz_block_junction_is_counted_once_with_the_previous_samples_carried():
    """Carrying the previous block's last samples (what the pipeline's Channel does) makes the block's first
    sample and the previous block's last one spike centres too: every position counted, none twice."""
    rng = np.random.default_rng(6)
    ref = np.full(3, np.sqrt(6.0 * ((0.36 * LSB) ** 2 + LSB ** 2 / 12.0)))
    seen = np.zeros(11)
    prev = _plane_block(rng)[-6:]
    for k in range(220):
        y = _plane_block(rng)
        i = k % 11
        y[i, 0] += 0.3 * (1 if k % 2 else -1)
        nxt = _plane_block(rng)
        st, st2 = block_stats(y, ref, prev=prev), block_stats(nxt, ref, prev=y[-6:])
        seen[i] += st.spikes[0] + st2.spikes[0]
        assert st2.v2[0] < 1e-5  # a spike on the junction is not in the next block's noise either
        prev = nxt[-6:]
    assert np.all(seen == 20), seen


def test_motion_starting_at_a_10hz_block_end_is_no_spike():
    """A real parked plane starting its take-off roll: the rate rises over the block's last samples."""
    rng = np.random.default_rng(4)
    ref = np.full(3, np.sqrt(6.0 * ((0.36 * LSB) ** 2 + LSB ** 2 / 12.0)))
    for k in range(200):
        y = _plane_block(rng)
        ramp = np.zeros(11)
        ramp[-2:] = rng.uniform(0.01, 0.2) * np.array([0.3, 1.0]) * (1 if k % 2 else -1)
        y[:, 0] += ramp
        y[-1, 2] += rng.uniform(0.01, 0.2)  # a step on the last sample
        assert block_stats(y, ref).spikes.sum() == 0, k


def test_spikes_at_10hz_are_named_spikes_not_noise():
    rng = np.random.default_rng(5)
    f = ImuFaults(0, ref_blocks=30)
    t0 = _learn(f, rng, _plane_block)
    events = []
    for k in range(120):  # 0.8 % of the samples, 0.3 rad/s
        y = _plane_block(rng)
        hit = rng.random(11) < 0.008
        y[hit, 1] += 0.3
        st = block_stats(y, f.dd_scale_ref())
        t = t0 + k + np.arange(11) / 10.0
        events += f.on_block(st, t, True, y) + f.on_quiet(st)
    kinds = {(e.kind, e.axis) for e in events}
    assert ("spikes", "gy") in kinds
    assert not any(e.kind == "noise" for e in events)


def _two_spikes(jolt: bool, spikes=(5, 25)):
    """A quiet 10 Hz gyro with 0.3 rad/s spikes in the given blocks (after 30 learned); with ``jolt`` the
    accelerometer moves on the same sample (a knock on the vehicle, not a gyro glitch). The blocks at which
    ``spikes`` was named."""
    rng = np.random.default_rng(7)
    f = ImuFaults(0, ref_blocks=30)
    accel = _accel(0.02)
    t0 = _learn(f, rng, _plane_block, accel=accel)
    named = []
    for k in range(60):
        y, a = _plane_block(rng), accel(rng, 11)
        if k in spikes:
            y[5, 2] += 0.3
            if jolt:
                a[5, 1] += 1.0
        st = block_stats(y, f.dd_scale_ref())
        ev = f.on_block(st, t0 + k + np.arange(11) / 10.0, True, y, a) + f.on_quiet(st)
        named += [k for e in ev if e.kind == "spikes" and e.state]
    return named


def test_two_large_spikes_on_a_still_gyro_are_named_at_the_second_one_never_at_one():
    # a 0.3 rad/s spike is ~500 robust sigmas here: its size is evidence, but one alone is never a fault
    assert _two_spikes(False) == [25]
    assert _two_spikes(False, spikes=(5,)) == []
    # the same with the accelerometer jolted on those samples: knocks, weighed by their count alone
    assert _two_spikes(True) == []


def _float_block(rng, n=250, sigma=2e-3):
    return rng.normal(0.01, sigma, (n, 3))


def _accel(scale):
    def make(rng, n):
        return rng.normal(0.0, scale, (n, 3)) + np.array([0.0, 0.0, -9.81])
    return make


def _run_float(rng, f, t0, blocks, gyro_sigma, accel_scale, frozen=None, dither=0.0):
    events = []
    for k in range(blocks):
        y = _float_block(rng, sigma=gyro_sigma)
        if frozen is not None:
            y[:, 0] = frozen + rng.normal(0.0, dither, y.shape[0])
        st = block_stats(y, f.dd_scale_ref())
        t = t0 + k + np.arange(y.shape[0]) / 250.0
        events += f.on_block(st, t, True, y, _accel(accel_scale)(rng, y.shape[0])) + f.on_quiet(st)
    return events


def test_float_gyro_frozen_with_a_dither_while_the_accel_still_vibrates_is_stuck():
    rng = np.random.default_rng(6)
    f = ImuFaults(0, ref_blocks=30)
    t0 = _learn(f, rng, _float_block, _accel(0.05))
    events = _run_float(rng, f, t0, 5, 2e-3, 0.05, frozen=0.0123, dither=0.2 * 2e-3)
    assert [(e.kind, e.axis) for e in events] == [("stuck", "gx")]


def test_float_gyro_quieter_when_the_vibration_stops_is_not_stuck():
    """A parked plane's engine stops: the gyro's noise falls 5x and so does the accelerometer's."""
    rng = np.random.default_rng(7)
    f = ImuFaults(0, ref_blocks=30)
    t0 = _learn(f, rng, _float_block, _accel(0.05))
    events = _run_float(rng, f, t0, 120, 2e-3 / 5, 0.05 / 5)
    assert not any(e.kind == "stuck" for e in events)
    # and without an accelerometer (nan columns) the variance drop alone is never stuck either
    g = ImuFaults(0, ref_blocks=30)
    t0 = _learn(g, rng, _float_block, lambda rng, n: np.full((n, 3), np.nan))
    ev = []
    for k in range(60):
        y = _float_block(rng, sigma=2e-3 / 5)
        st = block_stats(y, g.dd_scale_ref())
        ev += g.on_block(st, t0 + k + np.arange(250) / 250.0, True, y, np.full((250, 3), np.nan)) + g.on_quiet(st)
    assert not any(e.kind == "stuck" for e in ev)
