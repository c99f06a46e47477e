"""The sample-level dead/frozen test (health/frozen_watch.py) at telemetry rates, against known truth:
how many samples it needs (NEED motion pairs), no alarm on live gyros however slow the stream, none on a
gyro that reads 0 at rest (below resolution), and the same answer however the samples are split."""

import numpy as np
import pytest

from companion.health.hold import FAULT, OK
from companion.health.frozen_watch import CLEAR, NEED, FrozenWatch

LSB = 1e-3


def flight(rate: float, seconds: float, seed: int, imus: int = 2):
    """A flying vehicle seen by ``imus`` IMUs at ``rate`` Hz: body rates of +-0.5 rad/s changing every
    sample, vibration of 0.02 rad/s, rounded to 1 mrad/s; accel turning with the attitude."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate)
    t = 1.0 + np.arange(n) / rate + rng.uniform(-0.1, 0.1, n) / rate
    w = rng.uniform(-0.5, 0.5, (n, 3))
    tilt = rng.uniform(-0.3, 0.3, (n, 2))
    acc = np.column_stack([9.81 * np.sin(tilt[:, 0]), 9.81 * np.sin(tilt[:, 1]), -9.81 * np.cos(tilt[:, 0])])
    g = [np.round((w + rng.normal(0, 0.02, (n, 3))) / LSB) * LSB for _ in range(imus)]
    a = [acc + rng.normal(0, 0.3, (n, 3)) for _ in range(imus)]
    return t, g, a


def feed(watch, t, g, a, chunk: int = 1):
    events = []
    for k in range(0, t.size, chunk):
        for i in range(len(g)):
            watch.add(i, t[k:k + chunk], g[i][k:k + chunk], a[i][k:k + chunk])
        events += watch.judge()
    return events


@pytest.mark.parametrize("rate", [1.0, 2.0, 4.0, 10.0])
def test_a_gyro_zeroed_in_flight_is_named_after_need_motion_pairs(rate):
    t, g, a = flight(rate, 120.0, seed=int(rate))
    k0 = t.size // 2
    g[1][k0:] = 0.0
    events = feed(FrozenWatch(), t, g, a)
    named = [(te, ev) for te, ev in events if ev.state == FAULT]
    assert {ev.imu for _, ev in named} == {1}
    assert {ev.axis for _, ev in named} == {"gx", "gy", "gz"} and {ev.kind for _, ev in named} == {"dead"}
    # every pair is motion here (the twin moves by far more than 0.05 rad/s): named at the NEED-th pair of zeros
    first = min(te for te, _ in named)
    assert first == pytest.approx(t[k0 + NEED], abs=1e-9)


def test_one_imu_alone_is_named_by_its_accelerometer_and_a_frozen_value_is_stuck():
    t, g, a = flight(2.0, 200.0, seed=5, imus=1)
    k0 = 150
    g[0][k0:] = g[0][k0]  # frozen at its last value (not 0)
    events = feed(FrozenWatch(), t, g, a)
    assert [(ev.kind, ev.axis) for _, ev in events] == [("stuck", "gx"), ("stuck", "gy"), ("stuck", "gz")]
    assert all(te == pytest.approx(t[k0 + NEED]) for te, _ in events)


@pytest.mark.parametrize("seed", range(8))
def test_live_gyros_in_flight_never_named(seed):
    t, g, a = flight([1.0, 2.0, 4.0, 10.0][seed % 4], 300.0, seed=100 + seed, imus=3)
    assert feed(FrozenWatch(), t, g, a, chunk=4) == []


def test_zero_at_rest_is_resolution_not_dead_and_motion_then_names_it():
    """A quiet int16 gyro reads 0 at rest (SITL): no alarm however long; a twin moving while it still
    reads 0 names it (the twin's moves of 0.05 rad/s would show on a live gyro)."""
    rate, n = 1.0, 400
    t = 1.0 + np.arange(n) / rate
    acc = np.tile([0.0, 0.0, -9.81], (n, 1))
    g0, g1 = np.zeros((n, 3)), np.zeros((n, 3))
    w = FrozenWatch()
    assert feed(w, t, [g0, g1], [acc, acc]) == []
    assert w.imus[0].zero_still.sum() > 0.9 * 3 * (n - 1)
    # now the vehicle moves: IMU1 follows, IMU0 stays at 0
    t2 = t + n
    g1m = np.round(np.random.default_rng(1).uniform(-0.5, 0.5, (n, 3)) / LSB) * LSB
    events = feed(w, t2, [np.zeros((n, 3)), g1m], [acc, acc])
    assert {(ev.imu, ev.kind) for _, ev in events} == {(0, "dead")}


def test_clears_after_clear_pairs_that_change():
    t, g, a = flight(4.0, 100.0, seed=7)
    g[0][100:200] = 0.0
    events = feed(FrozenWatch(), t, g, a)
    states = [(ev.axis, ev.state) for _, ev in events if ev.axis == "gx"]
    assert states == [("gx", FAULT), ("gx", OK)]
    cleared = [te for te, ev in events if ev.axis == "gx" and ev.state == OK][0]
    assert cleared == pytest.approx(t[199 + CLEAR])


@pytest.mark.parametrize("chunk", [3, 9])
def test_same_events_however_the_samples_are_split(chunk):
    t, g, a = flight(2.0, 300.0, seed=9, imus=3)
    g[2][300:] = 0.0
    g[1][400:] = g[1][400]
    one = feed(FrozenWatch(), t, g, a, chunk=1)
    many = feed(FrozenWatch(), t, g, a, chunk=chunk)
    assert sorted((te, ev.imu, ev.axis, ev.kind, ev.state) for te, ev in one) == \
        sorted((te, ev.imu, ev.axis, ev.kind, ev.state) for te, ev in many)
    assert len(one) == 6


def rest(n: int, noise_lsb: float, seed: int):
    """One IMU at rest at 2 Hz: gyro noise of ``noise_lsb`` steps around a small bias, accel still."""
    rng = np.random.default_rng(seed)
    t = 1.0 + np.arange(n) / 2.0
    g = np.round((0.0004 + rng.normal(0, noise_lsb * LSB, (n, 3))) / LSB) * LSB
    a = np.tile([0.1, -0.05, -9.81], (n, 1)) + rng.normal(0, 0.01, (n, 3))
    return t, g, a


def test_a_gyro_that_resolves_its_noise_at_rest_is_named_when_it_dies_at_rest():
    """A single IMU at rest whose gyro changes value in most pairs (noise of 3 steps: p ~ 0.9): zeroed,
    it is named after L calm pairs, L from the learned p (about 20 at p = 0.9), without any motion."""
    t, g, a = rest(600, 3.0, seed=1)
    g[300:] = 0.0
    events = feed(FrozenWatch(), t, [g], [a])
    assert {(ev.kind, ev.detail) for _, ev in events} == {("dead", "float")}
    first = min(te for te, _ in events)
    assert t[300] < first <= t[300 + 40]


@pytest.mark.parametrize("seed", range(6))
def test_a_quiet_gyro_at_rest_is_never_named(seed):
    """Noise of 0.3-1 steps (a gyro that repeats its code at rest by nature): p < 0.8, the calm rule stays
    off whatever its runs of equal values."""
    t, g, a = rest(3000, [0.3, 0.5, 1.0][seed % 3], seed=10 + seed)
    assert feed(FrozenWatch(), t, [g], [a], chunk=7) == []


@pytest.mark.parametrize("sigma_lsb", [1.5, 2.5, 4.0])
def test_a_gyro_noisier_than_its_step_is_not_below_resolution(sigma_lsb):
    """A gyro whose noise spans a few 1 mrad/s steps reads 0 twice in a row on some pairs at rest (about
    P(0)^2, 4-7 % here) and changes while moving: it is not 'below resolution'. One that reads 0 at rest
    on nearly every pair and changes while moving is."""
    rate, n = 50.0, 6000
    rng = np.random.default_rng(int(sigma_lsb * 10))
    t = 1.0 + np.arange(2 * n) / rate
    acc = np.tile([0.0, 0.0, -9.81], (2 * n, 1))
    still = np.round(rng.normal(0, sigma_lsb * LSB, (n, 3)) / LSB) * LSB
    moving = np.round(rng.uniform(-0.5, 0.5, (n, 3)) / LSB) * LSB
    twin_moving = moving + np.round(rng.normal(0, 0.002, (n, 3)) / LSB) * LSB
    twin_still = np.round(rng.normal(0, sigma_lsb * LSB, (n, 3)) / LSB) * LSB
    w = FrozenWatch()
    feed(w, t, [np.vstack([still, moving]), np.vstack([twin_still, twin_moving])], [acc, acc], chunk=50)
    assert w.imus[0].zero_still.min() >= 20  # the old count alone would have said "below resolution"
    assert w.below_resolution(0) == []
    quiet = FrozenWatch()
    feed(quiet, t, [np.vstack([np.zeros((n, 3)), moving]), np.vstack([twin_still, twin_moving])], [acc, acc],
         chunk=50)
    assert quiet.below_resolution(0) == ["gx", "gy", "gz"]
