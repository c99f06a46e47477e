"""When a disagreement between two IMUs clears: only after sustained agreement, never while its cause persists.

A user trial froze one gyro in flight: the vehicle's true rate passed near the frozen value every few
seconds, one second's means agreed, and the pair's fault cleared on that one block and was named again a few
blocks later (9 named/cleared pairs in 106 s, each a CRITICAL STATUSTEXT). These tests feed a pair (and a
group of two stand-in channels) 1-s blocks of simulated rates, as the pipeline does.
"""

from __future__ import annotations

import math

import numpy as np

from companion.health.disagreement import CLEAR_BLOCKS, PairDisagreement
from companion.health.faults import Observation
from companion.health.hold import FAULT, OK
from companion.service.imu_group import ImuGroup

FS = 50
LSB = 1e-3
DEG = math.pi / 180
SIGMA = 2 * LSB
NV = SIGMA ** 2 + LSB ** 2 / 12
FROZEN = 20 * DEG  # the value IMU1's gyro X is frozen at


def turns(k0, n_blocks, x_mean=0.0, x_amp=40 * DEG):
    """True body rates of blocks k0.. (n_blocks * FS, 3): X swings through +-x_amp around x_mean with a 20 s
    period (its 1 s means pass near FROZEN twice a period), Y and Z turn on their own."""
    t = (k0 * FS + np.arange(n_blocks * FS)) / FS
    return np.column_stack([x_mean + x_amp * np.sin(2 * np.pi * 0.05 * t),
                            0.6 * np.sin(2 * np.pi * 0.3 * t), 0.4 * np.sin(2 * np.pi * 0.13 * t + 1)])


def imus(rng, w, frozen=False, step=None):
    """Both IMUs' rounded outputs of the true rates w: IMU1 with a 1 % scale difference on Y, its X frozen at
    FROZEN (exactly, as a frozen register) or shifted by ``step`` on Z."""
    y0 = w + rng.normal(0, SIGMA, w.shape)
    y1 = w * np.array([1.0, 1.01, 1.0]) + rng.normal(0, SIGMA, w.shape)
    if frozen:
        y1[:, 0] = FROZEN
    if step is not None:
        y1[:, 2] += step
    return np.round(y0 / LSB) * LSB, np.round(y1 / LSB) * LSB


def feed(pair, rng, k0, n_blocks, **kw):
    events = []
    w = turns(k0, n_blocks, **{k: kw.pop(k) for k in ("x_mean", "x_amp") if k in kw})
    for b in range(n_blocks):
        y0, y1 = imus(rng, w[b * FS:(b + 1) * FS], **kw)
        events += [(k0 + b, e) for e in pair.update(Observation(0, y=y0, other=y1, other_imu=1, noise_var=2 * NV,
                                                                noise_other=NV))]
    return events


def test_a_gyro_frozen_in_flight_is_named_once_while_the_turns_pass_its_value():
    rng = np.random.default_rng(7)
    pair = PairDisagreement(0, 1)
    assert feed(pair, rng, 0, 200) == []  # healthy turns: E learned, no disagreement
    ev = feed(pair, rng, 200, 300, frozen=True)
    # the 1 s means of the true X rate pass within the allowance of the frozen value about every 10 s ...
    w = turns(200, 300)[:, 0].reshape(300, FS).mean(axis=1)
    assert np.count_nonzero(np.abs(w - FROZEN) < 5 * DEG) >= 20
    # ... and the disagreement is named once, within a few blocks, and stays named
    assert [(e.axis, e.state) for _, e in ev] == [("gx", FAULT)], ev
    assert ev[0][0] - 200 <= 5
    assert pair.axis_state(0) == FAULT


def test_a_transient_disagreement_clears_after_sustained_agreement():
    rng = np.random.default_rng(8)
    pair = PairDisagreement(0, 1)
    assert feed(pair, rng, 0, 200) == []
    ev = feed(pair, rng, 200, 20, step=10 * DEG)  # 20 s of +10 deg/s on Z, above the floor
    assert [(e.axis, e.state) for _, e in ev] == [("gz", FAULT)] and ev[0][0] - 200 <= 5
    ev = feed(pair, rng, 220, 2 * CLEAR_BLOCKS)
    # cleared after CLEAR_BLOCKS agreeing blocks (the first after the step may still straddle it), once
    assert [(e.axis, e.state) for _, e in ev] == [("gz", OK)], ev
    assert 220 + CLEAR_BLOCKS - 1 <= ev[0][0] <= 220 + CLEAR_BLOCKS + 2
    # and the bias reference is the agreeing blocks' (no offset left to name again)
    assert feed(pair, rng, 220 + 2 * CLEAR_BLOCKS, 100) == []


class _Faults:
    def __init__(self, active=()):
        self._active = list(active)
        self.external = {}

    def noise_ref(self, axis):
        return NV

    def active(self):
        return self._active + [k for k, s in self.external.items() if s == FAULT]

    def set_external(self, kind, axis, state):
        self.external[(kind, axis)] = state


class _Channel:
    def __init__(self, imu, active=()):
        self.imu, self.faults, self.recent = imu, _Faults(active), []


def _group_run(stuck_named):
    """Two IMUs, IMU1's X frozen at FROZEN from block 200: turns, then a hover whose X rate sits at the frozen
    value for 3 x CLEAR_BLOCKS s, then turns again. Returns the group's disagreement events."""
    rng = np.random.default_rng(9)
    ch = {0: _Channel(0), 1: _Channel(1)}
    group = ImuGroup(reset_s=10.0)
    events = []
    hover = 3 * CLEAR_BLOCKS
    for k in range(200 + 60 + hover + 60):
        if k == 200 and stuck_named:
            ch[1].faults._active = [("stuck", "gx")]  # the stuck detector names the frozen axis
        in_hover = 260 <= k < 260 + hover
        w = turns(k, 1, x_mean=FROZEN, x_amp=0.5 * DEG) if in_hover else turns(k, 1)
        y0, y1 = imus(rng, w, frozen=k >= 200)
        t = (k * FS + np.arange(FS)) / FS
        ch[0].recent, ch[1].recent = [(t, y0)], [(t, y1)]
        events += [(k, e) for e in group.compare(1, ch, armed=True)]
    return events


def test_a_frozen_gyro_stays_named_through_a_hover_at_its_value_while_the_stuck_detector_names_it():
    ev = _group_run(stuck_named=True)
    assert [(e.imu, e.axis, e.state) for _, e in ev] == [(1, "gx", FAULT)], ev
    assert ev[0][0] - 200 <= 5 and ev[0][1].critical


def test_without_a_named_cause_a_long_agreement_clears_the_disagreement():
    # the same flight with no other fault named: the hover is sustained agreement, so the pair clears
    # there (after CLEAR_BLOCKS blocks) and the next turns name it again
    ev = _group_run(stuck_named=False)
    states = [(e.axis, e.state) for _, e in ev if e.imu == 1]
    assert states[:3] == [("gx", FAULT), ("gx", OK), ("gx", FAULT)], ev
    cleared = [k for k, e in ev if e.state == OK][0]
    assert 260 + CLEAR_BLOCKS - 1 <= cleared <= 260 + CLEAR_BLOCKS + 5
    assert all(e.axis == "gx" for _, e in ev)
