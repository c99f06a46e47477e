"""The noise test against a reference learned from few degrees of freedom (health/axis_ref.py NU_REF_MIN).

30 reference blocks of a 10 Hz stream hold 8 second differences each (about 120 chi-square dof in all), and such
a reference is 20-30 % below the truth in a few runs in a hundred by chance alone; the noise test's CUSUM then
drifts up on a healthy gyro: a healthy copter streamed at 10 Hz (its noisier IMU, far above the LSB) was called
noisy 5 times in 48 IMU-hours (benchmarks/bench_faults.py --preset, the copter preset at 10 Hz). The noise
level is now learned until it holds 700 dof, as 30 blocks of 50 Hz do (the other tests keep the 30-block
reference). Float white noise here (the plain reference, no rounding)."""

from __future__ import annotations

import json

import numpy as np

import companion.health.axis_ref as axis_ref
import companion.health.block_stats as block_stats
from companion.health.axis_ref import NU_REF_MIN, AxisRef
from companion.health.faults import Observation
from companion.health.noise import NoiseDetector
from tests.support.noise_blocks import learn_or_test, one_axis_stats as _stats

SIGMA = 3e-3  # rad/s: white, float (no code grid)


def _run(seed, n, blocks, ref_scale=1.0, fault_at=None, factor=2.0):
    """Reference blocks of noise ``ref_scale`` x SIGMA until the reference is ready, then ``blocks`` blocks of
    SIGMA (``factor`` x from ``fault_at``): (alarms, blocks to the first alarm after the fault, reference)."""
    rng = np.random.default_rng(seed)
    ref, det = AxisRef(), NoiseDetector()
    alarms, first, k = 0, None, 0
    while k < blocks:
        s = SIGMA * (ref_scale if not ref.noise_ready else factor if fault_at is not None and k >= fault_at else 1.0)
        y = s * rng.standard_normal(n)
        alarm = learn_or_test(ref, det, Observation(0, _stats(y), t=np.array([k + 1.0]), axis="gx", ref=ref,
                                                    y=y[:, None]))
        if alarm is None:
            continue
        k += 1
        if alarm:
            alarms += 1
            if fault_at is not None and first is None and k > fault_at:
                first = k - fault_at
    return alarms, first, ref


def _chance_low_seeds(n=10, blocks=30, below=0.75, count=3):
    """Seeds whose first ``blocks`` blocks of ``n`` samples have a mean v2 ``below`` x the truth: a 30-block
    10 Hz reference that low happens by chance in about 2 runs in 100."""
    out = []
    for seed in range(1000):
        rng = np.random.default_rng(seed)
        v = [float(_stats(SIGMA * rng.standard_normal(n)).v2[0]) for _ in range(blocks)]
        if np.mean(v) < below * SIGMA ** 2:
            out.append(seed)
            if len(out) == count:
                return out
    raise AssertionError("no such seed")


def test_a_reference_low_by_chance_at_10_hz_made_false_alarms_and_is_now_learned_on(monkeypatch):
    seeds = _chance_low_seeds()
    with monkeypatch.context() as m:
        m.setattr(axis_ref, "NU_REF_MIN", 0.0)  # the reference of 30 blocks whatever they hold
        assert sum(_run(s, 10, 3000)[0] for s in seeds) > 0
    for s in seeds:
        alarms, _, ref = _run(s, 10, 3000)
        assert alarms == 0 and ref.blocks == 30 and ref.noise_ready, (s, alarms, ref.blocks)


def test_healthy_10_hz_noise_raises_nothing_against_references_of_700_dof():
    assert sum(_run(10 + s, 10, 2000)[0] for s in range(8)) == 0


def test_doubled_noise_is_named_at_10_hz():
    for s in range(4):
        _, first, _ = _run(20 + s, 10, 200, fault_at=50)
        assert first is not None and first <= 30, (s, first)


def test_references_of_50_samples_a_block_are_learned_in_30_blocks_as_before():
    rng = np.random.default_rng(40)
    ref = AxisRef()
    for k in range(30):
        st = _stats(SIGMA * rng.standard_normal(51))
        ready = ref.add(float(st.v2[0]), float(st.m2[0]), float(st.mean[0]), 0, 51, 30)
        assert ready == (k == 29) and ref.noise_ready == (k == 29)
    assert ref.noise_sigma2 == ref.sigma2 and ref.noise_nu == ref.nu
    assert NU_REF_MIN <= 30 * block_stats.DD_NU_PER_SAMPLE * 49


def test_a_noise_level_still_learning_goes_on_after_a_restart_and_an_old_state_keeps_the_reference():
    rng = np.random.default_rng(50)
    stats = [_stats(SIGMA * rng.standard_normal(10)) for _ in range(300)]
    whole, first = AxisRef(), AxisRef()
    for st in stats:
        whole.add(float(st.v2[0]), float(st.m2[0]), float(st.mean[0]), 0, 10, 30)
    for st in stats[:60]:
        first.add(float(st.v2[0]), float(st.m2[0]), float(st.mean[0]), 0, 10, 30)
    assert first.ready and not first.noise_ready
    again = AxisRef()
    again.load_state_dict(json.loads(json.dumps(first.state_dict())))
    for st in stats[60:]:
        again.add(float(st.v2[0]), float(st.m2[0]), float(st.mean[0]), 0, 10, 30)
    assert again.noise_ready and again.noise_sigma2 == whole.noise_sigma2 and again.sigma2 == whole.sigma2
    old = {k: v for k, v in whole.state_dict().items() if k not in ("noise_sigma2", "noise_nu", "nu_sum")}
    restored = AxisRef()
    restored.load_state_dict(old)
    assert restored.noise_sigma2 == whole.sigma2 and restored.noise_nu == whole.nu
