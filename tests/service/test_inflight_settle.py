"""The in-flight test's data leave out each flight stretch's take-off and landing (``InflightConfig.settle_s``):
a touchdown shakes two IMUs differently, and a baseline holding one misjudges the quiet flight after it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.service.inflight_live import InflightConfig, InflightNoise, PairTrack

FS = 100.0
SIGMA = 3e-3  # rad/s per sample, each IMU: the difference's white level N^2 = 2 SIGMA^2 / FS


def _stretch(rng, t0: float, seconds: float, shaken: tuple = ()):
    """1-s blocks (t, gi, gj) of two IMUs on one turning body; ``shaken``: (start, end) spans where the IMUs'
    own noise is 10x (a take-off or a touchdown)."""
    t = t0 + np.arange(int(seconds * FS)) / FS
    body = np.column_stack([0.4 * np.sin(2 * np.pi * f * t + p) for f, p in ((0.3, 0.0), (0.7, 1.0), (1.1, 2.0))])
    s = np.full(t.size, SIGMA)
    for a, b in shaken:
        s[(t >= a) & (t < b)] *= 10.0
    gi = body + rng.normal(0.0, 1.0, (t.size, 3)) * s[:, None]
    gj = body + rng.normal(0.0, 1.0, (t.size, 3)) * s[:, None]
    n = int(FS)
    return [(t[k:k + n], gi[k:k + n], gj[k:k + n]) for k in range(0, t.size, n)]


@pytest.mark.parametrize("seed", [1, 2])
def test_take_off_and_landing_left_out_of_the_test(seed):
    rng = np.random.default_rng(seed)
    pt = PairTrack(InflightConfig())
    settle = pt.cfg.settle_s
    for blk in _stretch(rng, 0.0, 20.0):  # on the ground, motors running
        pt.feed(*blk, "ground", learning=True)
    flight = _stretch(rng, 20.0, 200.0, shaken=((20.0, 28.0), (212.0, 220.0)))  # take-off, touchdown
    for blk in flight:
        pt.feed(*blk, "flight", learning=True)
    for blk in _stretch(rng, 220.0, 20.0):  # landed: the flight's held last seconds are dropped
        pt.feed(*blk, "ground", learning=True)
    truth = 2.0 * SIGMA ** 2 / FS
    for a in range(3):
        v, s, _ = pt.level("flight", a, "learn")
        assert abs(v - truth) < 3.0 * s, (a, v / truth, s / truth)
        w, _, _ = pt.level("flight", a, "whole")  # the reported figures keep the whole flight
        assert w > 2.0 * truth, (a, w / truth)
    # tested: the flight without its first and last settle_s (the calibration's warm-up block aside)
    assert pt.seconds["flight"] == pytest.approx(200.0 - 2 * settle, abs=1.5)
    assert pt.whole_s["flight"] == pytest.approx(200.0, abs=1.5)


def test_held_seconds_reach_the_test_while_the_flight_goes_on():
    rng = np.random.default_rng(3)
    pt = PairTrack(InflightConfig())
    blocks = _stretch(rng, 0.0, 120.0)
    for k, blk in enumerate(blocks):
        pt.feed(*blk, "flight", learning=True)
        calibrated = pt.whole_s["flight"]  # flight since the relative calibration's first output
        # the test gets everything from settle_s after take-off to settle_s before the newest sample
        assert pt.seconds["flight"] == pytest.approx(max(calibrated - 2 * pt.cfg.settle_s, 0.0), abs=1.5), k
    assert pt.seconds["flight"] > 60.0
    v, s, _ = pt.level("flight", 0, "cur")
    assert abs(v - 2.0 * SIGMA ** 2 / FS) < 3.0 * s
    assert math.isfinite(v)


def test_a_check_without_new_data_is_no_new_look():
    """The debounced test counts checks as looks at new data: while the test gets none (on the ground, during
    a take-off's settle_s) a figure far from its baseline is one look, not one per check."""
    rng = np.random.default_rng(4)
    noise = InflightNoise(InflightConfig())
    pt = noise.pairs[(0, 1)] = PairTrack(noise.cfg)
    blocks = _stretch(rng, 0.0, 200.0)
    for blk in blocks[:120]:
        pt.feed(*blk, "flight", learning=False)
    now = noise._pair_levels("flight")[(0, 1)]
    noise.baseline["flight"] = {"imus": {}, "pairs": {(0, 1): {ax: (n / 3.0, s / 3.0) for ax, (n, s) in now.items()}}}
    for _ in range(10):  # no new data: however many checks, one look
        assert noise._test("flight") == []
    verdicts = []
    for blk in blocks[120:125]:  # new data each check: the fourth look in a row names both IMUs
        pt.feed(*blk, "flight", learning=False)
        verdicts.append(noise._test("flight"))
    assert [len(v) for v in verdicts[:2]] == [0, 0] and verdicts[2], verdicts
    assert {v.who for v in verdicts[2]} == {0, 1}


class _Faults:
    def __init__(self):
        self.held: list = []

    def active(self):
        return list(self.held)


class _Channel:
    def __init__(self, imu: int):
        self.imu, self.recent, self.filters, self.gyro_lsb, self.faults = imu, [], {}, None, _Faults()


def _fly(noise, chans, blocks, frozen: bool, held: bool) -> list:
    """Feed ``blocks`` (IMU1's gx frozen at its first value with ``frozen``; its fault held with ``held``)."""
    said = []
    for t, gi, gj in blocks:
        if frozen:
            gj = gj.copy()
            gj[:, 0] = chans[1].frozen_at
        chans[1].faults.held = [("stuck", "gx")] if held else []
        for ch, g in ((chans[0], gi), (chans[1], gj)):
            ch.recent = (ch.recent + [(t, g)])[-3:]
        for imu in (0, 1):
            said += noise.on_block(imu, chans, True, float(t[-1]))
    return said


@pytest.mark.parametrize("held", [True, False])
def test_pairs_of_an_imu_held_stuck_are_suspended_and_resume(held):
    """While IMU1 is held stuck its pair is out of the in-flight test (its difference is IMU0's whole motion on
    the frozen axis): nobody is named; when the fault clears the pair resumes against the baseline learned
    before, which the frozen span did not touch. Not held, the same data name both IMUs (the test can fail)."""
    rng = np.random.default_rng(5)
    noise = InflightNoise(InflightConfig(baseline_s=60.0))
    chans = {0: _Channel(0), 1: _Channel(1)}
    chans[1].frozen_at = 0.1
    said = _fly(noise, chans, _stretch(rng, 0.0, 120.0), frozen=False, held=False)
    base = {k: dict(v) for k, v in noise.baseline["flight"]["pairs"].items()}
    assert base and not said
    said = _fly(noise, chans, _stretch(rng, 120.0, 60.0), frozen=True, held=held)
    if not held:
        assert {v.who for v in said} == {0, 1}
        return
    assert not said and noise.pairs[(0, 1)].suspended
    said = _fly(noise, chans, _stretch(rng, 180.0, 120.0), frozen=False, held=False)
    assert not said and not noise.pairs[(0, 1)].suspended
    assert noise.baseline["flight"]["pairs"] == base
    z = noise.last_z["flight"]
    assert {ax for (k, ax) in z} == {"gx", "gy", "gz"} and all(abs(v) < 3.0 for v in z.values()), z
